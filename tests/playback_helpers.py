"""Shared pieces of the playback tests: the gait, the model-generated subject, comparisons."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from characterization.mocap.steps_artifact import StepsArtifact

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


def _truth_windows(result, take):
    """Per used step: (played-back step, its truth, mask of the truth's frames in
    [tau_lo, tau_hi], the truth's tau in the tube's phase).  The truth's tau and the
    playback's are the step's own; the tube's may be the gait's (``result.tube_tau``)."""
    truth = {t.index: t for t in take.ps_truth()}
    tube = result.tube
    for sp in result.playback.good:
        tr = truth[sp.step]
        tau = result.tube_tau(sp, tr.tau)
        yield sp, tr, (tau >= tube.tau_lo) & (tau <= tube.tau_hi), tau


def relative_rms_errors(result, take) -> np.ndarray:
    """(N, 3): per used step and component, RMS of (estimate - truth) over the truth's
    frames in [tau_lo, tau_hi], divided by the peak |F_s| of the true profile."""
    out = []
    for sp, tr, inside, _ in _truth_windows(result, take):
        err = estimate_at(sp, tr.tau[inside]) - tr.socket[inside]
        out.append(np.sqrt(np.mean(err**2, axis=0)) / np.abs(tr.socket).max(axis=0))
    return np.array(out)


def tube_excess(result, take, widened: bool = True) -> np.ndarray:
    """(N, 3): per used step and component, the largest excursion of the TRUE deviation
    F_s - F* outside the tube over [tau_lo, tau_hi] (<= 0: inside), divided by the peak
    |F_s| of the true profile; ``widened=False``: outside the certified bounds without the
    estimation allowance."""
    tube = result.tube
    out = []
    for _, tr, inside, tau_tube in _truth_windows(result, take):
        tau = tau_tube[inside]
        dF = tr.socket[inside] - tube.nominal_force(tau)
        lo, hi = tube.delta_bounds(tau, widened=widened)
        out.append(np.maximum(dF - hi, lo - dF).max(axis=0) / np.abs(tr.socket).max(axis=0))
    return np.array(out)


class PinocchioSocket:
    """The paper's eq. (Fsocket) computed with Pinocchio (an independent rigid-body library
    loading the model's URDF): D by CRBA, H by RNEA, the stance-foot Jacobian of an added
    sole frame; F_s = (J_s D^-1 J_s^T)^-1 J_s D^-1 (H - B u - J_f^T lam_foot) with J_s the
    selection of the fixed joint's coordinates (so Jdot_s qd = 0).  Same inputs, same
    conventions as ``socket_ps`` (coordinates mapped by name, pitch about +y)."""

    def __init__(self, model, domain: str = "ps") -> None:
        import pinocchio as pin

        from hp_model.urdf import to_urdf

        self.pin = pin
        tree = model.tree
        pm = pin.buildModelFromXML(to_urdf(tree))
        pm.gravity.linear = np.array([0.0, 0.0, -tree.gravity])
        for c, j in tree.armature.items():  # the drives' reflected rotor inertias
            pm.armature[pm.idx_vs[pm.getJointId(c)]] = j
        sole = model.stance_frame(domain)
        fr = next(f for f in tree.frames if f.name == sole)
        body = tree.body(fr.body)
        jid = pm.getJointId(body.coords[-1])
        self.fid = pm.addFrame(pin.Frame(sole, jid, pin.SE3(np.eye(3), np.array(
            [fr.point[0], 0.0, fr.point[1]])), pin.FrameType.OP_FRAME))
        self.pm, self.pd = pm, pm.createData()
        self.idx = np.array([pm.idx_vs[pm.getJointId(n)] for n in tree.coord_names])
        self.B = np.zeros((pm.nv, model.nu))
        self.B[self.idx] = model.B
        self.sel = self.idx[[tree.coord_names.index(c) for c in ("x_f", "z_f", "th_f")]]
        self.rows = [0, 2, 4]  # linear x, linear z, angular y (pitch)
        self.qp, self.vp = np.zeros(pm.nq), np.zeros(pm.nv)
        self.zero = np.zeros(pm.nv)

    def __call__(self, q, qd, u, lam_foot) -> np.ndarray:
        pin, pm, pd = self.pin, self.pm, self.pd
        self.qp[self.idx], self.vp[self.idx] = q, qd
        M = pin.crba(pm, pd, self.qp)
        M = np.triu(M) + np.triu(M, 1).T
        h = pin.rnea(pm, pd, self.qp, self.vp, self.zero)
        Jf = pin.computeFrameJacobian(pm, pd, self.qp, self.fid,
                                      pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[self.rows]
        X = np.linalg.solve(M, np.column_stack([np.eye(pm.nv)[:, self.sel],
                                                h - self.B @ u - Jf.T @ lam_foot]))
        return np.linalg.solve(X[self.sel, :3], X[self.sel, 3])
