"""Shared pieces of the playback tests: the gait, the model-generated subject, comparisons."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from characterization.steps_artifact import StepsArtifact

DATA = Path(__file__).parent / "data" / "playback"
GAIT = DATA / "gait_synthetic.json"


def subset_steps(a: StepsArtifact, keep: list[int]) -> StepsArtifact:
    """The artifact with only the steps ``keep`` (tau and its offsets rebuilt)."""
    taus = [a.step_tau(i) for i in keep]
    offs = np.concatenate([[0], np.cumsum([len(t) for t in taus])]).astype(np.int64)
    sel = np.asarray(keep, dtype=np.int64)
    return replace(
        a, step_domain=a.step_domain[sel], step_start=a.step_start[sel],
        step_end=a.step_end[sel], step_delta_lower=a.step_delta_lower[sel],
        step_delta_upper=a.step_delta_upper[sel], step_ss_start=a.step_ss_start[sel],
        step_ss_end=a.step_ss_end[sel],
        tau=np.concatenate(taus) if taus else np.zeros(0), tau_offsets=offs)


def estimate_at(sp, tau: np.ndarray) -> np.ndarray:
    """The played-back F_s of a step at the given phases (linear interpolation in tau)."""
    return np.column_stack([np.interp(tau, sp.tau, sp.socket[:, c]) for c in range(3)])


def relative_rms_errors(result, take) -> np.ndarray:
    """(N, 3): per used step and component, RMS of (estimate - truth) over the truth's
    frames in [tau_lo, tau_hi], divided by the peak |F_s| of the true profile."""
    truth = {t.index: t for t in take.ps_truth()}
    tube = result.tube
    out = []
    for sp in result.playback.good:
        tr = truth[sp.step]
        inside = (tr.tau >= tube.tau_lo) & (tr.tau <= tube.tau_hi)
        err = estimate_at(sp, tr.tau[inside]) - tr.socket[inside]
        out.append(np.sqrt(np.mean(err**2, axis=0)) / np.abs(tr.socket).max(axis=0))
    return np.array(out)


def tube_excess(result, take) -> np.ndarray:
    """(N, 3): per used step and component, the largest excursion of the TRUE deviation
    F_s - F* outside the tube over [tau_lo, tau_hi] (<= 0: inside), divided by the peak
    |F_s| of the true profile."""
    truth = {t.index: t for t in take.ps_truth()}
    tube = result.tube
    out = []
    for sp in result.playback.good:
        tr = truth[sp.step]
        inside = (tr.tau >= tube.tau_lo) & (tr.tau <= tube.tau_hi)
        tau = tr.tau[inside]
        dF = tr.socket[inside] - tube.nominal_force(tau)
        lo, hi = tube.delta_bounds(tau)
        out.append(np.maximum(dF - hi, lo - dF).max(axis=0) / np.abs(tr.socket).max(axis=0))
    return np.array(out)
