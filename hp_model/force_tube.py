"""The force tube: bounds on the socket-force deviation from nominal (paper Sec. IV-B).

With s = (tau - tau_lo) / (tau_hi - tau_lo) in [0, 1] over the single-support part of
prosthesis stance, for each component F_s = (F_x [N], F_z [N], M_y [N m]):

    F_s(tau) in [F*(tau) + dF_lo(tau),  F*(tau) + dF_hi(tau)]

with F*, dF_lo and dF_hi Bezier curves in s (coefficients stored).  Outside [tau_lo, tau_hi]
(the double-support ends of the recorded steps) the bounds of the nearest end are used.

File layout (``kind = "hpcosim-tube"``, ``schema_version = 1``): gait_hash, tau_lo, tau_hi,
degree, nominal (3, k+1), lower (3, m+1), upper (3, m+1), n_steps, credibility {...},
source {...}.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hp_model import bezier
from hp_model.artifacts import ArtifactError, FieldReader, load_json, save_json

KIND = "hpcosim-tube"
SCHEMA_VERSION = 1
COMPONENTS = ("F_x", "F_z", "M_y")


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

    def __post_init__(self) -> None:
        if not self.tau_hi > self.tau_lo:
            raise ValueError(f"tau_hi ({self.tau_hi}) must exceed tau_lo ({self.tau_lo})")
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

    def delta_bounds(self, tau: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dF_lo, dF_hi) at tau: (3,) each for scalar tau, (n, 3) for arrays."""
        s = self.phase(tau)
        return bezier.evaluate(self.lower, s), bezier.evaluate(self.upper, s)

    def nominal_force(self, tau: float | np.ndarray) -> np.ndarray:
        return bezier.evaluate(self.nominal, self.phase(tau))

    def box(self, tau: float) -> tuple[np.ndarray, np.ndarray]:
        """Centre c and half-width r (both (3,)) of the socket-force box at tau:
        F_s in [c - r, c + r]."""
        s = float(self.phase(tau))
        lo, hi = bezier.evaluate(self.lower, s), bezier.evaluate(self.upper, s)
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
        "n_steps": t.n_steps, "credibility": dict(t.credibility), "source": dict(t.source),
    }


def save_tube(path: str | os.PathLike[str], t: ForceTube) -> None:
    """Write the tube atomically."""
    save_json(path, to_document(t))


def load_tube(path: str | os.PathLike[str], gait_hash: str | None = None) -> ForceTube:
    """Read and validate a tube file; with ``gait_hash``, refuse a tube for another gait."""
    src = str(path)
    r = FieldReader(src, load_json(path, KIND, SCHEMA_VERSION))
    tau_lo, tau_hi = r.number("tau_lo", -0.5, 1.5), r.number("tau_hi", -0.5, 1.5)
    if not tau_hi > tau_lo:
        raise r.fail("tau_hi", f"must exceed tau_lo ({tau_lo})")
    m = int(r.number("degree", 0, 30))
    lower, upper = r.array("lower", (3, m + 1)), r.array("upper", (3, m + 1))
    nominal = r.array("nominal", (3, None))
    s = np.linspace(0, 1, 201)
    if np.any(bezier.evaluate(lower, s) > bezier.evaluate(upper, s) + 1e-9):
        raise r.fail("lower", "the lower bound exceeds the upper bound somewhere")
    t = ForceTube(gait_hash=r.string("gait_hash"), tau_lo=tau_lo, tau_hi=tau_hi,
                  nominal=nominal, lower=lower, upper=upper,
                  n_steps=int(r.number("n_steps", 0, 1e9)),
                  credibility=dict(r.get("credibility")), source=dict(r.get("source")))
    if gait_hash is not None and gait_hash != t.gait_hash:
        raise ArtifactError(f"{src}: field 'gait_hash': the tube was made for gait "
                            f"{t.gait_hash}, not for this gait ({gait_hash}); refit the tube")
    return t
