"""The rigid impact map (Grizzle, Westervelt) and the ps -> pns -> ps cycle."""

from __future__ import annotations

import numpy as np
import pytest

from hp_model.domains import PAPER_DOMAINS, Domain
from tests.conftest import random_state


@pytest.mark.parametrize("target", list(PAPER_DOMAINS))
def test_impact_zeroes_constraint_velocity_and_dissipates(model, rng, target):
    fs = model.numeric()
    for _ in range(50):
        q, qd = random_state(model, rng)
        qd_plus, impulse = fs[f"impact_{target}"](q, qd)
        qd_plus = qd_plus.copy()
        D, _, E, _ = fs[f"terms_{target}"](q, qd)
        assert np.abs(E @ qd_plus).max() < 1e-9 * max(1.0, np.abs(qd).max())
        T_minus, T_plus = 0.5 * qd @ D @ qd, 0.5 * qd_plus @ D @ qd_plus
        assert T_plus <= T_minus * (1 + 1e-12)
        # momentum balance: D (qd+ - qd-) = E^T F_I
        np.testing.assert_allclose(D @ (qd_plus - qd), E.T @ impulse, atol=1e-8)
        # the energy lost is exactly the kinetic energy of the velocity jump (Carnot)
        dq = qd_plus - qd
        assert T_minus - T_plus == pytest.approx(0.5 * dq @ D @ dq, rel=1e-8, abs=1e-9)


def test_impact_is_a_projection(model, rng):
    """Applying the impact twice changes nothing: post-impact states satisfy the constraint."""
    fs = model.numeric()
    q, qd = random_state(model, rng)
    once = fs["impact_pns"](q, qd)[0].copy()
    twice = fs["impact_pns"](q, once)[0].copy()
    np.testing.assert_allclose(twice, once, atol=1e-10)


def test_ps_pns_ps_cycle_relabels_consistently(model, rng):
    """Touchdown of the human foot (ps -> pns) then of the prosthesis foot (pns -> ps): each
    map uses the new stance foot and the socket, keeps positions, and leaves the fixed joint
    still; the old stance foot is released (it may lift off)."""
    fs = model.numeric()
    assert model.domains[Domain.PS].next == Domain.PNS
    assert model.domains[Domain.PNS].next == Domain.PS
    assert model.domains[Domain.PS].swing_frame == "l_sole"
    assert model.domains[Domain.PNS].swing_frame == "p_sole"
    q, _ = random_state(model, rng, scale=0.1)
    q = model.place_stance_foot(q, Domain.PS)
    _, _, Jps, _ = fs["terms_ps"](q, np.zeros(model.nq))
    qd = rng.normal(size=model.nq)
    qd -= np.linalg.pinv(Jps) @ (Jps @ qd)  # moving in ps
    qd1 = fs["impact_pns"](q, qd)[0].copy()
    _, _, Jpns, _ = fs["terms_pns"](q, qd1)
    assert np.abs(Jpns @ qd1).max() < 1e-9
    assert np.abs(qd1[7:10]).max() < 1e-9  # socket still fixed
    qd2 = fs["impact_ps"](q, qd1)[0].copy()
    assert np.abs(Jps @ qd2).max() < 1e-9
    T = [0.5 * v @ fs["terms_ps"](q, v)[0] @ v for v in (qd, qd1, qd2)]
    assert T[2] <= T[1] * (1 + 1e-12) <= T[0] * (1 + 1e-12) ** 2


def test_guards_measure_swing_foot_height(model, rng):
    fs = model.numeric()
    q, qd = random_state(model, rng)
    pose, vel = fs["frames"](q, qd)
    h, vz = fs["guard_ps"](q, qd)
    assert h[0] == pytest.approx(pose[1, model.frame_index("l_sole")], abs=1e-12)
    assert vz[0] == pytest.approx(vel[1, model.frame_index("l_sole")], abs=1e-12)
    h, vz = fs["guard_pns"](q, qd)
    assert h[0] == pytest.approx(pose[1, model.frame_index("p_sole")], abs=1e-12)
