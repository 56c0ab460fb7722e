"""The multi-contact controllers of a gait, made for a run: what ``clfqp``
(:class:`prosthesis_controller.contact_clf_qp.ContactClfQp`), its phase law ``contact-pd``
(:class:`prosthesis_controller.contact_phase_pd.ContactPhasePD`) and the paper's baselines on
this graph (``pd``, ``passive``: :func:`make_baseline`) follow, and what the human FMU tracks
(:func:`tracked_gait`).

The controllers' tables come from one stride of the in-process plant
(:class:`orchestrator.loop.plant.SimulatorPlant`: what AMPRO3 senses) with the prosthesis
holding the full feedback linearization's torque
(:func:`characterization.gait.contact_gait.held_oracle`), sensed the same way: the gait as
the model walks it (:func:`held_walk`); the CLF-QP's model is evaluated along the same
stance (the walker's states, wrenches and torques there).  The co-simulation writes them to
a file for the controller process (:mod:`prosthesis_controller.gait_tables`); the in-process
walks (:mod:`orchestrator.experiments.contact_walk`) use them directly.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

import hp_model.contact_interaction
import hp_model.contact_outputs
import hp_model.simulator
from characterization.gait.contact_gait import (
    GAINS,
    ContactGait,
    contact_gait_of,
    held_oracle,
    start_state,
)
from characterization.gait.multicontact import GRAPH
from characterization.gait.multicontact_artifact import load_contact_cycle
from characterization.tube.contact_model_error import Linearization, fit_contact_model_error
from characterization.tube.contact_playback import ContactTubeResult
from characterization.tube.fit import TubeFitError
from hp_model.artifacts import canonical_hash
from hp_model.closed_loop import ClosedLoop
from hp_model.compiled import cache_root
from hp_model.contact_interaction import ContactInteraction, wrench_size
from hp_model.domains import Domain
from hp_model.force_tube import ModelErrorBound
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.leg_kinematics import LegKinematics
from hp_model.simulator import HybridSimulator
from human_fmu.build import TrackedGait
from orchestrator.loop.plant import SimulatorPlant
from prosthesis_controller import contact_clf_qp, contact_phase_pd, gait_tables, passive, pd
from prosthesis_controller.contact_clf_qp import (
    DEFAULT_CONFIG,
    MAX_WRENCH,
    ContactClfConfig,
    ContactClfQp,
    WalkedStance,
    stance_qp,
)
from prosthesis_controller.contact_phase_pd import (
    DEFAULT_SWING_PHASE,
    STANCE_GAINS,
    SWING_GAINS,
    ContactGaitTables,
    ContactPhasePD,
    PDGains,
    PhaseTable,
    first_stride,
    tables_from_walk,
)
from prosthesis_controller.gait_tables import save_contact_controller
from prosthesis_controller.passive import ContactPassive, PassiveLaw, stance_accelerations
from prosthesis_controller.pd import ContactJointPD


def loop_simulator(model: HumanProsthesisModel, gait: ContactGait,
                   gains: tuple[float, float, float], closed_loop: ClosedLoop | None = None
                   ) -> HybridSimulator:
    """The in-process simulator of ``gait`` with the human's ``gains`` (eps, kp, kd);
    ``closed_loop``: the model's, when made already (it depends on the model and the
    curves' degree, not on the gait: 1-2 s to make)."""
    cl = closed_loop or ClosedLoop(model, gait.params[GRAPH.domains[0]].degree)
    return HybridSimulator(model, cl, gait.thetas(), np.array(gains))


class HeldOracleFellError(ValueError):
    """The gait does not walk even with the full-state prosthesis: no controller can be
    made from it (the tables come from that walk)."""


@dataclass(frozen=True)
class HeldWalk:
    """The held oracle's walk sampled each period: ``t`` (n,) s; ``sensed`` (n, 5) socket
    pitch, knee, ankle (rad), their rates (rad/s); ``contact`` (n,) the foot switch;
    ``torque`` (n, 2) the motor torques applied (N m); the plant's truth: ``domain`` (n,)
    codes, ``q``, ``qd`` (n, nq), ``wrench`` (n, 4) the contact wrenches under the torques
    applied (zero-padded), ``tau`` (n,) the person's phase in its domain (past 1: its
    designed touchdown passed, the person waiting for the ground on its resting tail)."""

    t: np.ndarray
    sensed: np.ndarray
    contact: np.ndarray
    torque: np.ndarray
    domain: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    wrench: np.ndarray
    tau: np.ndarray


def on_gait(domain: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Index (n,) of each sample of a walk (its ``domain`` codes and the person's phase
    ``tau``, (n,)) or, past its domain's designed touchdown (tau > 1), of the last sample of
    the same domain before it that was not: where a walk is the gait's.  Past tau 1 the
    person's law holds a resting tail, its torques change at once (the held oracle's
    prosthesis torque by 0.9 N m motor in the packaged person's last two milliseconds of
    ``ps_toe``): that is this walk's wait for the ground, not the gait."""
    index = np.arange(len(tau))
    for i in range(1, len(tau)):
        if tau[i] > 1.0 and domain[i] == domain[i - 1]:
            index[i] = index[i - 1]
    return index


def held_walk(sim: HybridSimulator, trajectory: Mapping[Domain, Mapping[str, Any]],
              start: tuple[np.ndarray, np.ndarray] | None = None) -> HeldWalk:
    """Two strides of the held oracle in the plant ``sim`` from the fitted cycle's start (a
    stride: the trajectory's domains' ends ``t``, s; ``start``: (q0, qd0) instead of the
    cycle's).  ValueError if it falls."""
    stride = sum(float(np.asarray(trajectory[d]["t"])[-1]) for d in GRAPH.domains)
    q0, qd0 = start_state(trajectory) if start is None else start
    plant = SimulatorPlant(sim, q0, qd0, GRAPH.domains[0])
    policy = held_oracle(sim.cl, {Domain(d): th for d, th in sim.thetas.items()}, sim.gains)
    rows: list[tuple[Any, ...]] = []
    while plant.observe().t < 2.0 * stride + 0.1:
        obs = plant.observe()
        st = plant.run.observe()
        torque = policy(obs.t, st)
        s = obs.sensed
        applied = plant.actuate(torque).torque
        # the wrench under the torque applied, not the one observed before it (under the
        # last period's): at a heel strike that was the swing's, and the stance QP's first
        # sample paired the stance torque with a heel pulling 0.2-0.5 kN
        wrench = np.zeros(MAX_WRENCH)
        n = wrench_size(st.domain)
        wrench[:n] = plant.run.last_sample()[3][:n]
        rows.append((obs.t, (s.socket_pitch, s.knee_angle, s.ankle_angle, s.knee_velocity,
                             s.ankle_velocity), s.contact, applied, st.domain.code,
                     st.q.copy(), st.qd.copy(), wrench, st.tau))
        if plant.fall is not None:
            raise HeldOracleFellError(f"the held oracle fell in the stride the tables are read "
                                 f"from: {plant.fall.message()}")
        plant.advance()
    cols = list(zip(*rows, strict=True))
    return HeldWalk(*(np.array(c) for c in cols))


@dataclass(frozen=True)
class LoopSetup:
    """What several walks of one gait can share: its in-process simulator
    (:func:`loop_simulator`) and the held oracle's walk (:func:`held_walk`; None: not made,
    or it fell)."""

    sim: HybridSimulator
    held: HeldWalk | None


def controller_tables(sim: HybridSimulator, leg: LegKinematics,
                      trajectory: Mapping[Domain, Mapping[str, Any]]) -> ContactGaitTables:
    """The tables of :func:`tables_from_walk` from :func:`held_walk`.  ValueError if it
    falls, or if the walk gives no tables."""
    w = held_walk(sim, trajectory)
    return tables_from_walk(leg, w.t, w.sensed, w.contact, w.torque)


def motors(model: HumanProsthesisModel) -> tuple[tuple[float, float], tuple[float, float]]:
    """The prosthesis's gear ratios and motor torque limits (N m), each (knee, ankle)."""
    p = model.device.prosthesis
    return ((p.knee.gear_ratio.value, p.ankle.gear_ratio.value),
            (p.knee.torque_limit.value, p.ankle.torque_limit.value))


def phase_law(model: HumanProsthesisModel, tables: ContactGaitTables, leg: LegKinematics,
              stance: PDGains = STANCE_GAINS, swing: PDGains = SWING_GAINS,
              swing_phase: str = DEFAULT_SWING_PHASE) -> ContactPhasePD:
    return ContactPhasePD(tables, leg, *motors(model), stance, swing, swing_phase)


def walked_tables(model: HumanProsthesisModel, gait: ContactGait,
                  trajectory: Mapping[Domain, Mapping[str, Any]], setup: LoopSetup | None,
                  gains: tuple[float, float, float] = GAINS
                  ) -> tuple[LegKinematics, HeldWalk, ContactGaitTables]:
    """The leg, :func:`held_walk` (``setup``'s when made already) and its tables
    (:func:`tables_from_walk`): what every controller of a gait is made from.  ValueError as
    :func:`controller_tables`."""
    leg = LegKinematics.of(model)
    w = (setup and setup.held) or held_walk(
        setup.sim if setup else loop_simulator(model, gait, gains), trajectory)
    return leg, w, tables_from_walk(leg, w.t, w.sensed, w.contact, w.torque)


def make_contact_pd(model: HumanProsthesisModel, gait: ContactGait,
                    trajectory: Mapping[Domain, Mapping[str, Any]],
                    setup: LoopSetup | None = None, swing_phase: str = DEFAULT_SWING_PHASE
                    ) -> ContactPhasePD:
    """contact-pd of ``gait`` with its default gains (:func:`walked_tables`);
    ``swing_phase``: :class:`ContactPhasePD`'s."""
    leg, _, tables = walked_tables(model, gait, trajectory, setup)
    return phase_law(model, tables, leg, swing_phase=swing_phase)


def make_baseline(name: str, model: HumanProsthesisModel, gait: ContactGait,
                  trajectory: Mapping[Domain, Mapping[str, Any]],
                  setup: LoopSetup | None = None, swing_phase: str = DEFAULT_SWING_PHASE,
                  passive_law: PassiveLaw | None = None) -> ContactPhasePD:
    """The paper's baseline ``name`` on the multi-contact graph (:data:`BASELINES`:
    :class:`~prosthesis_controller.pd.ContactJointPD`,
    :class:`~prosthesis_controller.passive.ContactPassive`) of ``gait``
    (:func:`walked_tables`); ``passive_law``: the device's compiled Spong law when made."""
    if name not in BASELINES:
        raise ValueError(f"baseline {name!r}: choose {' or '.join(BASELINES)}")
    leg, w, tables = walked_tables(model, gait, trajectory, setup)
    if name == "pd":
        return ContactJointPD(tables, leg, *motors(model), swing_phase=swing_phase)
    i0, i1, _ = first_stride(w.contact)
    accel = PhaseTable(tables.stance.phase,
                       stance_accelerations(w.t[i0:i1], w.sensed[i0:i1, 3:5]))
    return ContactPassive(tables, leg, *motors(model), passive_law or PassiveLaw(model), accel,
                          swing_phase=swing_phase)


def contact_clfqp(model: HumanProsthesisModel, gait: ContactGait,
                  trajectory: Mapping[Domain, Mapping[str, Any]],
                  gains: tuple[float, float, float] = GAINS,
                  config: ContactClfConfig = DEFAULT_CONFIG, *,
                  setup: LoopSetup | None = None,
                  model_error: ModelErrorBound | None = None,
                  swing_phase: str = DEFAULT_SWING_PHASE) -> ContactClfQp:
    """The CLF-QP of ``gait``: contact-pd's tables and the QP along the stance, both from
    the same stance of :func:`held_walk` (:func:`walked_tables`); ``model_error``: the
    bound of its model's error (the gait's force tube's, :func:`characterization.tube.
    contact_model_error.fit_contact_model_error`) for the robust term of its CLF row (None:
    none); ``swing_phase``: its phase law's (:class:`ContactPhasePD`)."""
    leg, w, tables = walked_tables(model, gait, trajectory, setup, gains)
    i0, i1, _ = first_stride(w.contact)
    # the stance's samples, each on the gait (on_gait): the QP's reference and model
    on = i0 + on_gait(w.domain[i0:i1], w.tau[i0:i1])
    inter = ContactInteraction(model, gait.params[GRAPH.domains[0]].degree).numeric()
    walked = WalkedStance(tables.stance.phase, w.domain[i0:i1], w.q[on], w.qd[on],
                          w.wrench[on], w.torque[on])
    stance = stance_qp(walked, inter, gait.thetas(), gains, model, config
                       ).with_margin(model_error)
    return ContactClfQp(phase_law(model, tables, leg, swing_phase=swing_phase), stance,
                        motors(model)[1], config)


def make_controller(name: str, model: HumanProsthesisModel, gait: ContactGait,
                    trajectory: Mapping[Domain, Mapping[str, Any]],
                    setup: LoopSetup | None = None, *, swing_phase: str = DEFAULT_SWING_PHASE,
                    model_error: ModelErrorBound | None = None,
                    passive_law: PassiveLaw | None = None) -> ContactClfQp | ContactPhasePD:
    """The multi-contact controller ``name`` of ``gait``: ``clfqp`` (:func:`contact_clfqp`,
    with ``model_error``), ``phase-pd`` or ``contact-pd`` (:func:`make_contact_pd`) or one of
    the paper's :data:`BASELINES` (:func:`make_baseline`, with ``passive_law``).  ValueError
    for another name, or as :func:`controller_tables`."""
    if name == "clfqp":
        return contact_clfqp(model, gait, trajectory, setup=setup, model_error=model_error,
                             swing_phase=swing_phase)
    if name in ("phase-pd", "contact-pd"):
        return make_contact_pd(model, gait, trajectory, setup, swing_phase)
    if name in BASELINES:
        return make_baseline(name, model, gait, trajectory, setup, swing_phase, passive_law)
    raise ValueError(f"controller {name!r}: choose clfqp, phase-pd (contact-pd), "
                     f"{', '.join(BASELINES)}")


def tracked_gait(model: HumanProsthesisModel, gait: ContactGait,
                 trajectory: Mapping[Domain, Mapping[str, Any]], name: str,
                 gains: tuple[float, float, float] = GAINS) -> TrackedGait:
    """What the human FMU tracks of ``gait`` (:func:`human_fmu.build_fmu`): its packed
    curves, the human's ``gains``, the fitted cycle's start; ``name`` the gait file's.  Its
    hash names the model, the gains and the curves."""
    thetas = gait.thetas()
    q0, qd0 = start_state(trajectory)
    identity = canonical_hash({"model_hash": model.parameter_hash(), "gains": list(gains),
                               "params": {d.value: thetas[d] for d in GRAPH.domains}})
    return TrackedGait(thetas, gains, q0, qd0, gait.params[GRAPH.domains[0]].degree,
                       identity, name)


@dataclass(frozen=True)
class ContactRun:
    """A multi-contact gait file as a run uses it: the model it carries, the stored cycle
    (trajectories, durations), its virtual constraints, what the human FMU tracks and the
    file's identity (``hash``: what a tube fitted around it names)."""

    model: HumanProsthesisModel
    trajectory: dict[Domain, dict[str, np.ndarray]]
    gait: ContactGait
    tracked: TrackedGait
    hash: str


def load_contact_run(path: str | os.PathLike[str]) -> ContactRun:
    """:class:`ContactRun` of a multi-contact gait file (the virtual constraints regressed
    from the stored cycle, the default gains); ArtifactError for a bad file,
    MultiContactError for a cycle with no phase."""
    cycle = load_contact_cycle(path)
    gait = contact_gait_of(cycle.model, cycle.trajectory, cycle.durations)
    return ContactRun(cycle.model, cycle.trajectory, gait,
                      tracked_gait(cycle.model, gait, cycle.trajectory, Path(path).name),
                      cycle.hash)


def load_tracked_gait(path: str | os.PathLike[str]
                      ) -> tuple[HumanProsthesisModel, TrackedGait]:
    """The model of a multi-contact gait file and what the human FMU tracks of it
    (:func:`load_contact_run`)."""
    run = load_contact_run(path)
    return run.model, run.tracked


#: the paper's baselines on the multi-contact graph (:func:`make_baseline`)
BASELINES = ("pd", "passive")

#: the sources whose code decides a controller file's content (its cache key)
MAKERS = (Path(__file__), *(Path(str(m.__file__)) for m in (
    contact_clf_qp, contact_phase_pd, gait_tables, passive, pd, hp_model.contact_interaction,
    hp_model.contact_outputs, hp_model.simulator)))


def ensure_controller_file(gait_path: Path, run: ContactRun,
                           say: Callable[[str], None] | None = None,
                           tube: tuple[Path, ModelErrorBound | None] | None = None,
                           controller: str = "clfqp") -> Path:
    """The file of ``controller`` (one of :data:`prosthesis_controller.gait_tables.LAWS`) of
    the multi-contact gait at ``gait_path`` (``run``: it loaded;
    :mod:`prosthesis_controller.gait_tables`), made once and cached (``$HPCOSIM_CACHE`` or
    ``~/.cache/hpcosim``/controller/<digest>/<controller>.npz; the digest covers the gait
    file, the model, the curves the human tracks, the tube file and the code that makes the
    controller); ``tube``: the tube file and its model-error bound, ``clfqp``'s robust term.
    ValueError for another controller, or if the held oracle falls in the stride the tables
    are read from."""
    if controller not in gait_tables.LAWS:
        raise ValueError(f"controller {controller!r}: a multi-contact gait's controller file "
                         f"holds one of {', '.join(gait_tables.LAWS)}")
    h = hashlib.sha256(Path(gait_path).read_bytes())
    if tube is not None:
        h.update(Path(tube[0]).read_bytes())
    h.update(run.model.parameter_hash().encode())
    h.update(run.tracked.hash.encode())  # the curves the human tracks, however regressed
    for f in MAKERS:
        h.update(f.read_bytes())
    out = cache_root() / "controller" / h.hexdigest()[:16] / f"{controller}.npz"
    if not out.is_file():
        (say or (lambda _m: None))("making the controller's tables (the gait walked once)")
        out.parent.mkdir(parents=True, exist_ok=True)
        ctl = make_controller(controller, run.model, run.gait, run.trajectory,
                              model_error=tube[1] if tube is not None else None)
        save_contact_controller(out, ctl, run.model, run.tracked.hash)
    return out


def controller_linearization(ctl: ContactClfQp) -> Linearization:
    """What the model-error characterization needs of ``clfqp``'s model along its stance."""
    st = ctl.stance
    return Linearization(st.phase, st.g, st.u_ref, st.qdd_ref, ctl.law.tables.progress)


def tube_with_model_error(res: ContactTubeResult, run: ContactRun) -> ContactTubeResult:
    """``res`` with its tube carrying the bound of ``clfqp``'s model error along the same
    playbacks (:mod:`characterization.tube.contact_model_error`, at the tube's degree and
    over its phase range); when the playbacks cannot give one, the tube's
    ``source["model_error"]`` says why.  ValueError as :func:`contact_clfqp` (the held
    oracle fell)."""
    tube = res.tube
    lin = controller_linearization(contact_clfqp(run.model, run.gait, run.trajectory))
    try:
        bound = fit_contact_model_error(run.model, lin, res.playbacks, tube.degree,
                                        (tube.tau_lo, tube.tau_hi))
    except TubeFitError as e:
        return replace(res, tube=replace(tube, source={**tube.source,
                                                       "model_error": f"not fitted: {e}"}))
    return replace(res, tube=replace(tube, model_error=bound))
