"""Refitting from co-simulation recordings (the recording's ``/ground_truth`` and
``/controller/disturbance``): the force tube around the gait's F* (the paper's graph: the ps
portions; a multi-contact gait: its flat single supports in the controllers' stance phase)
and the model-error bound of ``clfqp``'s nominal-human model."""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from bus_schemas.recording.reader import read_messages
from hp_model.domains import Domain
from orchestrator.cosim.recording import RecordingError, read_recording


def ps_profiles(path: str | Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Recorded ground-truth socket force of every complete prosthesis-stance (ps) portion:
    (tau (n,), F_s (n, 3)). A ps portion is complete when it starts at the run start or at
    an impact into ps and ends with the impact into pns."""
    rows = [o for _, _, o in read_messages(path, ["/ground_truth"])]
    out, cur, complete_start = [], [], True
    prev = None
    for o in rows:
        d = o["domain"]  # the domain's word
        if d == Domain.PS:
            if prev == Domain.PNS:
                cur, complete_start = [], True
            f = o["socket_force"]
            cur.append((o["tau"], f["Fx"], f["Fz"], f["My"]))
        elif prev == Domain.PS and cur and complete_start:
            a = np.array(cur, dtype=float)
            out.append((a[:, 0], a[:, 1:]))
            cur = []
        prev = d
    return out


def refit_tube(paths: Iterable[str | Path], gait_path: str | Path, out: str | Path, *,
               old_tube: str | Path | None = None, degree: int = 3,
               model: Any = None) -> dict[str, Any]:
    """Refit the force tube from the recorded ps portions of ``paths``; report coverage of
    the old tube (``old_tube``, default the tube attached to the first recording): the
    fraction of samples and of steps inside it."""
    import hp_model
    from characterization.tube.fit import fit_tube, nominal_coefficients
    from hp_model.force_tube import save_tube
    from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind, load_gait

    if artifact_kind(gait_path) == MULTICONTACT_KIND:
        return refit_contact_tube(paths, gait_path, out, old_tube=old_tube, degree=degree)
    model = model or hp_model.load_model()
    gait = load_gait(gait_path, model.parameter_hash())
    paths = [Path(p) for p in paths]
    check_recorded_gait(paths, gait.hash(), gait_path,
                        lambda f: load_gait(f, model.parameter_hash()).hash())
    steps: list[tuple[np.ndarray, np.ndarray]] = []
    for p in paths:
        steps.extend(ps_profiles(p))
    if len(steps) < degree + 2:
        raise RecordingError(f"{len(steps)} complete ps steps in {len(paths)} recordings; "
                             f"need at least {degree + 2}")
    tau_lo = max(0.0, max(float(s[0].min()) for s in steps))
    tau_hi = min(1.0, min(float(s[0].max()) for s in steps))
    nominal = nominal_coefficients(gait, tau_lo, tau_hi)
    profiles = []
    for tau, fs in steps:
        keep = (tau >= tau_lo) & (tau <= tau_hi)
        profiles.append((tau[keep], fs[keep] - gait.socket_force(tau[keep])))
    tube = fit_tube(profiles, nominal, tau_lo, tau_hi, degree=degree, gait_hash=gait.hash(),
                    source={"recordings": [str(p) for p in paths]})
    old = _old_tube(paths[0], old_tube, gait.hash())
    if old is not None and old.model_error is not None:  # the socket force only is refitted
        tube = replace(tube, model_error=old.model_error)
    save_tube(out, tube)
    report: dict[str, Any] = {"steps": len(steps), "tau_lo": tau_lo, "tau_hi": tau_hi,
                              "out": str(out)}
    if old is not None:
        report.update(old_coverage(old, steps))
    return report


def contact_ps_profiles(path: str | Path, model: Any, progress: tuple[float, float]
                        ) -> list[tuple[np.ndarray, np.ndarray]]:
    """A multi-contact recording's ground-truth socket force over every complete flat
    prosthesis single support (``ps`` entered from ``ds_p``, left into ``ps_toe``): (the
    prosthesis controllers' stance phase (n,), from the recorded posture and the gait's
    ``progress`` bounds; F_s (n, 3))."""
    from characterization.tube.contact_playback import stance_phase
    from hp_model.leg_kinematics import LegKinematics

    leg = LegKinematics.of(model)
    out: list[tuple[np.ndarray, np.ndarray]] = []
    cur: list[tuple[list[float], tuple[float, float, float]]] | None = None
    prev = None
    for _, _, o in read_messages(path, ["/ground_truth"]):
        d = o["domain"]
        if d == Domain.PS:
            if prev != Domain.PS:  # complete when entered from ds_p (not a run's start)
                cur = [] if prev == Domain.DS_P else None
            if cur is not None:
                f = o["socket_force"]
                cur.append((list(o["q"]), (f["Fx"], f["Fz"], f["My"])))
        elif prev == Domain.PS and cur and d == Domain.PS_TOE:
            q = np.array([c[0] for c in cur], float)
            out.append((stance_phase(leg, model, q, progress),
                        np.array([c[1] for c in cur], float)))
        prev = d
    return out


def refit_contact_tube(paths: Iterable[str | Path], gait_path: str | Path, out: str | Path,
                       *, old_tube: str | Path | None = None, degree: int = 3
                       ) -> dict[str, Any]:
    """:func:`refit_tube` for recordings of a multi-contact gait: the tube of their
    ground-truth socket force over the flat prosthesis single supports, around the gait's
    F* in the controllers' stance phase (:mod:`characterization.tube.contact_playback`)."""
    from characterization.gait.multicontact_artifact import load_contact_cycle
    from characterization.tube.contact_playback import gait_nominal, tube_around
    from hp_model.force_tube import load_tube, save_tube

    cycle = load_contact_cycle(gait_path)
    paths = [Path(p) for p in paths]
    check_recorded_gait(paths, cycle.hash, gait_path, lambda f: load_contact_cycle(f).hash)
    nominal = gait_nominal(cycle)
    steps: list[tuple[np.ndarray, np.ndarray]] = []
    for p in paths:
        steps.extend(contact_ps_profiles(p, cycle.model, nominal.progress))
    if len(steps) < degree + 2:
        raise RecordingError(f"{len(steps)} complete flat single supports in {len(paths)} "
                             f"recordings; need at least {degree + 2}")
    tube, _ = tube_around(nominal, steps, degree, cycle.hash, str(gait_path),
                          {"recordings": [str(p) for p in paths]})
    save_tube(out, tube)
    report: dict[str, Any] = {"steps": len(steps), "tau_lo": tube.tau_lo,
                              "tau_hi": tube.tau_hi, "out": str(out)}
    if old_tube is not None:
        report.update(old_coverage(load_tube(old_tube, cycle.hash), steps))
    return report


def old_coverage(old: Any, steps: list[tuple[np.ndarray, np.ndarray]]) -> dict[str, float]:
    """The share of the samples and of the steps ((tau, F_s) each) inside the tube ``old``."""
    inside_s, n_s, inside_steps = 0, 0, 0
    for tau, fs in steps:
        ok = old.contains(tau, fs - old.nominal_force(tau))
        inside_s += int(ok.sum())
        n_s += ok.size
        inside_steps += bool(ok.all())
    return {"old_coverage_samples": inside_s / max(1, n_s),
            "old_coverage_steps": inside_steps / len(steps)}


def check_recorded_gait(paths: Iterable[str | Path], gait_hash: str, gait_path: str | Path,
                        hash_of: Callable[[Path], str]) -> None:
    """Every recording was made with the gait of hash ``gait_hash`` (``hash_of`` reads the
    hash of its attached gait file, an ArtifactError when it does not fit): a tube refitted
    against another gait's phase and nominal force would be mislabelled."""
    from hp_model.artifacts import ArtifactError

    for p in paths:
        rec = read_recording(p, messages=False)
        if "gait.json" not in rec.attachments:
            raise RecordingError(f"{p}: attachment gait.json missing")
        with tempfile.TemporaryDirectory() as td:
            f = Path(td) / "gait.json"
            f.write_bytes(rec.attachments["gait.json"])
            try:
                h = hash_of(f)
            except ArtifactError as e:
                raise RecordingError(f"{p}: its gait does not fit this model "
                                     f"({str(e).replace(str(f), 'gait.json')})") from None
        if h != gait_hash:
            raise RecordingError(f"{p}: recorded with gait {h}, not with {gait_path} "
                                 f"({gait_hash})")


def _old_tube(first: str | Path, old_tube: str | Path | None, gait_hash: str) -> Any:
    """The tube to compare with: ``old_tube``, else the one attached to the recording
    ``first`` (None when it has none)."""
    from hp_model.force_tube import load_tube

    if old_tube is not None:
        return load_tube(old_tube, gait_hash)
    rec = read_recording(first, messages=False)
    if "tube.json" not in rec.attachments:
        return None
    with tempfile.TemporaryDirectory() as td:
        (Path(td) / "tube.json").write_bytes(rec.attachments["tube.json"])
        return load_tube(Path(td) / "tube.json", gait_hash)


# ----------------------------------------------------------- model-error refit

#: a gap between two recorded estimates longer than this starts a new stance (s)
STANCE_GAP = 0.005


def disturbance_samples(path: str | Path) -> list[Any]:
    """The controller's recorded model-error estimates (``/controller/disturbance``, valid
    ones only) of a recording, one :class:`characterization.tube.model_error.ErrorSamples`
    per stance (a new stance where the time since touchdown drops or the ticks are more
    than :data:`STANCE_GAP` apart)."""
    from characterization.tube.model_error import ErrorSamples

    rows = [o for _, _, o in read_messages(path, ["/controller/disturbance"])
            if o.get("valid")]
    rows.sort(key=lambda o: o["t"])
    out: list[Any] = []
    cur: list[tuple[float, float, float, float]] = []
    prev: dict[str, Any] | None = None
    for o in rows:
        if prev is not None and (o["t"] - prev["t"] > STANCE_GAP
                                 or o["since_touchdown"] < prev["since_touchdown"]):
            out.append(cur)
            cur = []
        cur.append((o["tau"], o["since_touchdown"], o["d"][0], o["d"][1]))
        prev = o
    if cur:
        out.append(cur)
    res = []
    for c in out:
        a = np.array(c, float)
        res.append(ErrorSamples(a[:, 0], a[:, 1], a[:, 2:4]))
    return res


def refit_model_error(paths: Iterable[str | Path], gait_path: str | Path, out: str | Path, *,
                      old_tube: str | Path | None = None, degree: int = 3,
                      exclude_after_touchdown: float | None = None, model: Any = None
                      ) -> dict[str, Any]:
    """Refit the tube's model-error bound (schema 2, ``model_error``) from the controller's
    recorded online estimates (``CtrlDisturbance``) of ``paths``; the socket-force tube is
    kept from ``old_tube`` (default: the tube attached to the first recording).  Reports the
    coverage of the old bound (fraction of the recorded estimates where it is defined that
    lie inside it; None without one).  ``exclude_after_touchdown`` defaults to the old
    bound's, else 30 ms.  Writes ``out`` atomically."""
    import hp_model
    from characterization.tube.fit import TubeFitError
    from characterization.tube.model_error import fit_model_error
    from hp_model.force_tube import EXCLUDE_AFTER_TOUCHDOWN, save_tube
    from hp_model.gait_artifact import load_gait

    model = model or hp_model.load_model()
    gait = load_gait(gait_path, model.parameter_hash())
    paths = [Path(p) for p in paths]
    check_recorded_gait(paths, gait.hash(), gait_path,
                        lambda f: load_gait(f, model.parameter_hash()).hash())
    old = _old_tube(paths[0], old_tube, gait.hash())
    if old is None:
        raise RecordingError(f"{paths[0]}: no tube attached; pass the tube to refit with "
                             "--old")
    samples = []
    for p in paths:
        samples.extend(disturbance_samples(p))
    if not samples:
        raise RecordingError(f"no model-error estimates in {len(paths)} recording(s) (a "
                             "controller without an estimator, e.g. not clfqp?)")
    ex = (exclude_after_touchdown if exclude_after_touchdown is not None
          else old.model_error.exclude_after_touchdown if old.model_error is not None
          else EXCLUDE_AFTER_TOUCHDOWN)
    report: dict[str, Any] = {"stances": len(samples), "out": str(out)}
    if old.model_error is not None:
        me = old.model_error
        inside = n = 0
        for e in samples:
            m = me.in_range(e.tau, e.since_touchdown)
            inside += int(me.contains(e.tau[m], e.d[m]).sum())
            n += int(m.sum())
        report["old_coverage_samples"] = inside / n if n else None
    else:
        report["old_coverage_samples"] = None
    try:
        bound = fit_model_error(samples, degree, ex, source={
            "recordings": [str(p) for p in paths],
            "method_d": "the controller's online estimate (CtrlDisturbance): filtered finite "
                        "difference of the measured joint velocities vs a + A u_prev"})
    except TubeFitError as e:
        raise RecordingError(f"model-error refit: {e}") from None
    save_tube(out, replace(old, model_error=bound))
    report.update({"tau_lo": bound.tau_lo, "tau_hi": bound.tau_hi,
                   "n_samples": bound.source["n_samples"],
                   "samples_inside": bound.credibility["samples_inside_fraction"]})
    return report
