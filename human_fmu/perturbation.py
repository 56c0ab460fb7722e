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
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hp_model.domains import Domain, DomainGraph

MASK = (1 << 64) - 1
GOLDEN = 0x9E3779B97F4A7C15
MIX1 = 0xBF58476D1CE4E5B9
MIX2 = 0x94D049BB133111EB


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
    with every Bezier coefficient moved by the generator's delta (the module docstring)."""
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
        for i in range(n_alpha):
            out[d][i] = out[d][i] + amplitude * (2.0 * uniform(seed, k0 + i) - 1.0)
        k0 += n_alpha
    return out
