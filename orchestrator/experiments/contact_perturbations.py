"""The multi-contact graph's prosthesis controllers under perturbation: the same draws for the
held oracle (full-state reference), ``clfqp``, contact-pd and the paper's baselines on this
graph (``pd``, ``passive``: :func:`orchestrator.cosim.contact_controllers.make_baseline`),
each walked in the in-process plant (:mod:`orchestrator.experiments.contact_walk`); what
docs/gait-design.md's perturbation table measures.

Families (``amplitude`` scales each; per draw, from its seed):

    bias     the socket IMU's pitch off by a constant, N(0, 0.5 deg x amplitude)
    imu      the IMU's pitch with white noise, 0.2 deg x amplitude
    encoder  the encoders with white noise, 1 mrad and 0.02 rad/s x amplitude
    sensors  all three together
    gains    the simulated human's gains (eps, kp, kd) each x exp(N(0, 0.3 x amplitude))
    posture  the human's four joints' curves offset by N(0, 1 deg x amplitude), every domain
    pace     the human's hip-rate curves (and v_hip) x exp(N(0, 0.05 x amplitude)), in every
             domain that has one: a person walking faster or slower than the gait, thigh
             and all (its joints follow the hip's progress)
    stride   the person's pace varying from stride to stride, coefficient of variation
             3 % x amplitude (:mod:`characterization.gait.pace_variability`)

The oracle reads the plant's state, not the sensors: in the sensor families it is not walked
(its row is the draws).

Usage: python -m orchestrator.experiments.contact_perturbations GAIT.json --family bias
       [--amplitude 1] [--draws 20] [--steps 10] [--swing-phase time|thigh]
(GAIT.json: a multi-contact gait written by ``hpcosim gait fit --domains multicontact``.)
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from characterization.gait.contact_gait import (
    GAINS,
    ContactGait,
    contact_gait_of,
    held_oracle,
    start_state,
)
from characterization.gait.multicontact import GRAPH
from characterization.gait.multicontact_artifact import load_contact_cycle
from characterization.gait.pace_variability import varying_pace
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain
from hp_model.force_tube import ModelErrorBound
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import GaitParams
from hp_model.simulator import GaitSchedule
from orchestrator.cosim.contact_controllers import (
    LoopSetup,
    held_walk,
    loop_simulator,
    make_controller,
)
from orchestrator.experiments.contact_walk import controller_run
from orchestrator.loop.link import IDEAL_ENCODER, Encoder
from prosthesis_controller.contact_phase_pd import DEFAULT_SWING_PHASE, SWING_PHASES

FAMILIES = ("bias", "imu", "encoder", "sensors", "gains", "posture", "pace", "stride")
#: the stride family's coefficient of variation at amplitude 1 (healthy walking: 2-3 %)
STRIDE_CV = 0.03
#: the human's joints whose curves the posture family offsets
HUMAN_JOINTS = ("th_lh", "th_lk", "th_la", "th_rh")
CONTROLLERS = ("oracle", "clfqp", "contact-pd", "pd", "passive")


@dataclass(frozen=True)
class Draw:
    """One draw: the gait the simulated human walks, its gains, the prosthesis's sensors."""

    gait: ContactGait
    gains: tuple[float, float, float]
    encoder: Encoder | None
    #: the pace's variation from stride to stride (coefficient of variation) and its seed
    stride_cv: float = 0.0
    stride_seed: int = 0

    def schedule(self) -> GaitSchedule | None:
        """The person's gait schedule (a fresh one per walk; None: the gait throughout)."""
        if self.stride_cv == 0.0:
            return None
        return varying_pace(self.gait.thetas(), self.stride_cv, self.stride_seed,
                            self.gait.params[GRAPH.domains[0]].degree)


def draw(gait: ContactGait, family: str, amplitude: float, seed: int) -> Draw:
    """The perturbation ``family`` (module docstring) of draw ``seed``."""
    rng = np.random.default_rng(seed)
    a = float(amplitude)
    if family == "bias":
        return Draw(gait, GAINS, Encoder(imu_bias=rng.normal(0, math.radians(0.5) * a),
                                         seed=seed))
    if family == "imu":
        return Draw(gait, GAINS, Encoder(imu_noise=math.radians(0.2) * a, seed=seed))
    if family == "encoder":
        return Draw(gait, GAINS, Encoder(angle_noise=1e-3 * a, velocity_noise=2e-2 * a,
                                         seed=seed))
    if family == "sensors":
        return Draw(gait, GAINS, Encoder(angle_noise=1e-3 * a, velocity_noise=2e-2 * a,
                                         imu_bias=rng.normal(0, math.radians(0.5) * a),
                                         imu_noise=math.radians(0.2) * a, seed=seed))
    if family == "gains":
        g = np.asarray(GAINS) * np.exp(rng.normal(0, 0.3 * a, 3))
        return Draw(gait, (float(g[0]), float(g[1]), float(g[2])), None)
    if family == "posture":
        offset = dict(zip(HUMAN_JOINTS, rng.normal(0, math.radians(1.0) * a, 4),
                          strict=True))
        return Draw(offset_outputs(gait, offset), GAINS, None)
    if family == "pace":
        return Draw(paced(gait, float(np.exp(rng.normal(0, 0.05 * a)))), GAINS, None)
    if family == "stride":
        return Draw(gait, GAINS, None, STRIDE_CV * a, seed)
    raise ValueError(f"unknown family {family!r}; choose from {', '.join(FAMILIES)}")


def offset_outputs(gait: ContactGait, offset: Mapping[str, float]) -> ContactGait:
    """``gait`` with each output curve of a coordinate in ``offset`` (rad) moved by it, in
    every domain where the coordinate is an output (a posture offset)."""
    params = {}
    for d, p in gait.params.items():
        alpha = np.array(p.alpha, float)
        for row, coord in enumerate(d.y2_coords):
            alpha[row] += offset.get(coord, 0.0)
        params[d] = GaitParams(alpha, p.v_hip, p.p_min, p.p_max)
    return ContactGait(params, gait.rms)


def paced(gait: ContactGait, factor: float) -> ContactGait:
    """``gait`` with the hip's rate curve V(tau) and its mean v_hip times ``factor`` in each
    domain with a velocity output (:mod:`hp_model.contact_outputs`); the toe domains' pace
    is their zero dynamics'."""
    params = {}
    for d, p in gait.params.items():
        alpha = np.array(p.alpha, float)
        v_hip = p.v_hip
        if d.velocity_output:
            alpha[len(d.y2_coords)] *= factor
            v_hip *= factor
        params[d] = GaitParams(alpha, v_hip, p.p_min, p.p_max)
    return ContactGait(params, gait.rms)


def walk_draw(model: HumanProsthesisModel, trajectory: Mapping[Domain, Mapping[str, Any]],
              d: Draw, controller: Any, steps: int, closed_loop: ClosedLoop | None = None
              ) -> bool:
    """Whether the plant of draw ``d`` takes ``steps`` steps with the prosthesis on
    ``controller`` ("oracle": :func:`held_oracle` on the plant's state; else a controller
    with ``reset`` and ``tick``, reading the sensors through the draw's encoder);
    ``closed_loop``: the model's, shared by the draws (:func:`loop_simulator`)."""
    sim = loop_simulator(model, d.gait, d.gains, closed_loop)
    if controller == "oracle":
        q0, qd0 = start_state(trajectory)
        policy = held_oracle(sim.cl, {Domain(k): th for k, th in sim.thetas.items()},
                             sim.gains, within_limits=True)
        res = sim.run(q0, qd0, GRAPH.domains[0], steps=steps, duration=2.0 * steps,
                      policy=policy, gaits=d.schedule())
        return res.fall is None and res.steps >= steps
    controller.reset()
    res = controller_run(sim, trajectory, controller, steps, d.encoder or IDEAL_ENCODER,
                         gaits=d.schedule())
    return res.fall is None and res.steps >= steps


def perturbed_controllers(model: HumanProsthesisModel, gait: ContactGait,
                          trajectory: Mapping[Domain, Mapping[str, Any]],
                          setup: LoopSetup | None = None,
                          model_error: ModelErrorBound | None = None,
                          swing_phase: str = DEFAULT_SWING_PHASE) -> dict[str, Any]:
    """The controllers a family walks (:data:`CONTROLLERS`), made once from the
    unperturbed gait (``setup``: its simulator and held walk, when made already;
    ``model_error``: the tube's bound, ``clfqp``'s robust term; ``swing_phase``: how they
    measure the swing's phase, :class:`~prosthesis_controller.contact_phase_pd.ContactPhasePD`)."""
    if setup is None or setup.held is None:
        sim = loop_simulator(model, gait, GAINS)
        setup = LoopSetup(sim, held_walk(sim, trajectory))
    return {"oracle": "oracle",
            **{name: make_controller(name, model, gait, trajectory, setup,
                                     swing_phase=swing_phase, model_error=model_error)
               for name in CONTROLLERS[1:]}}


def family_walks(model: HumanProsthesisModel, trajectory: Mapping[Domain, Mapping[str, Any]],
                 durations: Mapping[Domain, float], family: str, amplitude: float = 1.0,
                 draws: int = 20, steps: int = 10, *,
                 controllers: Mapping[str, Any] | None = None) -> dict[str, int]:
    """Walks of ``steps`` steps out of ``draws`` draws of ``family`` per controller (the
    same draws for each; ``controllers``: :func:`perturbed_controllers`, made here when not
    given)."""
    gait = contact_gait_of(model, trajectory, durations)
    ctls = controllers or perturbed_controllers(model, gait, trajectory)
    cl = ClosedLoop(model, gait.params[GRAPH.domains[0]].degree)
    walks = dict.fromkeys(CONTROLLERS, 0)
    for seed in range(draws):
        d = draw(gait, family, amplitude, seed)
        for name, ctl in ctls.items():
            if name == "oracle" and d.encoder is not None:
                walks[name] += 1  # it reads the plant's state, not the sensors
                continue
            walks[name] += walk_draw(model, trajectory, d, ctl, steps, cl)
    return walks


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("gait")
    ap.add_argument("--family", choices=FAMILIES, required=True)
    ap.add_argument("--amplitude", type=float, default=1.0)
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--swing-phase", choices=SWING_PHASES, default=DEFAULT_SWING_PHASE,
                    help="how the prosthesis controllers measure the swing's phase")
    a = ap.parse_args(argv)
    try:
        cycle = load_contact_cycle(a.gait)
        model, traj, durations = cycle.model, cycle.trajectory, cycle.durations
        ctls = perturbed_controllers(model, contact_gait_of(model, traj, durations), traj,
                                     swing_phase=a.swing_phase)
        w = family_walks(model, traj, durations, a.family, a.amplitude, a.draws, a.steps,
                         controllers=ctls)
    except (OSError, ValueError, KeyError) as e:  # a bad file, or the held oracle fell
        print(f"contact_perturbations: error: {a.gait}: {e}", file=sys.stderr)
        return 2
    print(f"{a.family} x{a.amplitude:g}, {a.draws} draws, {a.steps} steps: "
          + ", ".join(f"{k} {v}/{a.draws}" for k, v in w.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
