"""PHZD gait optimization: IPOPT converges from the regression's guess, and the result is a
real gait of the model, checked with independent pieces (the forward KKT dynamics and the
impact map).  The solve is the regeneration of the committed template gait
(tests/committed_gaits.py), shared with tests/test_committed_gaits.py."""

from __future__ import annotations

import numpy as np
import pytest

from characterization.phzd import CYCLE

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def result(regenerated):
    return regenerated("template")


def test_ipopt_converges(result):
    assert result.solver["success"], result.solver["status"]
    for d in CYCLE:
        assert np.all(np.abs(result.offsets[d]) <= 0.15 + 1e-6)


def test_collocation_points_satisfy_the_forward_dynamics(model, result):
    """Our KKT forward dynamics, fed the optimizer's (q, qd, u), returns its qdd and lam."""
    fs = model.numeric()
    for d in CYCLE:
        tr = result.trajectory[d]
        for k in range(tr["q"].shape[1]):
            qdd, lam = fs[f"dyn_{d}"](tr["q"][:, k], tr["qd"][:, k], tr["u"][:, k])
            np.testing.assert_allclose(qdd, tr["qdd"][:, k], atol=1e-5 * max(1, np.abs(qdd).max()))
            np.testing.assert_allclose(lam, tr["lam"][:, k], atol=1e-4 * np.abs(lam).max())
            fx, fz = lam[0], lam[1]
            assert fz > 0 and abs(fx) <= 0.6 * fz + 1e-6


def test_impacts_connect_the_domains_periodically(model, result):
    fs = model.numeric()
    ps, pns = result.trajectory["ps"], result.trajectory["pns"]
    qd_plus = fs["impact_pns"](ps["q"][:, -1], ps["qd"][:, -1])[0]
    np.testing.assert_allclose(pns["qd"][:, 0], qd_plus, atol=1e-6)
    np.testing.assert_allclose(pns["q"][:, 0], ps["q"][:, -1], atol=1e-8)
    qd_plus = fs["impact_ps"](pns["q"][:, -1], pns["qd"][:, -1])[0]
    np.testing.assert_allclose(ps["qd"][:, 0], qd_plus, atol=1e-6)
    np.testing.assert_allclose(ps["q"][1:, 0], pns["q"][1:, -1], atol=1e-8)
