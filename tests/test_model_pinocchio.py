"""D(q) and H(q, qd) against Pinocchio, an independent rigid-body library, loading a URDF
generated from the same parameters (same coordinates and signs: pitch about +y) with the
drives' reflected rotor inertias as Pinocchio's ``model.armature``."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import hp_model
from hp_model.domains import PAPER_DOMAINS
from hp_model.urdf import to_urdf
from tests.conftest import random_state

N_STATES = 100
REL_TOL = 1e-8


def _pin(tree):
    """Pinocchio's model of the tree's URDF, with the drives' reflected rotor inertias set as
    its ``armature`` (the URDF has no field for them)."""
    pm = pin.buildModelFromXML(to_urdf(tree))
    pm.gravity.linear = np.array([0.0, 0.0, -tree.gravity])
    idx = [pm.idx_vs[pm.getJointId(n)] for n in tree.coord_names]
    armature = np.zeros(pm.nv)
    for c, j in tree.armature.items():
        armature[idx[tree.coord_index(c)]] = j
    pm.armature = armature
    return pm, pm.createData(), idx


def _compare(hm, tree, states):
    pm, pd, idx = _pin(tree)
    assert pm.nq == pm.nv == hm.nq
    dom = next(iter(hm.domains))
    terms = hm.numeric()[f"terms_{dom}"]
    worst_D = worst_H = 0.0
    for q, qd in states:
        qp, vp = np.zeros(pm.nq), np.zeros(pm.nv)
        qp[idx], vp[idx] = q, qd
        M = pin.crba(pm, pd, qp)
        M = np.triu(M) + np.triu(M, 1).T
        h = pin.rnea(pm, pd, qp, vp, np.zeros(pm.nv))
        D, H, _, _ = terms(q, qd)
        Mp, hp = M[np.ix_(idx, idx)], h[idx]
        worst_D = max(worst_D, np.abs(D - Mp).max() / np.abs(Mp).max())
        worst_H = max(worst_H, np.abs(H - hp).max() / max(np.abs(hp).max(), 1.0))
    assert worst_D < REL_TOL, f"D differs from Pinocchio's CRBA by {worst_D:.2e} (relative)"
    assert worst_H < REL_TOL, f"H differs from Pinocchio's RNEA by {worst_H:.2e} (relative)"


def test_full_model_D_H_match_pinocchio(model, rng):
    states = [random_state(model, rng, on_socket=False, scale=1.0) for _ in range(N_STATES)]
    _compare(model, model.tree, states)


def test_subsystem_D_H_match_pinocchio(subsystem, rng):
    states = [(rng.normal(size=5), rng.normal(scale=2.0, size=5)) for _ in range(N_STATES)]
    _compare(subsystem, subsystem.tree, states)


@pytest.fixture(scope="module")
def worn(model):
    """The multi-contact model of the shipped device: its drives carry their armature (the
    paper's graph leaves it out, so ``model`` has none)."""
    from hp_model.human_prosthesis import HumanProsthesisModel

    m = HumanProsthesisModel(model.subject, hp_model.load_device(hp_model.default_device_path()),
                             graph="multicontact")
    assert set(m.tree.armature) == {"th_pk", "th_pa"}
    return m


def test_model_with_armature_D_H_match_pinocchio(worn, rng):
    states = [random_state(worn, rng, on_socket=False, scale=1.0) for _ in range(N_STATES)]
    _compare(worn, worn.tree, states)


def test_subsystem_with_armature_D_H_match_pinocchio(worn, rng):
    from hp_model.prosthesis import ProsthesisSubsystem

    sub = ProsthesisSubsystem(worn)
    assert set(sub.tree.armature) == {"th_pk", "th_pa"}
    states = [(rng.normal(size=5), rng.normal(scale=2.0, size=5)) for _ in range(N_STATES)]
    _compare(sub, sub.tree, states)


def test_frame_positions_match_pinocchio(model, rng):
    """Joint origins (knees, ankles, socket, hip) at the same world positions."""
    pm, pd, idx = _pin(model.tree)
    frames = model.numeric()["frames"]
    joint_of = {"l_knee": "th_lk", "l_ankle": "th_la", "socket": "th_f", "p_knee": "th_pk",
                "p_ankle": "th_pa", "hip": "th_B"}
    for _ in range(20):
        q, qd = random_state(model, rng, on_socket=False, scale=1.0)
        qp = np.zeros(pm.nq)
        qp[idx] = q
        pin.forwardKinematics(pm, pd, qp)
        pose, _ = frames(q, qd)
        for f, j in joint_of.items():
            p = pd.oMi[pm.getJointId(j)].translation
            np.testing.assert_allclose(pose[0:2, model.frame_index(f)], p[[0, 2]], atol=1e-12)


@pytest.mark.parametrize("dom", list(PAPER_DOMAINS))
def test_constrained_dynamics_match_pinocchio_kkt(model, rng, dom):
    """qdd and wrenches from our KKT solve equal Pinocchio's D, H fed to a dense LU solve."""
    pm, pd, idx = _pin(model.tree)
    terms, dyn = model.numeric()[f"terms_{dom}"], model.numeric()[f"dyn_{dom}"]
    for _ in range(20):
        q, qd = random_state(model, rng)
        u = rng.normal(scale=2.0, size=model.nu)
        qp, vp = np.zeros(pm.nq), np.zeros(pm.nv)
        qp[idx], vp[idx] = q, qd
        M = pin.crba(pm, pd, qp)
        M = (np.triu(M) + np.triu(M, 1).T)[np.ix_(idx, idx)]
        h = pin.rnea(pm, pd, qp, vp, np.zeros(pm.nv))[idx]
        _, _, J, Jdqd = terms(q, qd)
        K = np.block([[M, -J.T], [J, np.zeros((6, 6))]])
        sol = np.linalg.solve(K, np.r_[model.B @ u - h, -Jdqd])
        qdd, lam = dyn(q, qd, u)
        np.testing.assert_allclose(qdd, sol[:12], rtol=1e-8, atol=1e-8 * np.abs(sol[:12]).max())
        np.testing.assert_allclose(lam, sol[12:], rtol=1e-8, atol=1e-8 * np.abs(sol[12:]).max())
