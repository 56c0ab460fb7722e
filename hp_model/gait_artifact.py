"""The gait artifact: the optimized periodic gait (paper Sec. IV-A) as a versioned JSON file.

Layout (``kind = "hpcosim-gait"``, ``schema_version = 2``; SI units, angles in rad):

    model_hash            hash of the model parameters the gait was made for
    degree                Bezier degree m of y2
    gains                 {eps, kp, kd} of the human-side feedback linearization (eps as in the
                          optimization, which the orbit depends on; kp, kd for tracking)
    domains.<d>           per domain d in (ps, pns):
        alpha (5, m+1), v_hip, p_min, p_max      the optimized gait alpha*, v_hip*, phase bounds
        offsets (5,)                              delta_alpha (marker-placement offsets)
        duration                                  s
        data {alpha, v_hip, p_min, p_max}         the regression of the mocap data (alpha_mc)
        fit {rms (5,), r2 (5,), n}                its goodness of fit
    socket_nominal        {degree, coeffs (3, k+1)}: F*(tau) = (F_x, F_z, M_y) in N, N, N m over
                          the ps phase tau in [0, 1] (Bezier)
    controller_curves     what the prosthesis controllers read, fitted once from the trajectory
                          (:mod:`characterization.gait.controller_curves`), Bezier {degree, coeffs}:
        socket_pitch (1, k+1)     world pitch (rad) of the socket over the pns phase t / T_pns
        stance_torque (2, k+1)    nominal motor torques (knee, ankle; N m) over the ps phase tau
    trajectory.<d>        the collocation trajectory {t, q (12, P), qd, qdd, u (6, P), lam (6, P)}
    options               the optimization settings and weights used (null: a bound that is off,
                          +inf, e.g. ``touchdown_slip``; older files say ``Infinity``)
    solver                IPOPT status, iterations, wall time, cost, time in function evaluation
    verification          closed-loop checks (return-map eigenvalues, output RMS), when run

Loading validates every field and, given a model, refuses a gait made for other parameters.
A schema-1 gait (without ``controller_curves``) is refused with the command that remakes it.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hp_model import bezier
from hp_model.artifacts import ArtifactError, FieldReader, canonical_hash, load_json, save_json
from hp_model.domains import N_Y2, PAPER_DOMAINS, Domain
from hp_model.outputs import GaitParams

KIND = "hpcosim-gait"
SCHEMA_VERSION = 2
#: the kind of a multi-contact gait (characterization.gait.multicontact_artifact), which the
#: consumers of this artifact refuse with the command that makes theirs
MULTICONTACT_KIND = "hpcosim-gait-multicontact"


def artifact_kind(path: str | os.PathLike[str]) -> object:
    """A JSON file's ``kind`` field (None if it has none or is not JSON)."""
    import json

    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return doc.get("kind") if isinstance(doc, dict) else None


@dataclass(frozen=True)
class ControllerCurves:
    """The Bezier curves the prosthesis controllers read (module docstring,
    ``controller_curves``): ``socket_pitch`` (1, k+1) over the pns phase, ``stance_torque``
    (2, k+1) over the ps phase."""

    socket_pitch: np.ndarray
    stance_torque: np.ndarray


@dataclass(frozen=True)
class Gait:
    """A loaded or freshly optimized gait; see the module docstring for the fields."""

    params: Mapping[Domain, GaitParams]
    model_hash: str
    gains: tuple[float, float, float]
    socket_nominal: np.ndarray
    controller_curves: ControllerCurves
    offsets: Mapping[Domain, np.ndarray] = field(default_factory=dict)
    durations: Mapping[Domain, float] = field(default_factory=dict)
    data_params: Mapping[Domain, GaitParams] = field(default_factory=dict)
    fit_quality: Mapping[Domain, Mapping[str, Any]] = field(default_factory=dict)
    trajectory: Mapping[Domain, Mapping[str, np.ndarray]] = field(default_factory=dict)
    options: Mapping[str, Any] = field(default_factory=dict)
    solver: Mapping[str, Any] = field(default_factory=dict)
    verification: Mapping[str, Any] = field(default_factory=dict)

    @property
    def degree(self) -> int:
        return self.params[Domain.PS].degree

    @property
    def gains_array(self) -> np.ndarray:
        return np.asarray(self.gains, dtype=float)

    def theta(self, domain: Domain) -> np.ndarray:
        """Packed parameter vector of a domain (``GaitParams.pack``)."""
        return self.params[domain].pack()

    def hash(self) -> str:
        """Identity of the gait: its parameters, gains, nominal force and model hash (not
        what is fitted from the trajectory: the controller curves)."""
        return canonical_hash({
            "model_hash": self.model_hash, "gains": list(self.gains),
            "socket_nominal": self.socket_nominal,
            "params": {d: self.params[d].pack() for d in PAPER_DOMAINS}})

    def socket_force(self, tau: float | np.ndarray) -> np.ndarray:
        """Nominal socket force F*(tau) in ps: (3,) for a scalar tau, (n, 3) for an array;
        tau is clipped to [0, 1]."""
        return bezier.evaluate(self.socket_nominal, np.clip(tau, 0.0, 1.0))

    def check_model(self, model_hash: str, src: str = "gait") -> None:
        """Refuse a gait made for other model parameters."""
        if model_hash != self.model_hash:
            raise ArtifactError(
                f"{src}: field 'model_hash': the gait was made for model parameters "
                f"{self.model_hash}, not for the loaded subject/device ({model_hash}); "
                "refit the gait for this subject")

    def with_verification(self, verification: Mapping[str, Any]) -> Gait:
        from dataclasses import replace
        return replace(self, verification=dict(verification))


def _curve_doc(coeffs: np.ndarray) -> dict[str, Any]:
    return {"degree": coeffs.shape[1] - 1, "coeffs": coeffs}


def _params_doc(p: GaitParams) -> dict[str, Any]:
    return {"alpha": p.alpha, "v_hip": p.v_hip, "p_min": p.p_min, "p_max": p.p_max}


def to_document(g: Gait) -> dict[str, Any]:
    domains: dict[str, Any] = {}
    for d in PAPER_DOMAINS:
        doc = _params_doc(g.params[d])
        doc["offsets"] = np.asarray(g.offsets.get(d, np.zeros(N_Y2)))
        doc["duration"] = float(g.durations.get(d, 0.0))
        if d in g.data_params:
            doc["data"] = _params_doc(g.data_params[d])
        if d in g.fit_quality:
            doc["fit"] = dict(g.fit_quality[d])
        domains[d] = doc
    return {
        "kind": KIND, "schema_version": SCHEMA_VERSION, "gait_hash": g.hash(),
        "model_hash": g.model_hash, "degree": g.degree,
        "gains": dict(zip(("eps", "kp", "kd"), g.gains, strict=True)),
        "domains": domains,
        "socket_nominal": _curve_doc(g.socket_nominal),
        "controller_curves": {"socket_pitch": _curve_doc(g.controller_curves.socket_pitch),
                              "stance_torque": _curve_doc(g.controller_curves.stance_torque)},
        "trajectory": {d: dict(t) for d, t in g.trajectory.items()},
        "options": dict(g.options), "solver": dict(g.solver),
        "verification": dict(g.verification),
    }


def save_gait(path: str | os.PathLike[str], g: Gait) -> None:
    """Write the gait atomically."""
    save_json(path, to_document(g))


def _read_params(r: FieldReader, base: str, degree: int) -> GaitParams:
    alpha = r.array(f"{base}.alpha", (N_Y2, degree + 1))
    v_hip = r.number(f"{base}.v_hip", 0.05, 5.0)
    p_min, p_max = r.number(f"{base}.p_min", -2, 2), r.number(f"{base}.p_max", -2, 2)
    if not p_max > p_min:
        raise r.fail(f"{base}.p_max", f"must exceed p_min ({p_min})")
    return GaitParams(alpha, v_hip, p_min, p_max)


def _read_curve(r: FieldReader, field: str, rows: int) -> np.ndarray:
    k = int(r.number(f"{field}.degree", 0, 30))
    return r.array(f"{field}.coeffs", (rows, k + 1))


def load_gait(path: str | os.PathLike[str], model_hash: str | None = None) -> Gait:
    """Read and validate a gait file; with ``model_hash``, refuse a gait for another model."""
    src = str(path)
    try:
        doc = load_json(path, KIND, (1, SCHEMA_VERSION))
    except ArtifactError:
        if artifact_kind(path) == MULTICONTACT_KIND:
            raise ArtifactError(
                f"{src}: a multi-contact gait (`gait fit --domains multicontact`): `hpcosim "
                "fmu build` and `hpcosim run --controller clfqp` take it; this verb runs the "
                "paper's two domains for now (a gait of `hpcosim gait fit STEPS --out "
                "G.json`)") from None
        raise
    if doc["schema_version"] == 1:
        raise ArtifactError(
            f"{src}: field 'schema_version': a version-1 gait has no controller curves "
            f"(this program reads {SCHEMA_VERSION}); remake it with `hpcosim gait fit STEPS "
            f"--out {src}`")
    r = FieldReader(src, doc)
    degree = int(r.number("degree", 1, 20))
    eps, kp, kd = (r.number(f"gains.{k}", 0.0, 1e6) for k in ("eps", "kp", "kd"))
    params, data, offsets, durations, fit = {}, {}, {}, {}, {}
    for d in PAPER_DOMAINS:
        base = f"domains.{d}"
        params[d] = _read_params(r, base, degree)
        offsets[d] = r.array(f"{base}.offsets", (N_Y2,))
        durations[d] = r.number(f"{base}.duration", 0.0, 10.0)
        dd = r.get(base)
        if "data" in dd:
            data[d] = _read_params(r, f"{base}.data", degree)
        if "fit" in dd:
            fit[d] = dict(dd["fit"])
    nominal = _read_curve(r, "socket_nominal", 3)
    curves = ControllerCurves(_read_curve(r, "controller_curves.socket_pitch", 1),
                              _read_curve(r, "controller_curves.stance_torque", 2))
    traj: dict[Domain, dict[str, np.ndarray]] = {}
    for d, t in (r.get("trajectory") or {}).items():
        if d not in list(PAPER_DOMAINS):
            raise r.fail(f"trajectory.{d}", f"is not a domain ({Domain.choices()})")
        traj[Domain(d)] = {name: r.array(f"trajectory.{d}.{name}") for name in t}
    g = Gait(params=params, model_hash=r.string("model_hash"), gains=(eps, kp, kd),
             socket_nominal=nominal, controller_curves=curves, offsets=offsets,
             durations=durations, data_params=data, fit_quality=fit, trajectory=traj,
             options=r.settings("options"), solver=dict(r.get("solver")),
             verification=dict(doc.get("verification", {})))
    stored = doc.get("gait_hash")
    if stored is not None and stored != g.hash():
        raise r.fail("gait_hash", "does not match the file's contents (edited by hand?)")
    if model_hash is not None:
        g.check_model(model_hash, src)
    return g
