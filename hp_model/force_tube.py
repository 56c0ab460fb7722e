"""The force tube: bounds on the socket-force deviation from nominal (paper Sec. IV-B).

With s = (tau - tau_lo) / (tau_hi - tau_lo) in [0, 1] over the single-support part of
prosthesis stance, for each component F_s = (F_x [N], F_z [N], M_y [N m]):

    F_s(tau) in [F*(tau) + dF_lo(tau),  F*(tau) + dF_hi(tau)]

with F*, dF_lo and dF_hi Bezier curves in s (coefficients stored).  Outside [tau_lo, tau_hi]
(the double-support ends of the recorded steps) the bounds of the nearest end are used.

``lower``/``upper`` are the certified LP bounds of the estimated profiles.  ``allowance``
(3,) >= 0 widens both by a constant per component for the estimation error of the playback
(the estimated profiles are not the true ones); the tube everyone uses (:meth:`box`,
:meth:`delta_bounds`, :meth:`contains`, the controllers) is the widened one:
dF_lo - allowance <= dF <= dF_hi + allowance.  (A constant added to every Bezier coefficient
shifts the curve by that constant.)

The tube may also carry the characterised **model error** of the interaction-aware
controller (``clfqp``, :class:`ModelErrorBound`): bounds on d = nu_true - (a + A u_p), what the
nominal-human model (:mod:`hp_model.interaction`) does not explain, per output acceleration
(dy1 [m/s^2], d2y2 [rad/s^2]) as Bezier curves in s = (tau - tau_lo) / (tau_hi - tau_lo) over
the mid-stance range [tau_lo, tau_hi] of the gait's ps phase, valid from
``exclude_after_touchdown`` seconds after the prosthesis's touchdown on (the impact transient
before that is left to the CLF relaxation); outside its range the bound is not defined (the
controller's margin is zero there).  On the multi-contact graph the components are the
prosthesis joints' accelerations (qdd_pk, qdd_pa [rad/s^2]) against the multi-contact
``clfqp``'s model, over the controllers' stance phase
(:mod:`characterization.tube.contact_model_error`).

File layout (``kind = "hpcosim-tube"``, ``schema_version = 2``): gait_hash, tau_lo, tau_hi,
degree, nominal (3, k+1), lower (3, m+1), upper (3, m+1), allowance (3,) (optional, default
0), n_steps, credibility {...}, source {...}, and optionally ``model_error`` {components,
units, tau_lo, tau_hi, degree, lower (2, n+1), upper (2, n+1), exclude_after_touchdown (s),
n_steps, credibility {...}, source {...}}.  Schema 1 (no ``model_error``) is still read: no
model-error bound, the controller's margin is zero.  Other versions are refused.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hp_model import bezier
from hp_model.artifacts import ArtifactError, FieldReader, load_json, save_json
from hp_model.choices import Choice

KIND = "hpcosim-tube"
SCHEMA_VERSION = 2
READABLE_VERSIONS = (1, 2)
COMPONENTS = ("F_x", "F_z", "M_y")
ERROR_COMPONENTS = ("dy1", "d2y2")  # model error d: output accelerations
ERROR_UNITS = ("m/s^2", "rad/s^2")
#: the multi-contact ``clfqp``'s model error: the prosthesis joints' accelerations
#: (:mod:`characterization.tube.contact_model_error`)
CONTACT_ERROR_COMPONENTS = ("qdd_pk", "qdd_pa")
#: each model error a bound may hold, its components -> their units
ERROR_KINDS = {ERROR_COMPONENTS: ERROR_UNITS,
               CONTACT_ERROR_COMPONENTS: ("rad/s^2", "rad/s^2")}
#: default time after the prosthesis's touchdown excluded from the model-error bound (s)
EXCLUDE_AFTER_TOUCHDOWN = 0.03


class TubePhase(Choice):
    """The phase tau a tube is a function of (``source.playback.tube_phase``;
    :mod:`characterization.tube.playback`)."""

    GAIT = "gait"  # the gait's tau of each sample's configuration (what controllers compute)
    STEP = "step"  # each step's own tau (its own phase bounds: the paper's normalization)


@dataclass(frozen=True)
class ModelErrorBound:
    """Bezier bounds of the model error d = nu_true - (a + A u_p) (module docstring):
    d(tau) in [lower(s), upper(s)], s = (tau - tau_lo) / (tau_hi - tau_lo), for tau in
    [tau_lo, tau_hi] and t - t_touchdown >= ``exclude_after_touchdown`` (s)."""

    tau_lo: float
    tau_hi: float
    lower: np.ndarray  # (2, n+1): dy1 [m/s^2], d2y2 [rad/s^2]
    upper: np.ndarray  # (2, n+1)
    exclude_after_touchdown: float = EXCLUDE_AFTER_TOUCHDOWN
    n_steps: int = 0
    credibility: Mapping[str, Any] = field(default_factory=dict)
    source: Mapping[str, Any] = field(default_factory=dict)
    #: what d is (a key of :data:`ERROR_KINDS`): the paper graph's output accelerations or
    #: the multi-contact controller's joint accelerations
    components: tuple[str, str] = ERROR_COMPONENTS

    def __post_init__(self) -> None:
        if tuple(self.components) not in ERROR_KINDS:
            raise ValueError(f"model error: components {list(self.components)} are not one "
                             f"of {[list(k) for k in ERROR_KINDS]}")
        object.__setattr__(self, "components", tuple(self.components))
        if not (math.isfinite(self.tau_lo) and math.isfinite(self.tau_hi)
                and self.tau_hi > self.tau_lo):
            raise ValueError(f"model error: need finite tau_lo < tau_hi, got "
                             f"[{self.tau_lo}, {self.tau_hi}]")
        if not (math.isfinite(self.exclude_after_touchdown)
                and self.exclude_after_touchdown >= 0):
            raise ValueError("model error: exclude_after_touchdown must be finite and >= 0")
        for name in ("lower", "upper"):
            a = np.array(getattr(self, name), dtype=float)
            if a.ndim != 2 or a.shape[0] != 2 or not np.all(np.isfinite(a)):
                raise ValueError(f"model error: {name} must be finite with shape (2, n+1), "
                                 f"got {a.shape}")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        if self.lower.shape != self.upper.shape:
            raise ValueError("model error: lower and upper bounds must have the same degree")

    @property
    def degree(self) -> int:
        return self.lower.shape[1] - 1

    @property
    def units(self) -> tuple[str, str]:
        return ERROR_KINDS[self.components]

    def phase(self, tau: float | np.ndarray) -> np.ndarray:
        """s(tau) clipped to [0, 1]."""
        return np.clip((np.asarray(tau, dtype=float) - self.tau_lo)
                       / (self.tau_hi - self.tau_lo), 0.0, 1.0)

    def bounds(self, tau: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of d at tau: (2,) each for a scalar, (n, 2) for an array."""
        s = self.phase(tau)
        return bezier.evaluate(self.lower, s), bezier.evaluate(self.upper, s)

    def in_range(self, tau: np.ndarray, since_touchdown: np.ndarray) -> np.ndarray:
        """Per sample, whether the bound is defined there (phase range, excluded time)."""
        tau = np.asarray(tau, float)
        return ((tau >= self.tau_lo) & (tau <= self.tau_hi)
                & (np.asarray(since_touchdown, float) >= self.exclude_after_touchdown))

    def contains(self, tau: np.ndarray, d: np.ndarray, tol: float | np.ndarray = 0.0
                 ) -> np.ndarray:
        """Per sample, whether both components of d (n, 2) lie inside the bound (+- tol)."""
        lo, hi = self.bounds(np.asarray(tau, float))
        return np.all((d >= lo - tol) & (d <= hi + tol), axis=1)

    def to_document(self) -> dict[str, Any]:
        return {"components": list(self.components), "units": list(self.units),
                "tau_lo": self.tau_lo, "tau_hi": self.tau_hi, "degree": self.degree,
                "lower": self.lower, "upper": self.upper,
                "exclude_after_touchdown": self.exclude_after_touchdown,
                "n_steps": self.n_steps, "credibility": dict(self.credibility),
                "source": dict(self.source)}


@dataclass(frozen=True)
class ForceTube:
    """Bezier bounds of the socket-force deviation over [tau_lo, tau_hi] (module docstring)."""

    gait_hash: str
    tau_lo: float
    tau_hi: float
    nominal: np.ndarray  # (3, k+1) F*(s)
    lower: np.ndarray  # (3, m+1) dF_lo(s)
    upper: np.ndarray  # (3, m+1) dF_hi(s)
    n_steps: int = 0
    credibility: Mapping[str, Any] = field(default_factory=dict)
    source: Mapping[str, Any] = field(default_factory=dict)
    allowance: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (N, N, N m)
    model_error: ModelErrorBound | None = None  # the clfqp's characterised model error

    def __post_init__(self) -> None:
        if not self.tau_hi > self.tau_lo:
            raise ValueError(f"tau_hi ({self.tau_hi}) must exceed tau_lo ({self.tau_lo})")
        a = np.array(self.allowance, dtype=float).reshape(-1)
        if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a < 0):
            raise ValueError(f"allowance must be 3 finite values >= 0, got {a}")
        a.setflags(write=False)
        object.__setattr__(self, "allowance", a)
        for name in ("nominal", "lower", "upper"):
            a = np.array(getattr(self, name), dtype=float)
            if a.ndim != 2 or a.shape[0] != 3:
                raise ValueError(f"{name} must have shape (3, m+1), got {a.shape}")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        if self.lower.shape != self.upper.shape:
            raise ValueError("lower and upper bounds must have the same degree")

    @property
    def degree(self) -> int:
        return self.lower.shape[1] - 1

    def phase(self, tau: float | np.ndarray) -> float | np.ndarray:
        """s(tau) clipped to [0, 1]."""
        return np.clip((np.asarray(tau, dtype=float) - self.tau_lo)
                       / (self.tau_hi - self.tau_lo), 0.0, 1.0)

    @property
    def widened_lower(self) -> np.ndarray:
        """(3, m+1) Bezier coefficients of dF_lo - allowance (the bound in use)."""
        return self.lower - self.allowance[:, None]

    @property
    def widened_upper(self) -> np.ndarray:
        """(3, m+1) Bezier coefficients of dF_hi + allowance (the bound in use)."""
        return self.upper + self.allowance[:, None]

    def delta_bounds(self, tau: float | np.ndarray, widened: bool = True
                     ) -> tuple[np.ndarray, np.ndarray]:
        """(dF_lo, dF_hi) at tau: (3,) each for scalar tau, (n, 3) for arrays; with
        ``widened=False`` the certified LP bounds without the allowance."""
        s = self.phase(tau)
        lo, hi = (self.widened_lower, self.widened_upper) if widened else (self.lower,
                                                                          self.upper)
        return bezier.evaluate(lo, s), bezier.evaluate(hi, s)

    def nominal_force(self, tau: float | np.ndarray) -> np.ndarray:
        return bezier.evaluate(self.nominal, self.phase(tau))

    def box(self, tau: float) -> tuple[np.ndarray, np.ndarray]:
        """Centre c and half-width r (both (3,)) of the socket-force box at tau:
        F_s in [c - r, c + r]."""
        s = float(self.phase(tau))
        lo, hi = bezier.evaluate(self.lower, s), bezier.evaluate(self.upper, s)
        lo, hi = lo - self.allowance, hi + self.allowance
        f = bezier.evaluate(self.nominal, s)
        return f + 0.5 * (lo + hi), 0.5 * np.maximum(hi - lo, 0.0)

    def contains(self, tau: np.ndarray, delta: np.ndarray, tol: float = 0.0) -> np.ndarray:
        """Per sample, whether every component of delta (n, 3) lies inside the tube."""
        lo, hi = self.delta_bounds(np.asarray(tau))
        return np.all((delta >= lo - tol) & (delta <= hi + tol), axis=1)


def to_document(t: ForceTube) -> dict[str, Any]:
    return {
        "kind": KIND, "schema_version": SCHEMA_VERSION, "gait_hash": t.gait_hash,
        "components": list(COMPONENTS), "tau_lo": t.tau_lo, "tau_hi": t.tau_hi,
        "degree": t.degree, "nominal": t.nominal, "lower": t.lower, "upper": t.upper,
        "allowance": t.allowance, "n_steps": t.n_steps, "credibility": dict(t.credibility),
        "source": dict(t.source),
        **({"model_error": t.model_error.to_document()} if t.model_error is not None else {}),
    }


def save_tube(path: str | os.PathLike[str], t: ForceTube) -> None:
    """Write the tube atomically."""
    save_json(path, to_document(t))


def load_tube(path: str | os.PathLike[str], gait_hash: str | None = None) -> ForceTube:
    """Read and validate a tube file; with ``gait_hash``, refuse a tube for another gait."""
    src = str(path)
    r = FieldReader(src, load_json(path, KIND, READABLE_VERSIONS))
    tau_lo, tau_hi = r.number("tau_lo", -0.5, 1.5), r.number("tau_hi", -0.5, 1.5)
    if not tau_hi > tau_lo:
        raise r.fail("tau_hi", f"must exceed tau_lo ({tau_lo})")
    m = int(r.number("degree", 0, 30))
    lower, upper = r.array("lower", (3, m + 1)), r.array("upper", (3, m + 1))
    nominal = r.array("nominal", (3, None))
    s = np.linspace(0, 1, 201)
    if np.any(bezier.evaluate(lower, s) > bezier.evaluate(upper, s) + 1e-9):
        raise r.fail("lower", "the lower bound exceeds the upper bound somewhere")
    allowance = r.array("allowance", (3,)) if "allowance" in r.doc else np.zeros(3)
    if np.any(allowance < 0):
        raise r.fail("allowance", "must be >= 0")
    t = ForceTube(gait_hash=r.string("gait_hash"), tau_lo=tau_lo, tau_hi=tau_hi,
                  nominal=nominal, lower=lower, upper=upper, allowance=allowance,
                  n_steps=int(r.number("n_steps", 0, 1e9)),
                  credibility=dict(r.get("credibility")), source=dict(r.get("source")),
                  model_error=_read_model_error(r) if "model_error" in r.doc else None)
    if gait_hash is not None and gait_hash != t.gait_hash:
        raise ArtifactError(f"{src}: field 'gait_hash': the tube was made for gait "
                            f"{t.gait_hash}, not for this gait ({gait_hash}); refit the tube")
    return t


def _read_model_error(r: FieldReader) -> ModelErrorBound:
    """The optional ``model_error`` section (schema 2), validated field by field."""
    if int(r.number("schema_version")) < 2:
        raise r.fail("model_error", "not part of schema 1 (write schema_version 2)")
    if not isinstance(r.get("model_error"), Mapping):
        raise r.fail("model_error", "not an object")
    components = tuple(r.get("model_error.components") or ())
    if components not in ERROR_KINDS:
        raise r.fail("model_error.components",
                     f"expected one of {[list(k) for k in ERROR_KINDS]}")
    lo_t = r.number("model_error.tau_lo", -0.5, 1.5)
    hi_t = r.number("model_error.tau_hi", -0.5, 1.5)
    if not hi_t > lo_t:
        raise r.fail("model_error.tau_hi", f"must exceed tau_lo ({lo_t})")
    n = int(r.number("model_error.degree", 0, 30))
    lower = r.array("model_error.lower", (2, n + 1))
    upper = r.array("model_error.upper", (2, n + 1))
    s = np.linspace(0, 1, 201)
    if np.any(bezier.evaluate(lower, s) > bezier.evaluate(upper, s) + 1e-12):
        raise r.fail("model_error.lower", "the lower bound exceeds the upper bound somewhere")
    cred = r.get("model_error.credibility")
    source = r.get("model_error.source")
    if not isinstance(cred, Mapping) or not isinstance(source, Mapping):
        raise r.fail("model_error", "credibility and source must be objects")
    return ModelErrorBound(
        tau_lo=lo_t, tau_hi=hi_t, lower=lower, upper=upper,
        exclude_after_touchdown=r.number("model_error.exclude_after_touchdown", 0.0, 10.0),
        n_steps=int(r.number("model_error.n_steps", 0, 1e9)), credibility=dict(cred),
        source=dict(source), components=components)
