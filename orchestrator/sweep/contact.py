"""A sweep of a multi-contact gait (``gait fit --domains multicontact``): the same runs,
draws and rows as the paper's (:mod:`orchestrator.sweep.runs`), on the person's graph.

Per draw, the simulated human walks the gait's curves (:mod:`characterization.gait.
contact_gait`) moved as the draw says, in the in-process plant (AMPRO3's sensors through the
draw's encoder, the torque held 1 ms within the motors):

    human.bezier_amplitude  every coefficient of every domain's curves, the SplitMix64
                            generator of :mod:`human_fmu.perturbation` (its graph's order)
    human.output_offset     a constant on each human joint's curve (th_lh, th_lk, th_la,
                            th_rh), in every domain where it is an output; the person starts
                            in that posture (:func:`posture_start`)
    human.stiffness         the human's gains (eps, kp, kd) -> (s eps, s^2 kp, s kd)
    human.stride_cv         the person's pace varying from stride to stride (its draws from
                            the run's own seed, :mod:`characterization.gait.pace_variability`)
    human.speed             the person walking the spec's gait library, starting at the
                            first speed drawn and changing to the second (:func:`speed_change`:
                            from ``CHANGE_AT`` s at ``ACCELERATION`` m/s^2); the controllers
                            follow it over the library (:func:`orchestrator.cosim.
                            following.speed_following`), the oracle holds the
                            person's curves of the moment; it starts from the library's cycle
                            at the first speed
    plant.armature          the plant's drives' armature times this factor (the controllers
                            keep the nominal device; the oracle knows the plant's)
    initial.knee, .ankle    the prosthesis's knee and ankle moved at the start (rad), the
                            person's joints on its curves at the phase that moves
                            (:func:`prosthesis_start`)
    sensor.*                the prosthesis's encoders and IMU

The controllers are made once per worker from the unperturbed gait (its held oracle's walk,
:mod:`orchestrator.cosim.contact_controllers`): ``clfqp`` (:class:`prosthesis_controller.
contact_clf_qp.ContactClfQp`) and ``phase-pd`` (contact-pd, :class:`prosthesis_controller.
contact_phase_pd.ContactPhasePD`); the ``oracle`` run of a draw is the held oracle on the
plant's state (perfect sensing), its feedback yielding at the motors' limits
(:func:`characterization.gait.contact_gait.held_oracle` ``within_limits``).  Every run
starts from the fitted cycle's start, in the person's own posture where its curves are
offset (:func:`posture_start`), with the prosthesis's joints moved where the draw moves them
(:func:`prosthesis_start`).  The other quantities of a family (a tube margin, a controller
model of its own, the plant's body but its armature, the delayed human) are refused by the
spec
(:func:`orchestrator.sweep.contact_spec.check_multicontact`).  With the gait's tube (``tube
fit``), ``socket_force_in_tube`` is the share of the flat single support's periods with the
socket force inside it
(:func:`characterization.tube.contact_playback.share_inside`).

Row columns as the paper's; ``knee_rms_ps_rad`` and ``knee_rms_all_rad`` are the prosthesis
knee's RMS deviation from the fitted cycle over the run's last complete stride (rad; None
without one).
"""

from __future__ import annotations

import math
import os
import socket
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from characterization.gait.contact_gait import GAINS, ContactGait, held_oracle, start_state
from characterization.gait.library import (
    GaitLibrary,
    load_gait_library,
    speed_schedule,
    start_at,
)
from characterization.gait.multicontact import GRAPH
from characterization.gait.pace_variability import varying_pace
from characterization.tube.contact_playback import share_inside
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.json_io import finite_or_none
from hp_model.outputs import GaitParams
from hp_model.simulator import HybridSimulator, SimResult
from hp_model.speed_profile import SpeedProfile
from human_fmu.perturbation import perturbed_thetas
from orchestrator.cosim.contact_controllers import (
    LoopSetup,
    held_walk,
    load_contact_run,
    loop_simulator,
    make_controller,
)
from orchestrator.cosim.following import speed_following
from orchestrator.experiments.contact_walk import controller_run
from orchestrator.experiments.person_walks import stride_rms
from orchestrator.experiments.scenarios import ORACLE
from orchestrator.sweep.draws import HUMAN_JOINTS, Draw, RunKey
from orchestrator.sweep.spec import SweepSpec
from orchestrator.sweep.tempdirs import WorkFolder
from prosthesis_controller.contact_clf_qp import ContactClfQp
from prosthesis_controller.contact_phase_pd import ContactPhasePD
from prosthesis_controller.interface import ControllerMode, ControlOutput
from prosthesis_controller.speed_following import SpeedFollowing

#: s: when a ``human.speed`` draw's person starts changing its speed
CHANGE_AT = 1.0
#: m/s^2: how fast it changes it (the held oracle walked 0.08 on gaitalytics' library, 0.7 to
#: 1.3 m/s, and fell at 0.12: the person takes the new speed's curves at each domain's entry)
ACCELERATION = 0.06
#: the sweep's controller names and what :func:`speed_following` calls them
_FOLLOWING = {"clfqp": "clfqp", "phase-pd": "contact-pd", "pd": "pd", "passive": "passive"}


def speed_change(start: float, end: float) -> SpeedProfile:
    """The speed a ``human.speed`` draw commands (m/s): ``start`` until :data:`CHANGE_AT`,
    then towards ``end`` at :data:`ACCELERATION`, then ``end``."""
    if start == end:
        return SpeedProfile.constant(start)
    return SpeedProfile((0.0, CHANGE_AT, CHANGE_AT + abs(end - start) / ACCELERATION),
                        (start, start, end))


def draw_gait(gait: ContactGait, draw: Draw) -> dict[Domain, np.ndarray]:
    """The packed curves the human tracks in a draw (module docstring): each human joint's
    offset on its rows, then the Bezier perturbation."""
    params = {}
    for d, p in gait.params.items():
        alpha = np.array(p.alpha, float)
        for joint, off in zip(HUMAN_JOINTS, draw.output_offset, strict=True):
            if off != 0.0 and joint in d.y2_coords:
                alpha[d.y2_coords.index(joint)] += off
        params[d] = GaitParams(alpha, p.v_hip, p.p_min, p.p_max)
    thetas = {d.value: th for d, th in ContactGait(params, gait.rms).thetas().items()}
    return perturbed_thetas(thetas, draw.bezier_amplitude, draw.bezier_seed)


def posture_start(sim: HybridSimulator, start: tuple[np.ndarray, np.ndarray],
                  offsets: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """A person's start in its own posture: the cycle's start (q, qd at the start of the
    graph's first domain, a flat stance where every human joint is an output) with each human
    joint (:data:`HUMAN_JOINTS`) moved by its curve's offset (rad), placed again on the stance
    foot where the start has it, the base's velocity solving the foot at rest (the joints'
    rates kept).  Offsets of zero give the start itself.  A person whose posture differs stands
    in it from the first instant: started on the cycle's posture, its law pulled every joint
    by up to 3 deg within 0.1 s, and the stance foot left its cone."""
    q0, qd0 = start
    if not any(offsets):
        return start
    names = sim.model.coord_names
    q = np.array(q0, float)
    for joint, off in zip(HUMAN_JOINTS, offsets, strict=True):
        q[names.index(joint)] += off
    place = sim.mfs[f"place_{GRAPH.domains[0]}"]  # its outputs are overwritten by a call
    x_foot = -float(np.asarray(place(q0, qd0, 0.0)[0]).ravel()[0]) + float(q0[0])
    q_placed, qd_placed = (np.array(a, float).ravel() for a in place(q, qd0, x_foot))
    return q_placed, qd_placed


def prosthesis_start(sim: HybridSimulator, start: tuple[np.ndarray, np.ndarray],
                     knee: float, ankle: float) -> tuple[np.ndarray, np.ndarray]:
    """A start with the prosthesis's knee and ankle moved by ``knee`` and ``ankle`` (rad), as
    the paper's graph's ``start_<d>`` (:mod:`hp_model.placement`): the start's domain is a flat
    prosthesis stance, so its stance knee and ankle set the phase (the hip's progress over
    the stance foot depends on them alone); the human's joints go on the curves ``sim``
    tracks at that phase, their rates at its rate (the joints' of the start kept); placed on
    the stance foot where the start has it, the base's velocity solving the foot at rest.
    Offsets of zero give the start itself."""
    if knee == 0.0 and ankle == 0.0:
        return start
    domain = GRAPH.domains[0]
    names = sim.model.coord_names
    q0, qd0 = start
    q = np.array(q0, float)
    q[names.index("th_pk")] += knee
    q[names.index("th_pa")] += ankle
    place = sim.mfs[f"place_{domain}"]
    sole = sim.model.frame_index(sim.model.stance_frame(domain))
    x_foot = float(np.asarray(sim.mfs["frames"](q0, qd0)[0])[0, sole])

    def placed(q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q_p, qd_p = place(q, qd, x_foot)  # copies: the outputs are overwritten by a call
        return np.array(q_p, float).ravel(), np.array(qd_p, float).ravel()

    q, qd = placed(q, qd0)
    _, y2, dy2, _ = (np.array(a, float).ravel()
                     for a in sim.fs[f"outputs_{domain}"](q, qd, sim.thetas[domain]))
    for row, joint in enumerate(domain.y2_coords):
        if joint in HUMAN_JOINTS:  # a joint's output is its angle off its curve
            q[names.index(joint)] -= y2[row]
            qd[names.index(joint)] -= dy2[row]
    return placed(q, qd)


def draw_gains(draw: Draw) -> np.ndarray:
    """The human's gains (eps, kp, kd) in a draw: its stiffness s scales the bandwidth."""
    s = draw.human_stiffness
    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"human stiffness must be finite and > 0, got {s}")
    eps, kp, kd = GAINS
    return np.array([s * eps, s * s * kp, s * kd])


class ContactResources:
    """What a worker builds once from the artifacts of a multi-contact sweep: the gait's run
    (model, curves, fitted cycle), its compiled closed loop, the tube when there is one and
    the two controllers (made from the held oracle's walk; ``clfqp`` with the tube's
    model-error bound, its robust term, when it carries one)."""

    def __init__(self, artifacts: Any, workdir: Path | None = None) -> None:
        from hp_model.force_tube import load_tube

        self.digest = artifacts.digest()
        self.setup_id = f"{socket.gethostname()}:{os.getpid()}:{time.time_ns()}"
        self._folder = WorkFolder(self.digest[:12], workdir)
        gait_path = self._folder.path / "gait.json"
        gait_path.write_bytes(artifacts.gait)
        self.run = load_contact_run(gait_path)
        sim = loop_simulator(self.run.model, self.run.gait, GAINS)
        self.closed_loop = sim.cl
        #: the Bezier degree of the gait's curves
        self.degree = sim.cl.degree
        #: the walkers of other armatures (factor -> model, closed loop)
        self._walkers: dict[float, tuple[HumanProsthesisModel, ClosedLoop]] = {}
        setup = LoopSetup(sim, held_walk(sim, self.run.trajectory))
        self.tube = None
        if artifacts.tube is not None:
            tube_path = self._folder.path / "tube.json"
            tube_path.write_bytes(artifacts.tube)
            self.tube = load_tube(tube_path, self.run.hash)
        self._library: tuple[GaitLibrary, ClosedLoop] | None = None
        self._library_bytes = artifacts.library
        #: the controllers that follow the person's speed over the library (made when a
        #: draw first needs one)
        self._following: dict[str, SpeedFollowing] = {}
        self._setup = setup
        self._controllers: dict[str, ContactClfQp | ContactPhasePD] = {}

    def controller(self, name: str) -> ContactClfQp | ContactPhasePD:
        """The sweep's controller ``name`` on the gait (made when a run first needs it:
        ``clfqp`` with the tube's model-error bound, its robust term)."""
        if name not in self._controllers:
            run = self.run
            self._controllers[name] = make_controller(
                name, run.model, run.gait, run.trajectory, self._setup,
                model_error=self.tube.model_error if self.tube is not None else None)
        return self._controllers[name]

    def plant(self, draw: Draw) -> HybridSimulator:
        """The simulated walker of a draw: the draw's curves and gains on the shared closed
        loop, or, with another armature, on that walker's (made once per worker and
        armature; compiled once, then cached on disk by its source: about 20 s)."""
        model, cl = self.run.model, self.closed_loop
        if draw.armature != 1.0:
            if draw.armature not in self._walkers:
                m = HumanProsthesisModel(model.subject,
                                         model.device.with_armature_scaled(draw.armature),
                                         graph=GRAPH)
                self._walkers[draw.armature] = (m, ClosedLoop(m, self.degree))
            model, cl = self._walkers[draw.armature]
        return HybridSimulator(model, cl, draw_gait(self.run.gait, draw), draw_gains(draw))

    @property
    def library(self) -> tuple[GaitLibrary, ClosedLoop]:
        """The spec's gait library and its walker's closed loop (made once per worker;
        ValueError without one)."""
        if self._library is None:
            if self._library_bytes is None:
                raise ValueError("a human.speed draw needs the spec's 'library'")
            path = self._folder.path / "library.json"
            path.write_bytes(self._library_bytes)
            lib = load_gait_library(path)
            self._library = lib, ClosedLoop(lib.model,
                                            lib.curves[0].params[GRAPH.domains[0]].degree)
        return self._library

    def following(self, controller: str) -> SpeedFollowing:
        """``controller`` following the person's speed over the library (made once per
        worker: each library speed's held walk and controller, its estimate's calibration
        walks; 10-30 s)."""
        if controller not in self._following:
            lib, cl = self.library
            self._following[controller] = speed_following(lib, _FOLLOWING[controller],
                                                          closed_loop=cl)
        return self._following[controller]

    def close(self) -> None:
        self._folder.close()


def speed_walk(res: ContactResources, controller: str, draw: Draw, steps: int
               ) -> tuple[SimResult, Counter[ControllerMode], int]:
    """A ``human.speed`` draw's run (module docstring): its log, modes and fallbacks."""
    from orchestrator.sweep.runs import encoder_of

    assert draw.speed_start is not None and draw.speed_end is not None
    lib, cl = res.library
    profile = speed_change(draw.speed_start, draw.speed_end)
    sim = loop_simulator(lib.model, lib.gait_at(draw.speed_start), GAINS, cl)
    schedule, start = speed_schedule(lib, profile), start_at(lib, draw.speed_start)
    if controller == ORACLE:
        policy = held_oracle(sim.cl, {Domain(d): th for d, th in sim.thetas.items()},
                             sim.gains, within_limits=True)
        log = sim.run(*start, GRAPH.domains[0], steps=steps, duration=2.0 * steps,
                      policy=policy, gaits=schedule)
        return log, Counter(), 0
    ctl = res.following(controller)
    ctl.restart(draw.speed_start)
    modes: Counter[ControllerMode] = Counter()

    def count(out: ControlOutput) -> None:
        modes[out.diagnostics.mode] += 1

    log = controller_run(sim, lib.gaits[0].trajectory, ctl, steps, encoder_of(draw), count,
                         gaits=schedule, start=start)
    return log, modes, int(ctl.fallbacks)


def walk(res: ContactResources, controller: str, draw: Draw, steps: int
         ) -> tuple[SimResult, Counter[ControllerMode], int]:
    """One run's log, its controller's modes tick by tick and its fallbacks."""
    from orchestrator.sweep.runs import encoder_of

    if draw.speed_start is not None:
        return speed_walk(res, controller, draw, steps)
    sim = res.plant(draw)
    thetas = {Domain(k): th for k, th in sim.thetas.items()}
    start = posture_start(sim, start_state(res.run.trajectory), draw.output_offset)
    start = prosthesis_start(sim, start, draw.knee_offset, draw.ankle_offset)
    schedule = (varying_pace(thetas, draw.stride_cv, draw.stride_seed, res.degree)
                if draw.stride_cv != 0.0 else None)
    if controller == ORACLE:
        policy = held_oracle(sim.cl, thetas, sim.gains, within_limits=True)
        log = sim.run(*start, GRAPH.domains[0], steps=steps, duration=2.0 * steps,
                      policy=policy, gaits=schedule)
        return log, Counter(), 0
    ctl = res.controller(controller)
    ctl.reset()
    modes: Counter[ControllerMode] = Counter()

    def count(out: ControlOutput) -> None:
        modes[out.diagnostics.mode] += 1

    log = controller_run(sim, res.run.trajectory, ctl, steps, encoder_of(draw), count,
                         gaits=schedule, start=start)
    return log, modes, int(ctl.fallbacks)


def result_columns(res: ContactResources, log: SimResult, modes: Counter[ControllerMode],
                   fallbacks: int, steps: int) -> dict[str, Any]:
    """The measured columns of one run (the paper's rows', module docstring)."""
    fall = log.fall
    tq = np.asarray(log.u[:, 4:6], float)
    finite = bool(np.all(np.isfinite(tq)))
    peak = np.abs(tq).max(axis=0) if tq.size else np.zeros(2)
    knee, _ = stride_rms(log, res.run)
    knee_rad = finite_or_none(math.radians(knee))
    return {"steps_completed": int(log.steps), "success": fall is None and log.steps >= steps,
            "failed": fall is not None,
            "reason": fall.message() if fall is not None else "",
            "fall_reason": fall.reason.label if fall is not None else None,
            "fail_t": finite_or_none(fall.t) if fall is not None else None,
            "fail_tau": finite_or_none(fall.tau) if fall is not None else None,
            "fail_domain": str(fall.domain) if fall is not None else None,
            "duration_s": float(log.t[-1]) if log.t.size else 0.0,
            "knee_rms_ps_rad": knee_rad, "knee_rms_all_rad": knee_rad,
            "fallback_count": fallbacks,
            "fallback_ticks": int(modes.get(ControllerMode.FALLBACK, 0)),
            "fault_ticks": int(modes.get(ControllerMode.FAULT, 0)),
            "max_torque_knee": finite_or_none(peak[0]) if finite else None,
            "max_torque_ankle": finite_or_none(peak[1]) if finite else None,
            "torque_finite": finite,
            "socket_force_in_tube": (None if res.tube is None else
                                     finite_or_none(share_inside(res.tube, res.run.model, log)))}


def run_contact_draw(res: ContactResources, spec: SweepSpec, key: RunKey, draw: Draw
                     ) -> dict[str, Any]:
    """One run of a multi-contact sweep: never raises for an error of the run itself."""
    from orchestrator.sweep.runs import measured_row

    def measure() -> dict[str, Any]:
        log, modes, fallbacks = walk(res, key.controller, draw, spec.steps)
        return result_columns(res, log, modes, fallbacks, spec.steps)

    return measured_row(spec, res.digest, res.setup_id, key, draw, measure)
