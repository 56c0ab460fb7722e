"""Closed-loop scenarios: the full hybrid human-prosthesis model on the one simulator
(:class:`hp_model.simulator.HybridSimulator`, mode ``human``), the human side tracking its
outputs by feedback linearization (along perturbed thetas for perturbation cases), and a
prosthesis controller at 1 kHz (zero-order hold) fed ONLY what AMPRO3 senses
(:func:`orchestrator.loop.plant.sensed`), all through the one closed loop
(:func:`orchestrator.loop.run_loop`).  Falls detected by the simulator end a run as a
failure with its :class:`hp_model.falls.Fall`.

The plant need not be the controller's model: ``run_scenario`` takes the plant's model
(e.g. another human body) and the controller's context separately, the human's tracking
gains and feedback delay, and an :class:`Encoder` (noise and quantization of what AMPRO3
senses).  The controller name :data:`ORACLE` runs the prosthesis under full-state feedback
linearization with perfect knowledge of the plant and perfect sensing instead of a
controller: the controller-independent rule that labels a perturbed case walkable.

Perturbed human gaits come from :func:`human_fmu.perturbation.perturbed_thetas` (the
generator the FMU uses), so the in-process and FMU runs of a case agree.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from characterization.gait.verification import make_simulator
from characterization.tube.fit import deviation_profiles, fit_tube, nominal_coefficients
from hp_model import bezier
from hp_model.closed_loop import ClosedLoop, ClosedLoopMode
from hp_model.domains import N_Y2, PAPER_DOMAINS, PROSTHESIS, Domain
from hp_model.falls import Fall, FallOutcome
from hp_model.force_tube import ForceTube
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.simulator import HybridSimulator, Impact, SimOptions
from human_fmu.perturbation import perturbed_thetas
from orchestrator.loop import (
    IDEAL_ENCODER,
    ControllerLink,
    Encoder,
    Link,
    LoopLog,
    OracleLink,
    SimulatorPlant,
    run_loop,
)
from prosthesis_controller import ControllerContext, ControllerMode, ControllerName, make_controller

#: not a prosthesis controller: full-state feedback linearization of the whole walker with
#: perfect knowledge (the walkability label of a perturbed case)
ORACLE = "oracle"
#: the six actuated joints (the post-impact states of ScenarioResult)
JOINTS = ("th_lh", "th_lk", "th_la", "th_rh", "th_pk", "th_pa")


@dataclass(frozen=True)
class Perturbation:
    """The human's gait: nominal (amplitude 0) or the deterministic perturbation of the
    Bezier coefficients with ``amplitude`` (rad) and ``seed``."""

    name: str = "nominal"
    amplitude: float = 0.0
    seed: int = 0

    def thetas(self, gait: Gait) -> dict[Domain, np.ndarray]:
        return perturbed_thetas({d: gait.theta(d) for d in PAPER_DOMAINS}, self.amplitude,
                                self.seed)


NOMINAL = Perturbation()


@dataclass(frozen=True)
class Scenario:
    """One closed-loop run: prosthesis controller, the human's gait, number of steps
    (impacts), and an initial prosthesis offset (knee, ankle) in rad added to the nominal
    initial state (:func:`initial_state`)."""

    controller: str = ControllerName.CLFQP  # or ORACLE
    perturbation: Perturbation = NOMINAL
    steps: int = 20
    initial_offset: tuple[float, float] = (0.0, 0.0)

    @property
    def label(self) -> str:
        off = "" if self.initial_offset == (0.0, 0.0) else " +offset"
        return f"{self.controller} / {self.perturbation.name}{off}"


@dataclass
class ScenarioResult(FallOutcome):
    """Per-period time series (1 kHz) of one scenario and how it ended."""

    scenario: Scenario
    t: np.ndarray
    tau: np.ndarray
    domain: np.ndarray  # 0 = ps, 1 = pns
    q_p: np.ndarray  # (n, 2) th_pk, th_pa
    qd_p: np.ndarray  # (n, 2)
    torque: np.ndarray  # (n, 2) motor torques the controller commanded
    knee_ref: np.ndarray  # (n,) nominal knee B_pk(tau) of the domain (gait, not perturbed)
    mode: list[ControllerMode | str]  # per period ("" where the link reports none)
    V: np.ndarray
    rho: np.ndarray
    fallback_count: int
    steps: int
    fall: Fall | None  # how the run ended (None: no fall)
    post_impact: list[np.ndarray] = field(default_factory=list)  # joint states after ps impacts
    step_bounds: list[tuple[int, int]] = field(default_factory=list)  # ps segments [i0, i1)
    socket_force: np.ndarray | None = None  # (n, 3) F_s (ground truth, never fed back)
    fs_in_tube: float | None = None  # fraction of ps samples in [tau_lo, tau_hi] with F_s in tube
    touchdown_pitch: list[float] = field(default_factory=list)  # rad, landing-foot correction
    q: np.ndarray | None = None  # (n, 12) the full configuration (animation)

    @property
    def success(self) -> bool:
        return not self.failed and self.steps >= self.scenario.steps

    @property
    def fail_t(self) -> float | None:
        """Time of the fall (s)."""
        return None if self.fall is None else self.fall.t

    @property
    def fail_tau(self) -> float | None:
        return None if self.fall is None else self.fall.tau

    @property
    def fail_domain(self) -> str | None:
        return None if self.fall is None else self.fall.domain

    def knee_rms(self, domain: str | None = Domain.PS) -> float:
        """RMS of th_pk - B_pk(tau) over the samples of ``domain`` (None: all), rad."""
        m = np.ones(self.t.size, bool) if domain is None else \
            self.domain == Domain(domain).code
        if not m.any():
            return float("nan")
        e = self.q_p[m, 0] - self.knee_ref[m]
        return float(np.sqrt(np.mean(e**2)))

    def chatter_per_step(self) -> list[float]:
        """Total variation of the motor torques (sum over both joints of sum |du|, N m) over
        each complete or partial ps segment."""
        out = []
        for i0, i1 in self.step_bounds:
            u = self.torque[i0:i1]
            out.append(float(np.abs(np.diff(u, axis=0)).sum()) if len(u) > 1 else 0.0)
        return out


def knee_reference(gait: Gait, domain: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """The prosthesis knee's nominal angle (rad) per sample: in domain code ``domain``
    (0 ps, 1 pns) at phase ``tau`` (clipped to [0, 1]); shape of ``tau``."""
    domain, tau = np.asarray(domain), np.clip(np.asarray(tau, float), 0.0, 1.0)
    ref = np.zeros(tau.shape)
    for d in PAPER_DOMAINS:
        m = domain == d.code
        if m.any():
            r = d.y2_row(PROSTHESIS[0])
            ref[m] = bezier.evaluate(gait.params[d].alpha[r:r + 1], tau[m])[:, 0]
    return ref


def initial_state(model: HumanProsthesisModel, gait: Gait,
                  offset: Sequence[float] = (0.0, 0.0), closed_loop: ClosedLoop | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The gait's initial ps state with the prosthesis (knee, ankle) offset (rad): the
    start of :mod:`hp_model.placement` (``ClosedLoop.start_state``; the human on its own
    outputs at the phase the offset moves, the walker placed on the prosthesis foot; the
    FMU's offset_knee/offset_ankle start from the same state).  Only the prosthesis starts
    off its nominal trajectory, as in the paper's robustness test.  ``closed_loop``: of the
    model and the gait's degree (built here when absent)."""
    tr = gait.trajectory[Domain.PS]
    cl = closed_loop or ClosedLoop(model, gait.degree)
    return cl.start_state(Domain.PS, tr["q"][:, 0], tr["qd"][:, 0], gait.theta(Domain.PS), offset)


@dataclass(frozen=True)
class PlantSetup:
    """How a run's plant departs from the default: the simulator's options (None: the
    defaults), the human's tracking gains (eps, kp, kd; None: the gait's) and feedback delay
    (s; None: the continuous human, :class:`hp_model.simulator.HybridSimulator`), and the
    encoder the controller's measurements go through (the oracle ignores it)."""

    options: SimOptions | None = None
    human_gains: np.ndarray | None = None
    human_delay: float | None = None
    encoder: Encoder = IDEAL_ENCODER


DEFAULT_PLANT = PlantSetup()


def run_scenario(model: HumanProsthesisModel, gait: Gait, tube: ForceTube,
                 scenario: Scenario, *, context: ControllerContext | None = None,
                 closed_loop: ClosedLoop | None = None, plant: PlantSetup = DEFAULT_PLANT,
                 start: tuple[np.ndarray, np.ndarray] | None = None) -> ScenarioResult:
    """Run one scenario on the full hybrid model (module docstring).  ``model`` is the
    plant's; the controller's comes from ``context`` (default: the plant's).
    ``closed_loop``: the compiled closed-loop functions of the plant and the gait's degree,
    to reuse between runs (building them costs about 0.5 s); built here when absent.
    ``plant``: the simulator's options, the human's gains and delay, the encoder
    (:class:`PlantSetup`); ``start``: the initial (q, qd) (default: :func:`initial_state` with
    the scenario's offset)."""
    if closed_loop is None:
        closed_loop = ClosedLoop(model, gait.degree)
    elif closed_loop.degree != gait.degree or closed_loop.model is not model:
        raise ValueError("closed_loop was built for another model or Bezier degree")
    gains = (gait.gains_array if plant.human_gains is None
             else np.asarray(plant.human_gains, float))
    thetas = scenario.perturbation.thetas(gait)
    if scenario.controller == ORACLE:
        thetas = oracle_thetas(gait, thetas)
    sim = HybridSimulator(model, closed_loop, thetas, gains, plant.options or SimOptions(),
                          human_delay=plant.human_delay)
    q0, qd0 = start or initial_state(model, gait, scenario.initial_offset, closed_loop)
    link: Link
    if scenario.controller == ORACLE:
        sim_plant = SimulatorPlant(sim, q0, qd0, mode=ClosedLoopMode.FULL)
        link = OracleLink()
    else:
        ctx = context or ControllerContext(gait, tube, model, None)
        ctrl = make_controller(scenario.controller, gait, tube, model, context=ctx)
        sim_plant = SimulatorPlant(sim, q0, qd0)
        link = ControllerLink(ctrl, plant.encoder)
    log = run_loop(sim_plant, link, steps=scenario.steps)
    return scenario_result(model, gait, tube, scenario, log, sim_plant.run.impacts)


def oracle_thetas(gait: Gait, thetas: Mapping[Domain, np.ndarray]) -> dict[Domain, np.ndarray]:
    """The outputs the oracle's walker tracks: the human's rows of ``thetas`` (the human's
    possibly perturbed gait) and the prosthesis's rows of the nominal gait (what a prosthesis
    controller is given)."""
    L = gait.params[Domain.PS].layout
    out: dict[Domain, np.ndarray] = {}
    for d in PAPER_DOMAINS:
        th = np.array(thetas[d], float)
        nominal = gait.theta(d)
        for r in range(N_Y2):
            if r + 1 not in d.human_outputs:  # rows of (y1, y2): y2 row r is r + 1
                th[L.row(r)] = nominal[L.row(r)]
        th[L.progress] = nominal[L.progress]  # v_hip, p_min, p_max: the phase is the
        out[d] = th  # prosthesis's
    return out


def scenario_result(model: HumanProsthesisModel, gait: Gait, tube: ForceTube,
                    scenario: Scenario, log: LoopLog, impacts: Sequence[Impact] = ()
                    ) -> ScenarioResult:
    """The :class:`ScenarioResult` of a closed loop's log (:func:`orchestrator.loop.run_loop`,
    any plant); ``impacts``: the simulator's impact records (joint states after the ps
    impacts, touchdown pitch), when the plant has them."""
    n = log.periods
    domain = np.array(log.domain, int)
    tau = np.array(log.tau, float)
    ref = knee_reference(gait, domain, tau)
    bounds, i0 = [], None
    for i, d in enumerate(domain):
        if d == 0 and i0 is None:
            i0 = i
        if d != 0 and i0 is not None:
            bounds.append((i0, i))
            i0 = None
    if i0 is not None:
        bounds.append((i0, n))
    q = np.array(log.q, float).reshape(n, -1)
    qd = np.array(log.qd, float).reshape(n, -1)
    fs = np.array(log.socket_force, float).reshape(n, 3)
    ps = domain == 0
    j = [model.coord_names.index(c) for c in JOINTS]
    pk, pa = model.roles[Domain.PS].prosthesis
    post = [np.r_[im.q[j], im.qd_plus[j]] for im in impacts if im.into == Domain.PS]
    return ScenarioResult(
        scenario=scenario, t=np.array(log.t, float), tau=tau, domain=domain,
        q_p=q[:, [pk, pa]], qd_p=qd[:, [pk, pa]], torque=np.array(log.torque).reshape(n, 2),
        knee_ref=ref, mode=list(log.mode), V=np.array(log.V), rho=np.array(log.rho),
        fallback_count=log.fallback_count, steps=int(log.steps), fall=log.fall,
        post_impact=post, step_bounds=bounds,
        socket_force=fs, fs_in_tube=socket_force_in_tube(tube, tau[ps], fs[ps]),
        touchdown_pitch=[float(im.foot_pitch) for im in impacts], q=q)


def socket_force_in_tube(tube: ForceTube, tau: np.ndarray, force: np.ndarray
                         ) -> float | None:
    """Fraction of the samples with tau in [tau_lo, tau_hi] whose socket force lies in the
    tube: the premise under which the robust CLF condition holds; None without samples."""
    tau = np.asarray(tau, float)
    m = (tau >= tube.tau_lo) & (tau <= tube.tau_hi)
    if not m.any():
        return None
    delta = np.asarray(force, float)[m] - tube.nominal_force(tau[m]).reshape(-1, 3)
    return float(np.mean(tube.contains(tau[m], delta)))


def oracle_walks(model: HumanProsthesisModel, gait: Gait, tube: ForceTube, scenario: Scenario,
                 closed_loop: ClosedLoop | None = None) -> tuple[bool, str]:
    """Whether the :data:`ORACLE` (full-state feedback linearization of the prosthesis,
    perfect knowledge and sensing) walks ``scenario`` (its human gait, steps and initial
    offset; its controller is ignored): a case the walker itself cannot complete is not a
    test of the prosthesis controller (the sweeps' walkability label)."""
    r = run_scenario(model, gait, tube, replace(scenario, controller=ORACLE),
                     closed_loop=closed_loop)
    return r.success, r.reason


@dataclass(frozen=True)
class PerturbationSearch:
    """What :func:`select_perturbations` looks for: ``n`` perturbed human gaits of
    ``amplitude`` (rad) that the oracle walks for ``steps`` steps from ``initial_offset``
    (knee, ankle; rad), among the seeds below ``max_seed``."""

    n: int = 3
    amplitude: float = 0.01
    steps: int = 20
    initial_offset: tuple[float, float] = (0.0, 0.0)
    max_seed: int = 50


def select_perturbations(model: HumanProsthesisModel, gait: Gait, tube: ForceTube,
                         search: PerturbationSearch = PerturbationSearch(),
                         closed_loop: ClosedLoop | None = None) -> list[Perturbation]:
    """The first ``search.n`` seeds (0, 1, ...) whose perturbed human gait the oracle walks
    (:func:`oracle_walks`, :class:`PerturbationSearch`): the cases every controller is then
    run on.  A fixed rule, independent of any prosthesis controller."""
    out: list[Perturbation] = []
    for seed in range(search.max_seed):
        p = Perturbation(f"human-{len(out) + 1} (seed {seed})", search.amplitude, seed)
        sc = Scenario(ORACLE, p, search.steps, search.initial_offset)
        if oracle_walks(model, gait, tube, sc, closed_loop)[0]:
            out.append(p)
            if len(out) == search.n:
                return out
    raise RuntimeError(f"fewer than {search.n} of {search.max_seed} perturbed gaits (amplitude "
                       f"{search.amplitude} rad) walk {search.steps} steps under the oracle")


@dataclass(frozen=True)
class SimulatedTubeOptions:
    """The perturbed human gaits of :func:`simulated_tube` (amplitude, rad; seeds from
    ``first_seed``) and its tube (Bezier degree, phase window [tau_lo, tau_hi])."""

    amplitude: float = 0.01
    degree: int = 3
    tau_lo: float = 0.02
    tau_hi: float = 0.98
    first_seed: int = 1000


def simulated_tube(model: HumanProsthesisModel, gait: Gait, n_profiles: int = 20,
                   options: SimulatedTubeOptions = SimulatedTubeOptions(),
                   progress: Callable[[int], None] | None = None
                   ) -> tuple[ForceTube, list[tuple[np.ndarray, np.ndarray]]]:
    """Stand-in for socket-force playback (until ``characterization.tube.playback`` lands): the
    socket force F_s = lam[3:6] of the first ps step of ``n_profiles`` perturbed human gaits
    (seeds ``options.first_seed``, ...; prosthesis under feedback linearization, mode full),
    deviation from F*(tau), fitted with :func:`characterization.tube.fit.fit_tube`."""
    amplitude, first_seed = options.amplitude, options.first_seed
    tau_lo, tau_hi = options.tau_lo, options.tau_hi
    base = make_simulator(model, gait)
    q0, qd0 = initial_state(model, gait, closed_loop=base.cl)
    steps: list[tuple[np.ndarray, np.ndarray]] = []
    seed = first_seed
    while len(steps) < n_profiles and seed < first_seed + 20 * n_profiles:
        p = Perturbation("tube", amplitude, seed)
        seed += 1
        sim = HybridSimulator(model, base.cl, p.thetas(gait), gait.gains_array, base.opt)
        r = sim.run(q0, qd0, Domain.PS, steps=1)
        if r.failed or r.steps < 1:
            continue
        m = r.domain == 0
        steps.append((r.tau[m], r.lam[m, 3:6]))
        if progress is not None:
            progress(len(steps))
    coef = nominal_coefficients(gait, tau_lo, tau_hi)
    prof = deviation_profiles(steps, coef, tau_lo, tau_hi)
    tube = fit_tube(prof, coef, tau_lo, tau_hi, degree=options.degree, gait_hash=gait.hash(),
                    source={"kind": "simulated perturbed human gaits (playback stand-in)",
                            "amplitude_rad": amplitude, "first_seed": first_seed})
    return tube, prof


def summary(r: ScenarioResult) -> dict[str, Any]:
    """The numbers of one run for metrics.json."""
    return {"controller": r.scenario.controller, "perturbation": r.scenario.perturbation.name,
            "amplitude_rad": r.scenario.perturbation.amplitude,
            "seed": r.scenario.perturbation.seed,
            "initial_offset_rad": list(r.scenario.initial_offset),
            "steps_requested": r.scenario.steps, "steps_completed": r.steps,
            "success": r.success, "failed": r.failed, "reason": r.reason,
            "fall_reason": r.fall.reason.label if r.fall is not None else None,
            "fail_t": r.fail_t, "fail_tau": r.fail_tau, "fail_domain": r.fail_domain,
            "duration_s": float(r.t[-1]) if r.t.size else 0.0,
            "knee_rms_ps_rad": r.knee_rms(Domain.PS), "knee_rms_all_rad": r.knee_rms(None),
            "socket_force_in_tube": r.fs_in_tube,
            "max_touchdown_pitch_rad": (max(abs(p) for p in r.touchdown_pitch)
                                        if r.touchdown_pitch else None),
            "fallback_count": r.fallback_count,
            "modes": {m: r.mode.count(m) for m in sorted(set(r.mode))}}

