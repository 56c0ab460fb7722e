"""A synthetic subject on the prosthesis with known ground truth (``hpcosim mocap synth``).

The motion q(t) comes from one of two sources (``SynthOptions.source``):

- ``"model"`` (default): the model itself walks (:mod:`characterization.mocap.model_walk`): the
  hybrid simulator tracks a reference gait of the model (``gait_file``, default the packaged
  ``characterization/data/reference_gait.json``, see the NOTICE beside it), every step with
  its own perturbed Bezier coefficients (``sigma``) and hip velocity (``sigma_v_hip``).
  The motion is dynamically consistent with the model (impacts, no double support: a foot
  lifts when the other lands), so a gait fit of the take can be checked against the
  reference gait.  The truth's contact events are the simulated impacts.
- ``"template"``: the kinematic template of :mod:`characterization.mocap.synthetic_gait`
  (task-space footfalls with double support and inverse kinematics): human-like timing,
  but not a motion of the model's dynamics.

The model's forward kinematics (``model.numeric()["frames"]``) turns q into limb poses.
Every limb carries four markers offset from its joints (Marker1 -> Marker2 lies along the
limb's long axis, for feet heel -> toe); a rigid body per limb is created in the zero pose
with lab-aligned axes (Motive's default) and its pose is solved each frame from the visible
noisy markers (least-squares fit, >= 3 markers, as Motive does).  Measurement noise is
Gaussian per coordinate; dropouts are random marker occlusions and rigid-body losses.  The
take is written as a Motive CSV (Y up) and a C3D (Z up, markers only), with the ground truth
in ``truth.npz``.  Everything is a deterministic function of the options (seed included).
"""

from __future__ import annotations

import io
import itertools
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from characterization.mocap.c3d_io import write_c3d
from characterization.mocap.mapping import (
    JOINTS,
    LIMBS,
    MocapMapping,
    default_mapping,
    synthetic_names,
)
from characterization.mocap.model_walk import WalkError, WalkOptions, resample, walk
from characterization.mocap.motive_csv import write_motive_csv
from characterization.mocap.synthetic_gait import (
    GaitEvents,
    GaitParams,
    LegGeometry,
    gait_events,
    gait_q,
)
from characterization.mocap.take import MocapError, RigidBodyTrack, Take
from hp_model import HumanProsthesisModel
from hp_model.artifacts import ArtifactError
from hp_model.atomic_io import atomic_write_bytes, atomic_write_text
from hp_model.choices import Choice
from hp_model.domains import Domain
from hp_model.gait_artifact import Gait, load_gait
from hp_model.json_io import dumps
from hp_model.outputs import HipProgress

#: the packaged reference gait of the default subject and device (NOTICE.md beside it)
REFERENCE_GAIT = Path(__file__).resolve().parents[1] / "data" / "reference_gait.json"


class SynthSource(Choice):
    """Where the synthetic subject's motion comes from (module docstring)."""

    MODEL = "model"  # the model walks a reference gait
    TEMPLATE = "template"  # the kinematic template of characterization.mocap.synthetic_gait
    PERSON = "person"  # the model walks a multi-contact gait (characterization.gait.person_synth)


#: limb -> (frame giving its origin, coordinates summed for its pitch)
LIMB_POSE = {"hat": ("hip", ("th_B",)), "l_thigh": ("hip", ("th_B", "th_lh")),
             "l_shank": ("l_knee", ()), "l_foot": ("l_ankle", ()),
             "r_thigh": ("hip", ("th_B", "th_rh")), "p_shin": ("p_knee", ()),
             "p_foot": ("p_ankle", ())}
JOINT_FRAMES = {"hip_l": "hip", "knee_l": "l_knee", "ankle_l": "l_ankle", "hip_r": "hip",
                "knee_p": "p_knee", "ankle_p": "p_ankle"}
#: marker offsets (x forward, y left, z up) in each limb's frame, m; Marker1 -> Marker2 is
#: the pitch pair (along the long axis; feet: heel -> toe at equal height)
MARKERS: dict[str, tuple[tuple[float, float, float], ...]] = {
    "hat": ((-0.10, 0.0, 0.05), (-0.10, 0.0, 0.35), (0.10, 0.12, 0.08), (0.10, -0.12, 0.08)),
    "l_thigh": ((0.05, 0.14, -0.33), (0.05, 0.14, -0.10), (-0.06, 0.13, -0.20),
                (0.07, 0.10, -0.22)),
    "l_shank": ((0.04, 0.13, -0.33), (0.04, 0.13, -0.08), (-0.05, 0.12, -0.15),
                (0.05, 0.09, -0.20)),
    "l_foot": ((-0.07, 0.10, -0.04), (0.19, 0.10, -0.04), (0.05, 0.12, -0.01),
               (0.12, 0.07, -0.025)),
    "r_thigh": ((0.05, -0.14, -0.48), (0.05, -0.14, -0.10), (-0.06, -0.13, -0.25),
                (0.06, -0.10, -0.30)),
    "p_shin": ((0.04, -0.12, -0.20), (0.04, -0.12, -0.04), (-0.04, -0.11, -0.12),
               (0.05, -0.09, -0.10)),
    "p_foot": ((-0.07, -0.10, -0.04), (0.17, -0.10, -0.04), (0.04, -0.12, -0.01),
               (0.10, -0.07, -0.025)),
}
LATERAL = {"hat": 0.0, "l_thigh": 0.09, "l_shank": 0.09, "l_foot": 0.09, "r_thigh": -0.09,
           "p_shin": -0.09, "p_foot": -0.09}
#: lab frames of the two files: Motive Y up, C3D Z up; the subject walks along lab -X
CSV_LAB = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])  # cols x, y, z
C3D_FROM_CSV = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
LAB_ORIGIN = np.array([18.0, 0.0, 0.4])  # model origin in the CSV lab frame, m


@dataclass(frozen=True)
class SynthOptions:
    """Synthetic take options (SI units)."""

    n_strides: int = 37
    seed: int = 0
    rate: float = 120.0  # Hz
    noise_mm: float = 0.5  # SD per coordinate
    dropout_rate: float = 0.5  # marker occlusions per marker per second
    dropout_max_frames: int = 10
    rb_dropout_rate: float = 0.3  # rigid-body losses (markers still seen) per body per second
    rb_dropout_max_frames: int = 24
    lead: float = 0.35  # s of partial steps before the first and after the last cycle
    source: SynthSource = SynthSource.MODEL  # or its value
    gait_file: str | None = None  # model source: reference gait (None: the packaged one)
    sigma: float = 0.03  # model source: rad, SD of the interior Bezier coefficients per step
    sigma_v_hip: float = 0.03  # model source: relative SD of the hip velocity per step
    gait: GaitParams = field(default_factory=GaitParams)  # template source


@dataclass(frozen=True)
class SyntheticTake:
    """The take in the Motive lab frame (Y up) and the C3D lab frame (Z up), and the truth
    (a dict of arrays, see :func:`synthesize`)."""

    take: Take
    take_c3d: Take
    truth: dict[str, np.ndarray]


def _kabsch(template: np.ndarray, obs: np.ndarray, w: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted rigid fit per frame: obs ~ R (template - ct) + pos.  template (m, 3), obs
    (n, m, 3) with NaN where not visible, w (n, m) bool.  Returns R (n, 3, 3), the position
    of the template origin (n, 3), mean residual (n,)."""
    wf = w.astype(float)[..., None]
    y = np.where(w[..., None], obs, 0.0)
    sw = np.maximum(wf.sum(1), 1.0)
    cy = (wf * y).sum(1) / sw
    ct = (wf * template[None]).sum(1) / sw
    a = (template[None] - ct[:, None]) * wf
    b = (y - cy[:, None]) * wf
    H = np.einsum("nmi,nmj->nij", a, b)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))
    D = np.zeros_like(H)
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = np.einsum("nji,njk,nlk->nil", Vt, D, U)
    pos = cy - np.einsum("nij,nj->ni", R, ct)
    fit = np.einsum("nij,mj->nmi", R, template) + pos[:, None]
    err = np.linalg.norm(np.where(w[..., None], fit - obs, 0.0), axis=2)
    return R, pos, (err * w).sum(1) / sw[:, 0]


def _gaps(rng: np.random.Generator, n: int, rate_per_frame: float, max_len: int
          ) -> np.ndarray:
    """(n,) bool mask of random gaps (Poisson starts, uniform lengths 1..max_len)."""
    mask = np.zeros(n, bool)
    k = rng.poisson(rate_per_frame * n)
    for s, ln in zip(rng.integers(0, n, k), rng.integers(1, max_len + 1, k), strict=True):
        mask[s:s + ln] = True
    return mask


def _truth_steps(delta: np.ndarray, t: np.ndarray, ev_p_land: np.ndarray,
                 ev_p_lift: np.ndarray, T: float) -> list[tuple[str, int, int]]:
    """Steps from the exact extrema of the noise-free delta_p_hip around contact events
    (windows clipped to the take; an extremum on the take's first or last frame is its
    edge, not a turn)."""
    def extremum(tl: float, before: float, after: float, pick) -> int | None:
        w = np.flatnonzero((t >= tl - before * T) & (t <= tl + after * T))
        if w.size == 0:
            return None
        i = int(w[pick(delta[w])])
        return i if 0 < i < len(t) - 1 else None

    mins = [extremum(tl, 0.25, 0.15, np.argmin) for tl in ev_p_land]
    maxs = [extremum(tl, 0.10, 0.25, np.argmax) for tl in ev_p_lift]
    pts = sorted([(i, "min") for i in mins if i is not None]
                 + [(i, "max") for i in maxs if i is not None])
    return [(Domain.PS if ka == "min" else Domain.PNS, a, b)
            for (a, ka), (b, _) in itertools.pairwise(pts)]


def _template_motion(model: HumanProsthesisModel, opts: SynthOptions,
                     rng: np.random.Generator
                     ) -> tuple[np.ndarray, np.ndarray, GaitEvents, float]:
    """Times (s), q (n, 12), contact events and the nominal stride time of the kinematic
    template (:mod:`characterization.mocap.synthetic_gait`)."""
    z0 = model.numeric()["frames"](np.zeros(model.nq), np.zeros(model.nq))[0].copy()
    zf = {n: z0[:, i] for i, n in enumerate(model.frame_names)}
    left, right = (LegGeometry(-zf[f"{s}_knee"][1], zf[f"{s}_knee"][1] - zf[f"{s}_ankle"][1],
                               zf[f"{s}_ankle"][1] - zf[f"{s}_sole"][1],
                               zf[f"{s}_ankle"][0] - zf[f"{s}_heel"][0],
                               zf[f"{s}_toe"][0] - zf[f"{s}_ankle"][0]) for s in ("l", "p"))
    g = opts.gait
    ev = gait_events(opts.n_strides + 2, g, rng)
    t0, t1 = ev.p_land[1] - opts.lead, ev.p_land[-1] + opts.lead
    t = t0 + np.arange(int(np.floor((t1 - t0) * opts.rate)) + 1) / opts.rate
    return t, gait_q(t, ev, g, left, right, rng), ev, g.stride_time


def reference_gait(model: HumanProsthesisModel, gait_file: str | None = None) -> Gait:
    """The reference gait the model source walks: ``gait_file`` or the packaged one; one
    line (MocapError) if it was made for other model parameters."""
    path = gait_file or REFERENCE_GAIT
    try:
        return load_gait(path, model.parameter_hash())
    except ArtifactError as e:
        if gait_file is None and "model_hash" in str(e):
            raise MocapError("synthetic subject: the packaged reference gait was made for the "
                             "default subject and device; give a gait of this model "
                             "(--gait, from `hpcosim gait fit`) or use --source template"
                             ) from None
        raise


def _model_motion(model: HumanProsthesisModel, opts: SynthOptions,
                  rng: np.random.Generator
                  ) -> tuple[np.ndarray, np.ndarray, GaitEvents, float]:
    """Times (s), q (n, 12), contact events (the impacts) and the mean stride time of the
    model walking its reference gait (:mod:`characterization.mocap.model_walk`)."""
    gait = reference_gait(model, opts.gait_file)
    wopt = WalkOptions(sigma=opts.sigma, sigma_v_hip=opts.sigma_v_hip)
    try:  # strides 0 .. n_strides + 1 (the take covers 1 .. n_strides + 1)
        steps = walk(model, gait, 2 * (opts.n_strides + 2), rng, wopt)
    except WalkError as e:
        raise MocapError(f"synthetic subject: {e}; lower --variability") from None
    p_land = np.array([s.t[0] for s in steps if s.domain == Domain.PS])
    h_land = np.array([s.t[0] for s in steps if s.domain == Domain.PNS])
    # start in the pns before stride 1 and end in the last ps: at most halfway into them,
    # so that the take's ends are not turning points of delta_p_hip
    t0 = p_land[1] - min(opts.lead, 0.5 * (p_land[1] - h_land[0]))
    t1 = p_land[-1] + min(opts.lead, 0.5 * (h_land[-1] - p_land[-1]))
    t = t0 + np.arange(int(np.floor((t1 - t0) * opts.rate)) + 1) / opts.rate
    q, _, _ = resample(steps, t)
    none = np.full(p_land.size, np.nan)
    ev = GaitEvents(p_land=p_land, h_lift=p_land, h_land=h_land, p_lift=h_land,
                    p_print=none, h_print=none)
    return t, q, ev, float(np.mean(np.diff(p_land)))


def marker_offsets(model: HumanProsthesisModel) -> dict[str, tuple[tuple[float, ...], ...]]:
    """:data:`MARKERS` on ``model``: each foot's toe marker (Marker2) no further forward than
    the model's toe, the point its rigid foot rolls off (a lab's marker on the metatarsal
    heads).  Ahead of it the marker would sink into the floor as the foot rolls; behind it
    it rises and the contact rule sees the foot leave the ground at the heel off.  The
    example subject's toes are ahead of both markers: its takes are unchanged."""
    z0 = model.numeric()["frames"](np.zeros(model.nq), np.zeros(model.nq))[0]
    x = {n: float(z0[0, i]) for i, n in enumerate(model.frame_names)}
    out: dict[str, tuple[tuple[float, ...], ...]] = dict(MARKERS)
    for limb, side in (("l_foot", "l"), ("p_foot", "p")):
        heel, (bx, by, bz), *rest = MARKERS[limb]
        out[limb] = (heel, (min(bx, x[f"{side}_toe"] - x[f"{side}_ankle"]), by, bz), *rest)
    return out


def _markers(model: HumanProsthesisModel, t: np.ndarray, q: np.ndarray, opts: SynthOptions,
             rng: np.random.Generator) -> tuple[Take, Take, dict[str, np.ndarray],
                                                np.ndarray, dict[str, np.ndarray]]:
    """The markers and rigid bodies of the motion q (n, 12) at times t, with noise and
    dropouts: (Motive take, C3D take, limb poses (x, z, pitch), joint positions, exact
    markers in the model frame)."""
    fs = model.numeric()
    fr = fs["frames"]
    names = model.frame_names
    n = t.size
    poses = np.empty((n, 3, len(names)))
    zero = np.zeros(model.nq)
    for i in range(n):
        poses[i] = fr(q[i], zero)[0]
    ci = {c: k for k, c in enumerate(model.coord_names)}
    fi = {f: k for k, f in enumerate(names)}
    # limb poses (x, z, pitch) from the frames; thighs share the hip's origin
    limb_pose = {}
    for limb, (frame, coords) in LIMB_POSE.items():
        p = poses[:, :, fi[frame]].copy()
        if coords:
            p[:, 2] = q[:, [ci[c] for c in coords]].sum(1)
        limb_pose[limb] = p
    joint_pos = np.stack([poses[:, :2, fi[JOINT_FRAMES[j]]] for j in JOINTS], axis=1)

    # markers in the model frame (x, y, z), exact
    exact: dict[str, np.ndarray] = {}
    rbn = synthetic_names()
    offsets = marker_offsets(model)
    for limb, offs in offsets.items():
        p = limb_pose[limb]
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        for k, (bx, by, bz) in enumerate(offs):
            exact[f"{rbn[limb]}:Marker{k + 1}"] = np.column_stack(
                [p[:, 0] + c * bx + s * bz, np.full(n, LATERAL[limb] + by),
                 p[:, 1] - s * bx + c * bz])
    noisy = {k: v + opts.noise_mm * 1e-3 * rng.standard_normal(v.shape)
             for k, v in exact.items()}
    visible = {k: ~_gaps(rng, n, opts.dropout_rate / opts.rate, opts.dropout_max_frames)
               for k in noisy}
    for name, v in noisy.items():
        v[~visible[name]] = np.nan

    # rigid bodies: fit in the model frame, then express in the lab frame
    def to_lab(p: np.ndarray) -> np.ndarray:
        return p @ CSV_LAB.T + LAB_ORIGIN

    bodies: dict[str, RigidBodyTrack] = {}
    rb_markers: dict[str, np.ndarray] = {}
    for limb, offs in offsets.items():
        mk = [f"{rbn[limb]}:Marker{k + 1}" for k in range(len(offs))]
        template = np.array([[bx, LATERAL[limb] + by, bz] for bx, by, bz in offs])
        template = template - template.mean(0)
        obs = np.stack([noisy[m] for m in mk], axis=1)
        w = np.stack([visible[m] for m in mk], axis=1)
        R, pos, err = _kabsch(template, obs, w)
        lost = (w.sum(1) < 3) | _gaps(rng, n, opts.rb_dropout_rate / opts.rate,
                                      opts.rb_dropout_max_frames)
        R_lab = np.einsum("ij,njk,lk->nil", CSV_LAB, R, CSV_LAB)
        quat = Rotation.from_matrix(R_lab).as_quat()
        quat[lost] = np.nan
        pos_lab = to_lab(pos)
        pos_lab[lost] = np.nan
        err[lost] = np.nan
        bodies[rbn[limb]] = RigidBodyTrack(pos_lab, quat, err)
        solved = np.einsum("nij,mj->nmi", R, template) + pos[:, None]
        for j, m in enumerate(mk):
            s_lab = to_lab(solved[:, j])
            s_lab[lost] = np.nan
            rb_markers[m] = s_lab
    markers = {k: to_lab(v) for k, v in noisy.items()}
    take = Take(source="synthetic", frame_rate=opts.rate, time=t - t[0], markers=markers,
                rigid_bodies=bodies, rigid_body_markers=rb_markers, up_axis="+y")
    take_c3d = Take(source="synthetic.c3d", frame_rate=opts.rate, time=t - t[0],
                    markers={k: v @ C3D_FROM_CSV.T for k, v in markers.items()}, up_axis="+z")

    return take, take_c3d, limb_pose, joint_pos, exact


def static_trial(model: HumanProsthesisModel, opts: SynthOptions = SynthOptions(),
                 seconds: float = 2.0) -> SyntheticTake:
    """The synthetic subject standing still in the neutral posture (every joint angle and
    the trunk pitch zero, both soles on the ground) for ``seconds``: a static calibration
    trial with the same markers, noise and dropouts as :func:`synthesize`.  Truth: time, q
    and limb_pitch (zero)."""
    rng = np.random.default_rng(opts.seed)
    z0 = model.numeric()["frames"](np.zeros(model.nq), np.zeros(model.nq))[0]
    sole = z0[1, model.frame_names.index("l_sole")]
    t = np.arange(round(seconds * opts.rate) + 1) / opts.rate
    q = np.zeros((t.size, model.nq))
    q[:, model.coord_names.index("z_B")] = -sole
    take, take_c3d, limb_pose, _, _ = _markers(model, t, q, opts, rng)
    pitch = np.column_stack([limb_pose[k][:, 2] for k in LIMBS])
    return SyntheticTake(take, take_c3d, {"time": t, "q": q, "limb_pitch": pitch})


def synthesize(model: HumanProsthesisModel, opts: SynthOptions = SynthOptions()
               ) -> SyntheticTake:
    """Generate the synthetic take and its truth.

    Truth keys (positions in the sagittal projection of the lab frame): source, time, q (n, 12),
    limb_pitch (n, 7), joint_position (n, 6, 2), joint_lambda (6, 2, 2), delta_ps (n,),
    step_domain/step_start/step_end (truth steps from the extrema of the noise-free
    delta_p_hip), step_ss_start/step_ss_end (the non-stance foot's swing: single
    support), p_land/p_lift/h_lift/h_land (contact event times, s).
    """
    try:
        source = SynthSource(opts.source)
    except ValueError as e:
        raise MocapError(f"synthetic subject: {e}") from None
    if source == SynthSource.PERSON:
        raise MocapError("synthetic subject: --source person walks a multi-contact gait "
                         "(characterization.gait.person_synth)")
    rng = np.random.default_rng(opts.seed)
    motion = _template_motion if source == SynthSource.TEMPLATE else _model_motion
    t, q, ev, stride_time = motion(model, opts, rng)
    return take_of_motion(model, t, q, ev, stride_time, opts, rng, source.value)


def take_of_motion(model: HumanProsthesisModel, t: np.ndarray, q: np.ndarray, ev: GaitEvents,
                   stride_time: float, opts: SynthOptions, rng: np.random.Generator,
                   source: str) -> SyntheticTake:
    """The take of a motion q (n, 12) of ``model`` at times t (s), its contact events and
    mean stride time (s): the markers with the noise and dropouts of ``opts`` (from
    ``rng``) and the truth of :func:`synthesize`."""
    take, take_c3d, limb_pose, joint_pos, exact = _markers(model, t, q, opts, rng)
    limb_pitch = np.column_stack([limb_pose[k][:, 2] for k in LIMBS])
    ci = {c: k for k, c in enumerate(model.coord_names)}

    # truth
    delta = HipProgress.of(model, Domain.PS)(q[:, ci["th_pk"]], q[:, ci["th_pa"]])
    steps = _truth_steps(delta, t, ev.p_land, ev.p_lift, stride_time)
    ss = []
    for dom, a, b in steps:
        lifts, lands = ((ev.h_lift, ev.h_land) if dom == Domain.PS else (ev.p_lift[:-1],
                                                                    ev.p_land[1:]))
        mid = t[(a + b) // 2]
        k = int(np.argmin(np.abs(0.5 * (lifts + lands) - mid)))
        ss.append((int(np.searchsorted(t, lifts[k])), int(np.searchsorted(t, lands[k])) - 1))
    lam = np.zeros((len(JOINTS), 2, 2))
    mapping = default_mapping()
    for j, (la, lb) in enumerate(JOINTS.values()):
        for side, (limb, mname) in enumerate(zip((la, lb), mapping.joints[list(JOINTS)[j]]
                                                 .markers, strict=True)):
            p = limb_pose[limb][0]
            m = exact[mname][0][[0, 2]]
            c, s = np.cos(p[2]), np.sin(p[2])
            Rm = np.array([[c, s], [-s, c]])
            lam[j, side] = Rm.T @ (joint_pos[0, j] - m)
    # truth in the sagittal projection of the lab frame (what processing reports)
    shift = np.array([LAB_ORIGIN @ CSV_LAB[:, 0], LAB_ORIGIN @ CSV_LAB[:, 2]])
    joint_pos = joint_pos + shift
    q = q.copy()
    q[:, 0:2] += shift
    truth = {
        "source": np.array(source), "time": t - t[0], "q": q, "limb_pitch": limb_pitch,
        "joint_position": joint_pos, "joint_lambda": lam, "delta_ps": delta,
        "step_domain": np.array([s[0] for s in steps]),
        "step_start": np.array([s[1] for s in steps], dtype=np.int64),
        "step_end": np.array([s[2] for s in steps], dtype=np.int64),
        "step_ss_start": np.array([s[0] for s in ss], dtype=np.int64),
        "step_ss_end": np.array([s[1] for s in ss], dtype=np.int64),
        "p_land": ev.p_land - t[0], "p_lift": ev.p_lift - t[0], "h_lift": ev.h_lift - t[0],
        "h_land": ev.h_land - t[0],
    }
    return SyntheticTake(take, take_c3d, truth)


def write_synthetic(out_dir: str | os.PathLike[str], synth: SyntheticTake,
                    opts: SynthOptions, mapping: MocapMapping | None = None) -> dict[str, Path]:
    """Write take.csv (Motive), take.c3d, truth.npz, mapping.toml (``mapping``, default
    :func:`default_mapping`) and options.json."""
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    paths = {"csv": d / "take.csv", "c3d": d / "take.c3d", "truth": d / "truth.npz",
             "mapping": d / "mapping.toml", "options": d / "options.json"}
    write_motive_csv(paths["csv"], synth.take, take_name=f"synthetic-seed{opts.seed}")
    write_c3d(paths["c3d"], synth.take_c3d)
    buf = io.BytesIO()
    np.savez_compressed(buf, allow_pickle=False, **synth.truth)  # numeric arrays only
    atomic_write_bytes(paths["truth"], buf.getvalue())
    atomic_write_text(paths["mapping"], mapping_toml(mapping or default_mapping()))
    atomic_write_text(paths["options"], dumps(asdict(opts), indent=2))
    return paths


def mapping_toml(m: MocapMapping) -> str:
    """A mapping config as TOML text."""
    import tomli_w

    return tomli_w.dumps(m.model_dump(exclude_none=True))
