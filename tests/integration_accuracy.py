"""The accuracy check of the production integration (the FMU's doStep, which the
in-process ``HybridSimulator`` reproduces bit for bit) against a tight-tolerance reference
run of the same scenario: the criterion and its pieces, used by
``benchmarks/bench_accuracy.py`` (the figures, docs/performance.md) and
``tests/test_integration_accuracy.py`` (the bound, on a few steps).

Scenario: the demo walking controller ``clfqp`` in process on the demo gait and tube
(tests/data/controller/gait_demo.json, tube_demo.json), its torque held over each 1 ms
period (zero-order hold, as in the co-simulation), from the gait's initial state.

Reference: the same loop with ``substeps`` = 64 RK4 steps per period (h = 15.6 us) and the
touchdown located to 1e-13 m.  Its own error is estimated Richardson-style: the criterion
below applied to the same integrator at half the substeps (32) measures e(32) ~ 16 e(64)
(RK4 is fourth order), so e(64) ~ e(32) / 15.

Criterion (per-step restart): the closed loop amplifies a difference from period to period
(the controller answers the state it sees; about 2-3x per walking step), so a free-running
comparison over 20 steps measures the loop's sensitivity, not the integrator.  Instead, for
every impact k of the reference (k = 0: the start), the integrator under test is restarted
from the reference's state at the first 1 ms communication point after impact k (the
simulator's whole run state: hybrid state, domain, time, torque held, phase peak, guard
height; the controller brought to the same state by replaying the reference's observations
into a fresh one, whose torques are checked to equal the reference's bit for bit) and run
with the same controller to the next impact; its pre-impact state (q in m and rad, qd- in
m/s and rad/s, at the located touchdown, after the foot is flattened) and the impact time
are compared with the reference's impact k + 1.  Target (issue 22): state error (inf-norm)
below 1e-6 at every impact.  The free-running error (one run from the start, compared impact
by impact) is reported too, for transparency.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

import hp_model
from hp_model.closed_loop import ClosedLoop
from hp_model.force_tube import load_tube
from hp_model.gait_artifact import load_gait
from hp_model.simulator import HybridSimulator, Impact, SimOptions
from orchestrator.experiments.scenarios import initial_state
from orchestrator.loop import ControllerLink, Observation, SimulatorPlant
from prosthesis_controller import ControllerContext, make_controller

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT / "tests/data/controller/gait_demo.json"
TUBE = ROOT / "tests/data/controller/tube_demo.json"
CONTROLLER = "clfqp"
TARGET = 1e-6  # state error (inf-norm) at every impact
#: the reference: 64 RK4 steps per 1 ms period, touchdown to 1e-13 m
REFERENCE = SimOptions(substeps=64, event_tol=1e-13, event_iters=200)


@dataclass
class Checkpoint:
    """The run state at a communication point: what a restart needs."""

    period: int  # observations before this point (= the period about to be observed)
    x: np.ndarray
    domain: str
    t_step: float
    tau_peak: float
    z_prev: float
    u_p: np.ndarray
    bad_cone: int


@dataclass
class Run:
    """A closed-loop run: its observations and torques per period, its impacts, and the
    checkpoints at the first communication point after each impact (index 0: the start)."""

    obs: list[Observation]
    torque: list[np.ndarray]
    impacts: list[Impact]
    checkpoints: list[Checkpoint]
    fall: str = ""


class Scenario:
    """The model, demo gait, tube and controller context, built once."""

    def __init__(self) -> None:
        self.model = hp_model.load_model()
        self.gait = load_gait(GAIT, self.model.parameter_hash())
        self.tube = load_tube(TUBE, self.gait.hash())
        self.cl = ClosedLoop(self.model, self.gait.degree)
        self.ctx = ControllerContext(self.gait, self.tube, self.model, None)
        self.q0, self.qd0 = initial_state(self.model, self.gait, (0.0, 0.0), self.cl)

    def simulator(self, options: SimOptions) -> HybridSimulator:
        g = self.gait
        return HybridSimulator(self.model, self.cl, {d: g.theta(d) for d in self.model.domains},
                               g.gains_array, options)

    def link(self) -> ControllerLink:
        return ControllerLink(make_controller(CONTROLLER, self.gait, self.tube, self.model,
                                              context=self.ctx))


def _checkpoint(plant: SimulatorPlant) -> Checkpoint:
    r = plant.run
    return Checkpoint(r.periods, r._x.copy(), r.domain, r._t_step, r._tau_peak, r._z_prev,
                      r._u_p.copy(), r._bad_cone)


def _restart(sim: HybridSimulator, c: Checkpoint) -> SimulatorPlant:
    """A plant whose run continues from checkpoint ``c`` (the run state a period boundary
    holds; see :class:`hp_model.simulator.SimulationRun`)."""
    nq = sim.nq
    plant = SimulatorPlant(sim, c.x[:nq], c.x[nq:], c.domain)
    r = plant.run
    r.periods, r.t = c.period, c.period * sim.opt.dt
    r._t_step, r._tau_peak, r._z_prev = c.t_step, c.tau_peak, c.z_prev
    r._u_p, r._bad_cone = c.u_p.copy(), c.bad_cone
    plant._k = c.period
    return plant


def run(sc: Scenario, options: SimOptions, steps: int, start: Checkpoint | None = None,
        replay: Run | None = None, checkpoints: bool = True) -> Run:
    """The closed loop for ``steps`` impacts (or a fall), from the start or from ``start``
    (with the controller replayed along ``replay``, the run the checkpoint belongs to)."""
    sim = sc.simulator(options)
    link = sc.link()
    if start is None:
        plant = SimulatorPlant(sim, sc.q0, sc.qd0)
    else:
        assert replay is not None
        for o, u in zip(replay.obs[:start.period], replay.torque[:start.period], strict=True):
            if not np.array_equal(link.exchange(o).torque, u):
                raise RuntimeError("the controller's replay does not reproduce its torques")
        plant = _restart(sim, start)
    out = Run([], [], [], [_checkpoint(plant)] if checkpoints else [])
    n0 = plant.run.steps
    while True:
        o = plant.observe()
        cmd = link.exchange(o)
        plant.actuate(cmd.torque)
        out.obs.append(o)
        out.torque.append(np.array(cmd.torque, float))
        if plant.fall is not None:
            out.fall = plant.fall.message()
            break
        if plant.run.steps - n0 >= steps:
            break
        before = plant.run.steps
        plant.advance()
        if checkpoints and plant.run.steps > before:
            out.checkpoints.append(_checkpoint(plant))
    out.impacts = plant.run.impacts[:]
    return out


def state_error(a: Impact, b: Impact) -> dict[str, float]:
    dq = float(np.abs(a.q - b.q).max())
    dqd = float(np.abs(a.qd_minus - b.qd_minus).max())
    return {"q": dq, "qd": dqd, "state": max(dq, dqd), "t": abs(a.t - b.t)}


def per_step(sc: Scenario, ref: Run, options: SimOptions, steps: int | None = None
             ) -> list[dict[str, float]]:
    """The per-step restart criterion (module docstring): one row per impact k + 1 of the
    reference, k = 0 .. steps - 1."""
    n = len(ref.impacts) if steps is None else min(steps, len(ref.impacts))
    rows = []
    for k in range(n):
        prod = run(sc, options, 1, start=ref.checkpoints[k], replay=ref, checkpoints=False)
        if prod.fall or not prod.impacts:
            rows.append({"q": np.inf, "qd": np.inf, "state": np.inf, "t": np.inf})
            continue
        rows.append(state_error(prod.impacts[-1], ref.impacts[k]))
    return rows


def free_running(ref: Run, prod: Run) -> list[dict[str, float]]:
    n = min(len(ref.impacts), len(prod.impacts))
    return [state_error(prod.impacts[k], ref.impacts[k]) for k in range(n)]


def worst(rows: list[dict[str, float]]) -> dict[str, float]:
    return {k: float(max(r[k] for r in rows)) for k in ("q", "qd", "state", "t")}
