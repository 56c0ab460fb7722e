"""The multi-contact graph (hp_model.domains.DomainGraph.MULTICONTACT): its domains' constraint
stacks, guards and impacts, and the double supports' constrained dynamics against Pinocchio
(its own contact Jacobians and acceleration drift of the heel and toe points)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from hp_model.compiled import CompileBackend
from hp_model.domains import PAPER_DOMAINS, Domain, DomainGraph, FootPart
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.urdf import to_urdf
from tests.conftest import random_state

MC = DomainGraph.MULTICONTACT


@pytest.fixture(scope="module")
def mc_model(model) -> HumanProsthesisModel:
    """The default subject and device on the multi-contact graph (interpreted: a few calls)."""
    return HumanProsthesisModel(model.subject, model.device, backend=CompileBackend.SX,
                                graph=MC)


def test_graphs_are_cycles_with_the_paper_kept():
    assert DomainGraph.PAPER.domains == PAPER_DOMAINS == (Domain.PS, Domain.PNS)
    assert MC.domains == (Domain.PS, Domain.PS_TOE, Domain.DS_H, Domain.PNS, Domain.PNS_TOE,
                          Domain.DS_P)
    for g in DomainGraph:
        walk = [g.domains[0]]
        for _ in g.domains:
            walk.append(g.next(walk[-1]))
        assert walk[-1] == walk[0] and set(walk) == set(g.domains)
    with pytest.raises(ValueError, match="not in the paper graph"):
        DomainGraph.PAPER.next(Domain.DS_H)


def test_guards_are_the_next_contacts_touchdown():
    assert [DomainGraph.PAPER.touchdown_frame(d) for d in PAPER_DOMAINS] == ["l_sole", "p_sole"]
    # heel off (a lift-off: no touchdown), heel strike, then the leading foot lands flat: its
    # toe touches down
    assert [MC.touchdown_frame(d) for d in MC.domains] == [
        None, "l_heel", "l_toe", None, "p_heel", "p_toe"]
    # armed from the entry where the landing foot was already in the air before it (the toe
    # domains, entered at the other heel's lift-off); a swing's start (the paper's domains) and
    # a heel landing flat wait for guard_tau_min
    assert [DomainGraph.PAPER.guard_from_entry(d) for d in PAPER_DOMAINS] == [False, False]
    assert [MC.guard_from_entry(d) for d in MC.domains] == [
        False, True, False, False, True, False]


def test_double_supports_hold_leading_heel_and_trailing_toe(mc_model):
    for d, lead, trail in ((Domain.DS_H, "l", "p"), (Domain.DS_P, "p", "l")):
        assert [(c.side, c.part) for c in d.contacts] == [(lead, FootPart.HEEL),
                                                          (trail, FootPart.TOE)]
        cd = mc_model.domains[d]
        assert cd.n_constraints == 2 + 2 + 3  # heel (x, z), toe (x, z), socket
        assert cd.wrench_slice(f"{lead}_heel") == slice(0, 2)
        assert cd.wrench_slice(f"{trail}_toe") == slice(2, 4)
        assert cd.wrench_slice("socket") == slice(4, 7)
    assert set(mc_model.roles) == set()  # the paper's outputs: flat stances ended by touchdown
    for d, side in ((Domain.PS_TOE, "p"), (Domain.PNS_TOE, "l")):
        assert mc_model.domains[d].n_constraints == 2 + 3
        assert mc_model.domains[d].wrench_slice(f"{side}_toe") == slice(0, 2)


def test_paper_model_is_unchanged_by_the_graph(model):
    assert model.graph == DomainGraph.PAPER and set(model.domains) == set(PAPER_DOMAINS)
    assert model.name == "hp12"
    other = HumanProsthesisModel(model.subject, model.device, backend=CompileBackend.SX,
                                 graph=MC)
    assert other.parameter_hash() != model.parameter_hash()


def _pinocchio(tree):
    pm = pin.buildModelFromXML(to_urdf(tree))
    pm.gravity.linear = np.array([0.0, 0.0, -tree.gravity])
    idx = [pm.idx_vs[pm.getJointId(n)] for n in tree.coord_names]
    joint_of_body = {b.name: b.coords[-1] for b in tree.bodies}
    for f in tree.frames:
        jid = pm.getJointId(joint_of_body[f.body])
        place = pin.SE3(np.eye(3), np.array([f.point[0], 0.0, f.point[1]]))
        pm.addFrame(pin.Frame(f.name, jid, 0, place, pin.FrameType.OP_FRAME))
    return pm, pm.createData(), idx


@pytest.mark.parametrize("dom", [Domain.DS_H, Domain.DS_P])
def test_double_support_dynamics_match_pinocchio(mc_model, rng, dom):
    """qdd and the heel, toe and socket wrenches from the model's KKT solve equal a KKT solve
    built from Pinocchio alone: CRBA, RNEA, the heel and toe frames' Jacobians and their
    classical acceleration at qdd = 0 (the drift), the socket's coordinates."""
    pm, pd, idx = _pinocchio(mc_model.tree)
    dyn = mc_model.numeric()[f"dyn_{dom}"]
    socket = [mc_model.coord_names.index(c) for c in ("x_f", "z_f", "th_f")]
    for _ in range(10):
        q, qd = random_state(mc_model, rng)
        u = rng.normal(scale=2.0, size=mc_model.nu)
        qp, vp = np.zeros(pm.nq), np.zeros(pm.nv)
        qp[idx], vp[idx] = q, qd
        M = pin.crba(pm, pd, qp)
        M = (np.triu(M) + np.triu(M, 1).T)[np.ix_(idx, idx)]
        h = pin.rnea(pm, pd, qp, vp, np.zeros(pm.nv))[idx]
        pin.forwardKinematics(pm, pd, qp, vp, np.zeros(pm.nv))
        pin.computeJointJacobians(pm, pd, qp)
        pin.updateFramePlacements(pm, pd)
        rows, drift = [], []
        for c in dom.contacts:
            fid = pm.getFrameId(c.frame)
            Jf = pin.getFrameJacobian(pm, pd, fid, pin.LOCAL_WORLD_ALIGNED)[[0, 2]][:, idx]
            a = pin.getFrameClassicalAcceleration(pm, pd, fid, pin.LOCAL_WORLD_ALIGNED).linear
            rows.append(Jf)
            drift.append(a[[0, 2]])
        Js = np.zeros((3, mc_model.nq))
        Js[range(3), socket] = 1.0
        J = np.vstack([*rows, Js])
        Jdqd = np.r_[np.concatenate(drift), np.zeros(3)]
        n = J.shape[0]
        K = np.block([[M, -J.T], [J, np.zeros((n, n))]])
        sol = np.linalg.solve(K, np.r_[mc_model.B @ u - h, -Jdqd])
        qdd, lam = dyn(q, qd, u)
        np.testing.assert_allclose(np.ravel(qdd), sol[:12], rtol=1e-8,
                                   atol=1e-8 * np.abs(sol[:12]).max())
        np.testing.assert_allclose(np.ravel(lam), sol[12:], rtol=1e-8,
                                   atol=1e-8 * np.abs(sol[12:]).max())


def test_heel_strike_impact_stops_the_heel_and_keeps_the_toe(mc_model, rng):
    """Impact into ds_h from a prosthesis-stance state: afterwards the human heel and the
    prosthesis toe are at rest (the impact is the new constraints' projection) and the
    kinetic energy does not grow."""
    fs = mc_model.numeric()
    q, qd = random_state(mc_model, rng)
    q, qd = mc_model.stance_state(q, qd, Domain.PS)
    qd_plus, _ = fs[f"impact_{Domain.DS_H}"](q, qd)
    _, vel = fs["frames"](q, np.ravel(qd_plus))
    for f in ("l_heel", "p_toe"):
        np.testing.assert_allclose(vel[:2, mc_model.frame_index(f)], 0.0, atol=1e-10)
    T0 = np.ravel(fs["energy"](q, qd)[0]).item()
    T1 = np.ravel(fs["energy"](q, np.ravel(qd_plus))[0]).item()
    assert T1 <= T0 + 1e-9
