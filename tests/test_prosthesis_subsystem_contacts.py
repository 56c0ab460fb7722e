"""The 5-DOF prosthesis subsystem with its foot on its heel or toe (a multi-contact model's):
driven by the full model's socket wrench and the same prosthesis torques, it moves as the full
model's prosthesis does in every domain where the prosthesis foot touches the ground, and the
ground pushes on its heel or toe as on the full model's."""

from __future__ import annotations

import numpy as np
import pytest

from hp_model.domains import DomainGraph, FootPart
from hp_model.prosthesis import ProsthesisSubsystem
from tests.multicontact_cycle import load_cycle


@pytest.fixture(scope="module")
def loaded():
    model, traj, _, _ = load_cycle()
    return model, traj, ProsthesisSubsystem(model)


STANCE = [d for d in DomainGraph.MULTICONTACT.domains if d.prosthesis_contact is not None]


def test_the_paper_subsystem_is_unchanged() -> None:
    """Built from a paper model it has the flat foot only (its functions and hash as before)."""
    from hp_model.config import (
        default_device_path,
        default_subject_path,
        load_device,
        load_subject,
    )
    from hp_model.human_prosthesis import HumanProsthesisModel

    paper = ProsthesisSubsystem(HumanProsthesisModel(load_subject(default_subject_path()),
                                                     load_device(default_device_path())))
    assert list(paper.domains) == ["ps"]
    assert not any(n.startswith("sub_dyn_") for n in paper.functions)


@pytest.mark.parametrize("domain", STANCE, ids=[d.value for d in STANCE])
def test_the_subsystem_reproduces_the_full_prosthesis_motion(loaded, domain) -> None:
    model, traj, sub = loaded
    fs, sfs = model.numeric(), sub.numeric()
    contact = domain.prosthesis_contact
    name = sub.contact_domain(contact.part)
    dyn = sfs["sub_dyn"] if contact.part == FootPart.FLAT else sfs[f"sub_dyn_{name}"]
    stack = model.domains[domain]
    rng = np.random.default_rng(3)
    tr = traj[domain]
    for k in range(0, tr["q"].shape[1], 4):  # states of the fitted cycle, torques at random
        q, qd = np.asarray(tr["q"][:, k], float), np.asarray(tr["qd"][:, k], float)
        u = rng.normal(scale=[30, 30, 30, 30, 1, 1])
        qdd, lam = (np.asarray(a, float).ravel() for a in fs[f"dyn_{domain}"](q, qd, u))
        qb, qbd, qbdd = sub.from_full(q, qd, qdd)
        qbdd_sub, lam_sub = (np.asarray(a, float).ravel() for a in dyn(
            qb, qbd, u[4:], lam[stack.wrench_slice("socket")]))
        np.testing.assert_allclose(qbdd_sub, qbdd, atol=1e-8 * max(1.0, np.abs(qbdd).max()))
        ground = lam[stack.wrench_slice(contact.name)]
        np.testing.assert_allclose(lam_sub, ground, atol=1e-7 * max(1.0, np.abs(lam).max()))
        # not vacuous: another socket wrench moves the prosthesis otherwise
        other = dyn(qb, qbd, u[4:], lam[stack.wrench_slice("socket")] + [50.0, 0.0, 0.0])[0]
        assert np.abs(np.asarray(other).ravel() - qbdd).max() > 1e-2
