"""A gait library over walking speed: the person's multi-contact gait (:mod:`.multicontact`)
fitted again at other speeds by the same optimization, each fit continued from its
neighbour's (the fitted gait first), written as one artifact.

At a speed v, the targets are the take's (its tracked angles, its flat feet's pitch), with

- the speed v (the fit's speed term weighted ``w_speed``),
- each domain's duration the take's times (v0 / v) ** ``cadence_exponent`` (v0 the take's
  speed): a person walking faster lengthens the stride and quickens the cadence together,
  about equally in log terms (stride length and cadence both about proportional to v ** 0.5
  over 0.7-1.6 m/s; Grieve and Gear, Ergonomics 9, 1966; Dean, Ergonomics 8, 1965),
- no force plates: the take's forces are the take's speed's;
- the tracked angles weighted ``w_angles`` (a tenth of the fit of the take's own speed) and
  no fourth solve on the angles' limit: a person's knee flexes more as they walk faster, so
  the take's angles are a template, not a measurement, away from its speed.

The fits run outward from the fitted gait's speed (up, then down), each starting from the
nearest speed's result (:func:`characterization.gait.multicontact.cycle_guess`): a
continuation in speed.  On gaitalytics' treadmill take (1.05 m/s) fits at 0.86 and 1.29 m/s
converged in 91 and 142 iterations from its fitted gait.

Artifact (``kind = "hpcosim-gait-library"``, ``schema_version = 1``; SI units, rad):

    model_hash, subject, device    the model (as the gait file's; it remakes the model)
    domain_graph, domains          "multicontact" and its domains in walking order
    source                         the fitted gait: {file, hash (its cycle's), speed m/s}
    options                        the library's settings and the fit's
    gaits                          by increasing speed, each {speed m/s (the fit's), target
                                   m/s, stride {length, time, speed}, trajectory (per domain
                                   as the gait file's), solver {status, iterations, seconds},
                                   closed_loop (the held oracle's walk of 10 steps), source
                                   (true for the fitted gait itself)}

:func:`load_gait_library` reads it back; :meth:`GaitLibrary.gait_at` gives the virtual
constraints at any speed in its range (each coefficient interpolated linearly between the
two nearest speeds' regressed curves).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from characterization.gait.contact_gait import (
    ContactGait,
    ContactWalk,
    contact_gait_of,
    start_state,
    walk_contact_gait,
)
from characterization.gait.multicontact import (
    GRAPH,
    MultiContactError,
    MultiContactOptions,
    MultiContactTargets,
    cycle_guess,
    fit_multicontact,
)
from characterization.gait.multicontact_artifact import ContactCycle, model_of
from hp_model.artifacts import ArtifactError, load_json, save_json
from hp_model.domains import Domain
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import GaitParams
from hp_model.simulator import GaitSchedule
from hp_model.speed_profile import SpeedProfile

KIND = "hpcosim-gait-library"
SCHEMA_VERSION = 1
#: m/s: a requested speed this close to the fitted gait's is the fitted gait
SAME_SPEED = 0.03
#: the speeds a library spans by default (m/s): a person's slow to brisk walking
DEFAULT_SPEEDS = (0.6, 0.8, 1.0, 1.2, 1.4)


@dataclass(frozen=True)
class LibraryOptions:
    """How the gaits at other speeds are fitted (module docstring)."""

    w_angles: float = 100.0  # 1 / (rad^2 s), a tenth of the take's own fit
    w_speed: float = 3000.0  # s^2 / m^2, ten times the take's own fit
    cadence_exponent: float = 0.5  # durations x (v0 / v) ** this
    steps: int = 10  # steps each gait is walked with the held oracle

    def __post_init__(self) -> None:
        if not (self.w_angles >= 0 and self.w_speed > 0):
            raise MultiContactError("library: w_angles must be >= 0 and w_speed > 0")
        if not 0.0 <= self.cadence_exponent <= 1.0:
            raise MultiContactError(f"library: cadence_exponent {self.cadence_exponent} "
                                    "must be in [0, 1]")
        if self.steps < 1:
            raise MultiContactError("library: steps must be >= 1")


def speed_targets(targets: MultiContactTargets, speed: float, exponent: float
                  ) -> MultiContactTargets:
    """The take's targets moved to walking ``speed`` (m/s; module docstring): its angles,
    durations times (v0 / speed) ** ``exponent``, no force plates."""
    k = targets.speed / speed
    return replace(targets, speed=float(speed), stance_fz={},
                   durations={d: T * k ** exponent for d, T in targets.durations.items()})


@dataclass(frozen=True)
class LibraryGait:
    """One speed of the library: the fitted cycle (per domain ``t``, ``q``, ``qd``, ``qdd``,
    ``u``, ``lam``; durations s), its stride, the fit's solver record, the held oracle's
    walk, and whether it is the fitted gait itself."""

    target: float  # m/s
    trajectory: dict[Domain, dict[str, np.ndarray]]
    durations: dict[Domain, float]
    stride_length: float  # m
    solver: dict[str, Any]
    walk: ContactWalk | None
    source: bool = False

    @property
    def stride_time(self) -> float:
        return float(sum(self.durations[d] for d in GRAPH.domains))

    @property
    def speed(self) -> float:
        """The fitted cycle's mean speed (m/s)."""
        return self.stride_length / self.stride_time

    def to_json(self) -> dict[str, Any]:
        return {"speed": self.speed, "target": self.target,
                "stride": {"length": self.stride_length, "time": self.stride_time,
                           "speed": self.speed},
                "trajectory": {d.value: {"duration": self.durations[d], **self.trajectory[d]}
                               for d in GRAPH.domains},
                "solver": self.solver, "source": self.source,
                "closed_loop": None if self.walk is None else self.walk.to_json()}


def _stride_length(trajectory: Mapping[Domain, Mapping[str, np.ndarray]]) -> float:
    """The hip's travel over the cycle (m): the stride."""
    first, last = trajectory[GRAPH.domains[0]], trajectory[GRAPH.domains[-1]]
    return float(np.asarray(last["q"])[0, -1] - np.asarray(first["q"])[0, 0])


def source_gait(cycle: ContactCycle) -> LibraryGait:
    """The fitted gait as the library's entry at its own speed."""
    length = _stride_length(cycle.trajectory)
    entry = LibraryGait(0.0, {d: dict(tr) for d, tr in cycle.trajectory.items()},
                        dict(cycle.durations), length, {"status": "the fitted gait"}, None,
                        source=True)
    return replace(entry, target=entry.speed)


def fit_library(model: HumanProsthesisModel, targets: MultiContactTargets,
                cycle: ContactCycle, speeds: Sequence[float],
                fit_options: MultiContactOptions | None = None,
                options: LibraryOptions | None = None,
                progress: Callable[[str], None] | None = None) -> list[LibraryGait]:
    """The library (module docstring): the fitted ``cycle`` (made from ``targets``) and a fit
    at each of ``speeds`` (m/s) but those within :data:`SAME_SPEED` of its own, by
    increasing speed, each walked by the held oracle.  MultiContactError when a fit does not
    converge (naming the speed)."""
    opt = options or LibraryOptions()
    fit_opt = replace(fit_options or MultiContactOptions(), w_angles=opt.w_angles,
                      w_speed=opt.w_speed, w_angle_limit=0.0, w_force=0.0)
    base = source_gait(cycle)
    wanted = sorted({round(float(v), 6) for v in speeds})
    for v in wanted:
        if not (np.isfinite(v) and 0.2 <= v <= 2.5):
            raise MultiContactError(f"library: speed {v} m/s is outside 0.2-2.5 m/s")
    up = [v for v in wanted if v > base.speed + SAME_SPEED]
    down = [v for v in reversed(wanted) if v < base.speed - SAME_SPEED]
    P = 2 * fit_opt.nodes - 1
    fitted: list[LibraryGait] = [base]
    for chain in (up, down):
        last = base
        for v in chain:
            if progress is not None:
                progress(f"gait library: {v:.2f} m/s (from {last.speed:.2f})")
            res = fit_multicontact(model, speed_targets(targets, v, opt.cadence_exponent),
                                   fit_opt, cycle_guess(last.trajectory, last.durations, P))
            if not res.success:
                raise MultiContactError(f"gait library: the fit at {v:.2f} m/s did not "
                                        f"converge ({res.status} after {res.iterations} "
                                        "iterations)")
            last = LibraryGait(v, res.trajectory, res.durations, res.stride_length,
                               {"status": res.status, "iterations": res.iterations,
                                "seconds": res.solve_seconds, "cost": res.cost}, None)
            fitted.append(last)
    walked = []
    for g in sorted(fitted, key=lambda g: g.speed):
        if progress is not None:
            progress(f"gait library: walking {g.speed:.2f} m/s")
        gait = contact_gait_of(model, g.trajectory, g.durations)
        walked.append(replace(g, walk=walk_contact_gait(model, gait, g.trajectory,
                                                        steps=opt.steps)))
    return walked


def to_document(gaits: Sequence[LibraryGait], cycle: ContactCycle, source_file: str,
                subject: Mapping[str, Any], device: Mapping[str, Any],
                fit_options: MultiContactOptions, options: LibraryOptions) -> dict[str, Any]:
    """The artifact's JSON document (module docstring)."""
    base = next(g for g in gaits if g.source)
    return {"kind": KIND, "schema_version": SCHEMA_VERSION,
            "model_hash": cycle.model.parameter_hash(), "subject": dict(subject),
            "device": dict(device), "domain_graph": GRAPH.value,
            "domains": [d.value for d in GRAPH.domains],
            "source": {"file": os.path.basename(source_file), "hash": cycle.hash,
                       "speed": base.speed},
            "options": {"library": asdict(options), "fit": asdict(fit_options)},
            "gaits": [g.to_json() for g in sorted(gaits, key=lambda g: g.speed)]}


def save_gait_library(path: str | os.PathLike[str], doc: Mapping[str, Any]) -> None:
    """Write the document atomically (strict JSON)."""
    save_json(path, dict(doc))


@dataclass(frozen=True)
class GaitLibrary:
    """A gait library read back: its model, and per speed (increasing) the fitted cycle and
    its regressed virtual constraints."""

    model: HumanProsthesisModel
    gaits: tuple[LibraryGait, ...]
    curves: tuple[ContactGait, ...]

    @property
    def speeds(self) -> np.ndarray:
        """The gaits' speeds (m/s), increasing."""
        return np.array([g.speed for g in self.gaits])

    def _between(self, speed: float) -> tuple[int, float]:
        """The lower of the two nearest speeds' places and the weight of the upper one at
        ``speed`` (m/s, clamped to the library's range; (0, 0) for a single speed)."""
        v = self.speeds
        if len(v) == 1:
            return 0, 0.0
        s = float(np.clip(speed, v[0], v[-1]))
        j = int(np.clip(np.searchsorted(v, s) - 1, 0, len(v) - 2))
        return j, (s - v[j]) / (v[j + 1] - v[j])

    @functools.cached_property
    def _thetas(self) -> tuple[dict[Domain, np.ndarray], ...]:
        return tuple(c.thetas() for c in self.curves)

    def theta_at(self, speed: float, domain: Domain) -> np.ndarray:
        """``domain``'s packed gait at ``speed`` (m/s): :meth:`gait_at`'s, interpolated
        packed (the same numbers, without making the whole gait: a person changing speed
        asks for it at every domain's entry, the FMU's master at every period)."""
        j, w = self._between(speed)
        if len(self.curves) == 1:
            return self._thetas[0][domain].copy()
        return (1 - w) * self._thetas[j][domain] + w * self._thetas[j + 1][domain]

    def gait_at(self, speed: float) -> ContactGait:
        """The virtual constraints at ``speed`` (m/s; clamped to the library's range): each
        domain's coefficients, v_hip, p_min and p_max interpolated linearly between the two
        nearest speeds."""
        if len(self.curves) == 1:
            return self.curves[0]
        j, w = self._between(speed)
        a, b = self.curves[j], self.curves[j + 1]
        params = {}
        for d in GRAPH.domains:
            pa, pb = a.params[d], b.params[d]
            params[d] = GaitParams((1 - w) * np.asarray(pa.alpha) + w * np.asarray(pb.alpha),
                                   (1 - w) * pa.v_hip + w * pb.v_hip,
                                   (1 - w) * pa.p_min + w * pb.p_min,
                                   (1 - w) * pa.p_max + w * pb.p_max)
        return ContactGait(params, {d: np.maximum(a.rms[d], b.rms[d]) for d in GRAPH.domains})

    def stride_at(self, speed: float) -> float:
        """The stride period (s) of the curves at ``speed`` (:meth:`gait_at`): each domain's
        hip progress over its mean rate, summed (the person's stride when it walks them;
        what a controller reads the person's speed from)."""
        g = self.gait_at(speed)
        return float(sum((p.p_max - p.p_min) / p.v_hip for p in g.params.values()))


def start_at(library: GaitLibrary, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """The walker's state (q, qd) at the start of the cycle at ``speed`` (m/s, clamped to
    the library's range): the two nearest speeds' fitted starts blended as
    :meth:`GaitLibrary.gait_at` blends their curves, placed on the first domain's stance
    foot (:meth:`hp_model.hybrid.HybridModel.stance_state`)."""
    v = library.speeds
    s = float(np.clip(speed, v[0], v[-1]))
    j = int(np.clip(np.searchsorted(v, s) - 1, 0, max(len(v) - 2, 0)))
    starts = [start_state(g.trajectory) for g in library.gaits]
    if len(v) == 1:
        return starts[0]
    w = (s - v[j]) / (v[j + 1] - v[j])
    q = (1 - w) * starts[j][0] + w * starts[j + 1][0]
    qd = (1 - w) * starts[j][1] + w * starts[j + 1][1]
    return library.model.stance_state(q, qd, GRAPH.domains[0].value)


def load_gait_library(path: str | os.PathLike[str]) -> GaitLibrary:
    """The library of a file written by ``hpcosim gait library`` (ArtifactError naming the
    file and field when it is not one)."""
    doc = dict(load_json(path, KIND, SCHEMA_VERSION))
    model = model_of(doc, path)
    if doc.get("model_hash") != model.parameter_hash():
        raise ArtifactError(f"{path}: field 'model_hash': the file was made for another "
                            "model than its own subject and device give")
    gaits = []
    try:
        for k, g in enumerate(doc["gaits"]):
            traj = {d: {n: np.asarray(v, float) for n, v in g["trajectory"][d.value].items()
                        if n != "duration"} for d in GRAPH.domains}
            durations = {d: float(g["trajectory"][d.value]["duration"]) for d in GRAPH.domains}
            gaits.append(LibraryGait(float(g["target"]), traj, durations,
                                     float(g["stride"]["length"]), dict(g["solver"]), None,
                                     bool(g.get("source", False))))
            if not np.isfinite(gaits[-1].speed):
                raise ValueError(f"gait {k}: no finite speed")
    except (KeyError, TypeError, ValueError) as e:
        raise ArtifactError(f"{path}: field 'gaits': {e}") from None
    if not gaits:
        raise ArtifactError(f"{path}: field 'gaits': empty")
    speeds = np.array([g.speed for g in gaits])
    if np.any(np.diff(speeds) <= 0):
        raise ArtifactError(f"{path}: field 'gaits': speeds {np.round(speeds, 3).tolist()} "
                            "do not increase")
    try:
        curves = tuple(contact_gait_of(model, g.trajectory, g.durations) for g in gaits)
    except MultiContactError as e:
        raise ArtifactError(f"{path}: field 'gaits': {e}") from None
    return GaitLibrary(model, tuple(gaits), curves)


def speed_schedule(library: GaitLibrary, profile: SpeedProfile) -> GaitSchedule:
    """The simulated person walking ``library`` at the speed ``profile`` commands: entering
    a domain at t s, it tracks that domain's curves at the commanded speed
    (:meth:`GaitLibrary.gait_at`; the hip's rate output then brings its speed there within
    the step)."""

    def gait(d: Domain, t: float) -> np.ndarray:
        return library.theta_at(profile.at(t), d)

    return gait
