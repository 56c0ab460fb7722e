"""The human's deviation from the nominal gait: a deterministic perturbation of the Bezier
coefficients, generated identically here and in the FMU's C code (``hpfmu.c``).

Generator (documented so any importer can reproduce it):

    k-th draw, k = 0, 1, ...:  z = seed + (k + 1) * 0x9E3779B97F4A7C15   (mod 2^64)
                               z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9    (mod 2^64)
                               z = (z ^ (z >> 27)) * 0x94D049BB133111EB    (mod 2^64)
                               z =  z ^ (z >> 31)
                               r = (z >> 11) * 2^-53                        in [0, 1)
    delta_k = amplitude * (2 r - 1)                                          in [-a, a)

i.e. SplitMix64 (Steele, Lea, Flood 2014) read at counter k + 1.  ``seed`` is the FMU's
32-bit Integer parameter taken modulo 2^64 (two's complement for negative seeds).  Draw
k = A_d + i perturbs the i-th entry of domain d's packed alpha (row-major (rows, m+1)), A_d
the count of alpha entries of the domains before d in the graph's walking order (the
paper's: ps then pns, so k = d * n_alpha + i with d = 0 for ps, 1 for pns); v_hip, p_min and
p_max are not perturbed.  An amplitude of 0
leaves the gait exactly nominal.

On the multi-contact graph each curve keeps its ends: the first two and the last two
coefficients of every row (:data:`KEPT_AT_EACH_END`), which set its value and slope where
its domain starts and ends, are not moved (their draws are read and left unused, so the
interior ones are the same draws as on the paper's graph).  Its six domains meet at the
contact events, four of them lift-offs where a person's joints move on without a jump, and
two are 0.1 s long: moving every coefficient on its own made the curves the person tracks
jump at each event by up to 2a in angle and, the toe domains' slope being m (a_m -
a_(m-1)) over 0.1 s, by up to 2.5 rad/s in rate at a = 0.025 rad (the packaged person's
degree-5 curves).  With the ends kept a curve moves by at most 0.625 a (at mid-domain,
degree 5), against a.  Measured on the packaged person (20 draws U(0, 0.025), 10 steps,
docs/sweeps.md): the held oracle walked 8 with every coefficient moved, 18 with the ends
kept.  The paper's graph moves every coefficient (its two domains meet at impacts, and its
results were measured so).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hp_model.contact_outputs import theta_rows
from hp_model.domains import Domain, DomainGraph

MASK = (1 << 64) - 1
GOLDEN = 0x9E3779B97F4A7C15
MIX1 = 0xBF58476D1CE4E5B9
MIX2 = 0x94D049BB133111EB
#: coefficients kept at each end of every curve on the multi-contact graph (value and slope)
KEPT_AT_EACH_END = 2


def splitmix64(seed: int, k: int) -> int:
    """The k-th (0-based) output of SplitMix64 seeded with ``seed``."""
    z = (seed + (k + 1) * GOLDEN) & MASK
    z = ((z ^ (z >> 30)) * MIX1) & MASK
    z = ((z ^ (z >> 27)) * MIX2) & MASK
    return z ^ (z >> 31)


def uniform(seed: int, k: int) -> float:
    """The k-th draw in [0, 1) (53 random bits)."""
    return (splitmix64(seed & MASK, k) >> 11) * 2.0**-53


def perturbed_thetas(thetas: Mapping[str, np.ndarray], amplitude: float, seed: int
                     ) -> dict[Domain, np.ndarray]:
    """The packed gait parameters the human tracks: ``thetas`` (every domain of one graph)
    with its Bezier coefficients moved by the generator's delta (the module docstring: on
    the multi-contact graph all but each curve's two first and two last)."""
    if not (np.isfinite(amplitude) and amplitude >= 0):
        raise ValueError(f"amplitude must be finite and >= 0, got {amplitude}")
    keys = {Domain(d) for d in thetas}
    graph = next((g for g in DomainGraph if set(g.domains) == keys), None)
    if graph is None:
        raise ValueError(f"the domains {sorted(keys)} are not those of a graph")
    out = {d: np.array(thetas[d], dtype=float) for d in graph.domains}
    if amplitude == 0:
        return out
    k0 = 0
    for d in graph.domains:
        n_alpha = out[d].size - 3  # all but v_hip, p_min, p_max
        moved = moved_coefficients(graph, d, n_alpha)
        for i in range(n_alpha):
            if moved[i]:
                out[d][i] = out[d][i] + amplitude * (2.0 * uniform(seed, k0 + i) - 1.0)
        k0 += n_alpha
    return out


def moved_coefficients(graph: DomainGraph, d: Domain, n_alpha: int) -> np.ndarray:
    """(n_alpha,) bool: which of domain ``d``'s packed Bezier coefficients the perturbation
    moves (the module docstring)."""
    moved = np.ones(n_alpha, bool)
    if graph == DomainGraph.PAPER:
        return moved
    m1, rest = divmod(n_alpha, theta_rows(d))
    if rest:
        raise ValueError(f"{d}: {n_alpha} Bezier coefficients are not {theta_rows(d)} rows")
    col = np.arange(n_alpha) % m1
    return (col >= KEPT_AT_EACH_END) & (col < m1 - KEPT_AT_EACH_END)
