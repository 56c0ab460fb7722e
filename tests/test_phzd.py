"""PHZD gait optimization: IPOPT converges from the regression's guess, and the result is a
real gait of the model, checked with independent pieces (the forward KKT dynamics and the
impact map).  The solve is the regeneration of the committed template gait
(tests/committed_gaits.py), shared with tests/test_committed_gaits.py."""

from __future__ import annotations

import numpy as np
import pytest

from hp_model.domains import PAPER_DOMAINS, Domain

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def result(regenerated):
    return regenerated("template")


def test_ipopt_converges(result):
    assert result.solver["success"], result.solver["status"]
    for d in PAPER_DOMAINS:
        assert np.all(np.abs(result.offsets[d]) <= 0.15 + 1e-6)


def test_collocation_points_satisfy_the_forward_dynamics(model, result):
    """Our KKT forward dynamics, fed the optimizer's (q, qd, u), returns its qdd and lam."""
    fs = model.numeric()
    for d in PAPER_DOMAINS:
        tr = result.trajectory[d]
        for k in range(tr["q"].shape[1]):
            qdd, lam = fs[f"dyn_{d}"](tr["q"][:, k], tr["qd"][:, k], tr["u"][:, k])
            np.testing.assert_allclose(qdd, tr["qdd"][:, k], atol=1e-5 * max(1, np.abs(qdd).max()))
            np.testing.assert_allclose(lam, tr["lam"][:, k], atol=1e-4 * np.abs(lam).max())
            fx, fz = lam[0], lam[1]
            assert fz > 0 and abs(fx) <= 0.6 * fz + 1e-6


def test_impacts_connect_the_domains_periodically(model, result):
    fs = model.numeric()
    ps, pns = result.trajectory[Domain.PS], result.trajectory[Domain.PNS]
    qd_plus = fs["impact_pns"](ps["q"][:, -1], ps["qd"][:, -1])[0]
    np.testing.assert_allclose(pns["qd"][:, 0], qd_plus, atol=1e-6)
    np.testing.assert_allclose(pns["q"][:, 0], ps["q"][:, -1], atol=1e-8)
    qd_plus = fs["impact_ps"](pns["q"][:, -1], pns["qd"][:, -1])[0]
    np.testing.assert_allclose(ps["qd"][:, 0], qd_plus, atol=1e-6)
    np.testing.assert_allclose(ps["q"][1:, 0], pns["q"][1:, -1], atol=1e-8)


_SMALL_SOLVE = """
import hashlib, numpy as np, hp_model
from characterization.gait.phzd import PHZDOptions, optimize_gait
from hp_model.blas_threads import blas_thread_counts
from hp_model.domains import PAPER_DOMAINS
from tests.gait_template import template_targets
r = optimize_gait(hp_model.load_model(), template_targets(), PHZDOptions(nodes=7, max_iter=15))
x = np.concatenate([np.ravel(r.trajectory[d][k]) for d in PAPER_DOMAINS
                    for k in ("q", "qd", "qdd", "u", "lam")])
print(hashlib.sha256(x.tobytes()).hexdigest(), max(blas_thread_counts().values()))
"""


def test_the_optimization_does_not_depend_on_the_thread_settings():
    """The same 15 IPOPT iterations in processes with 1, 2 and the default (unset) BLAS /
    OpenMP thread counts give bit-identical iterates.  Without the single-threaded solve
    (hp_model.blas_threads) the default/2-thread runs and the 1-thread run differ from the
    15th iteration on (measured); the default here leaves OpenBLAS more than one thread on
    a machine with two or more CPUs, which the printed thread count shows."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    base = {k: v for k, v in os.environ.items()
            if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    base["PYTHONPATH"] = str(root)
    out = {}
    for name, extra in (("unset", {}), ("1", {"OPENBLAS_NUM_THREADS": "1",
                                              "OMP_NUM_THREADS": "1"}),
                        ("2", {"OPENBLAS_NUM_THREADS": "2", "OMP_NUM_THREADS": "2"})):
        p = subprocess.run([sys.executable, "-c", _SMALL_SOLVE], cwd=root, env={**base, **extra},
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr[-2000:]
        digest, threads = p.stdout.split()[-2:]
        out[name] = digest
        if name == "2":
            assert int(threads) == 2  # the process did run with two BLAS threads outside
    assert len(set(out.values())) == 1, out
