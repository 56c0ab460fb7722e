"""Stability evidence of a sampled controller's walk (:func:`orbit_stability`): the return
map's spectral radius by central finite differences, and a contraction measure from starts
perturbed off the orbit (docs/experiments.md)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from orchestrator.experiments.bench import Bench
from orchestrator.experiments.scenarios import NOMINAL, Scenario

#: finite-difference steps of the return-map estimate: a sampled controller's return map is
#: not differentiable at the scale of its own quantization, so the estimate is shown at three
#: steps and trusted only where they agree
FD_STEPS = (1e-5, 1e-4, 1e-3)
#: contraction measure: perturbed post-impact starts, cycles followed, and the size of the
#: perturbation (angles rad, rates rad/s).  Under a 1 kHz controller the orbit is a thin
#: band, not a point: the human's swing-leg rates after the prosthesis's touchdown vary
#: by ~0.03 rad/s (std) from cycle to cycle with any prosthesis controller (the landing
#: instant falls between ticks), the angles by ~3e-4 rad; the perturbation is well above it
CONTRACTION_STARTS = 8
CONTRACTION_CYCLES = 4
CONTRACTION_DELTA = (1e-2, 2e-1)


def _cycle_map(bench: Bench, controller: str, cycles: int = 1
               ) -> Callable[[np.ndarray], list[np.ndarray]]:
    """P: the post-impact ps joint state (12) -> the ones after each of ``cycles`` cycles
    (ps -> pns -> ps), the controller reset at the section."""
    from characterization.gait.verification import _Section

    sec = _Section(bench.model)

    def P(s: np.ndarray) -> list[np.ndarray]:
        q, qd = sec.expand(s)
        r = bench.run(Scenario(controller, NOMINAL, 2 * cycles), start=(q, qd))
        if r.failed or r.steps < 2 * cycles or len(r.post_impact) < cycles:
            raise RuntimeError(r.reason or "the cycles did not complete")
        return r.post_impact[:cycles]  # one per cycle: after each impact into ps

    return P


def _return_map_radius(P: Callable[[np.ndarray], list[np.ndarray]], x0: np.ndarray,
                       delta: float) -> float | None:
    """Spectral radius of the central-difference Jacobian of the return map at x0."""
    J = np.empty((12, 12))
    try:
        for i in range(12):
            e = np.zeros(12)
            e[i] = delta
            J[:, i] = (P(x0 + e)[0] - P(x0 - e)[0]) / (2 * delta)
    except RuntimeError:
        return None
    return float(np.abs(np.linalg.eigvals(J)).max())


def orbit_stability(bench: Bench, controller: str, x_star: np.ndarray, seed: int = 0,
                    fd: bool = True) -> dict[str, Any]:
    """Stability evidence for a sampled controller about the post-impact state ``x_star``
    of its orbit.

    - The return map's finite-difference spectral radius at the steps ``FD_STEPS``; they
      agree (within 20 %) only where the map is differentiable at those scales.
    - A contraction measure: ``CONTRACTION_STARTS`` starts perturbed off the orbit's
      post-impact state x* in random directions (size ``CONTRACTION_DELTA``: the unit of a
      scaled norm), each followed for ``CONTRACTION_CYCLES`` cycles next to the unperturbed
      continuation from x*; per start the factor |x_K - x*_K|^(1/K) in that norm (|x_0 -
      x*| = 1), and the worst over the starts; ``orbit_band``: the largest cycle-to-cycle
      change of the unperturbed continuation in the same norm (the band the sampled loop
      walks in).  The orbit counts as contracting when every perturbed start walks and the
      worst factor is < 1.
    """
    P1 = _cycle_map(bench, controller, 1)
    radii = {f"{d:g}": _return_map_radius(P1, x_star, d) for d in FD_STEPS} if fd else {}
    vals = [v for v in radii.values() if v is not None]
    agree = bool(fd and len(vals) == len(FD_STEPS) and max(vals) <= 1.2 * min(vals))
    factors, floor = _contraction(_cycle_map(bench, controller, CONTRACTION_CYCLES), x_star,
                                  seed)
    ok = [f for f in factors if f is not None]
    worst = max(ok) if ok and len(ok) == len(factors) else None
    return {"fd_spectral_radius": radii, "fd_steps_agree": agree,
            "contraction_factor_per_cycle": factors, "contraction_worst": worst,
            "orbit_band": floor, "perturbation": list(CONTRACTION_DELTA),
            "contraction_starts": CONTRACTION_STARTS, "contraction_cycles": CONTRACTION_CYCLES,
            "contracting": bool(worst is not None and worst < 1.0)}


def _contraction(PK: Callable[[np.ndarray], list[np.ndarray]], x_star: np.ndarray, seed: int
                 ) -> tuple[list[float | None], float | None]:
    """The contraction measure of :func:`orbit_stability` with the ``CONTRACTION_CYCLES``
    map ``PK``: each perturbed start's factor per cycle (None: it did not walk) and the
    orbit band; ([], None) when the unperturbed continuation itself does not walk."""
    scale = np.r_[np.full(6, CONTRACTION_DELTA[0]), np.full(6, CONTRACTION_DELTA[1])]
    try:
        base = PK(x_star)  # the unperturbed continuation: the deviation is measured from it
    except RuntimeError:
        return [], None
    floor = float(max(np.linalg.norm((b - a) / scale) for a, b in
                      zip([x_star, *base[:-1]], base, strict=True)))
    rng = np.random.default_rng(seed)
    factors: list[float | None] = []
    for _ in range(CONTRACTION_STARTS):
        d = rng.normal(size=12)
        d /= np.linalg.norm(d)
        try:
            xs = PK(x_star + scale * d)
        except RuntimeError:
            factors.append(None)
            continue
        eK = np.linalg.norm((xs[-1] - base[-1]) / scale)
        factors.append(float(eK ** (1.0 / CONTRACTION_CYCLES)))  # e0 = 1 in these units
    return factors, floor
