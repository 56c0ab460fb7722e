"""The drives' reflected rotor inertia (armature): the mass matrix gains exactly
diag(armature) at the actuated joints, nothing else changes; the device config's values and
the model's tree carry it (Pinocchio's agreement: test_model_pinocchio.py)."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import hp_model
from hp_model.dynamics import energies, mass_matrix_and_bias
from hp_model.tree import Body, JointKind, ModelError, PlanarTree


def _tree(armature: float) -> PlanarTree:
    """A floating trunk with a two-link leg; the lower joint driven through a gear."""
    return PlanarTree((
        Body("trunk", None, JointKind.PLANAR, ("x", "z", "th"), mass=10.0, com=(0.0, 0.3),
             inertia=0.5),
        Body("thigh", "trunk", JointKind.REVOLUTE, ("hip",), mass=5.0, com=(0.0, -0.2),
             inertia=0.1),
        Body("shin", "thigh", JointKind.REVOLUTE, ("knee",), placement=(0.0, -0.4), mass=3.0,
             com=(0.02, -0.2), inertia=0.05, armature=armature),
    ))


def _D_H(tree: PlanarTree, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    qs, qds = ca.SX.sym("q", tree.nq), ca.SX.sym("qd", tree.nq)
    D, H = mass_matrix_and_bias(tree, qs, qds)
    f = ca.Function("f", [qs, qds], [D, H])
    Dn, Hn = f(q, qd)
    return np.array(Dn), np.array(Hn).ravel()


def test_mass_matrix_gains_exactly_the_armature_on_its_joint():
    rng = np.random.default_rng(3)
    a = 0.0275  # kg m^2: the device's 1.1e-5 kg m^2 (motor side) through its 50:1 gear
    for _ in range(5):
        q, qd = rng.normal(size=5), rng.normal(size=5)
        D0, H0 = _D_H(_tree(0.0), q, qd)
        D1, H1 = _D_H(_tree(a), q, qd)
        expected = np.zeros((5, 5))
        expected[4, 4] = a
        np.testing.assert_allclose(D1 - D0, expected, atol=1e-12)
        np.testing.assert_allclose(H1, H0, atol=1e-12)  # no bias term from a rotor


def test_kinetic_energy_holds_the_rotor():
    """T gains 1/2 a qd_knee^2: the rotor spinning at N times the joint rate."""
    qs, qds = ca.SX.sym("q", 5), ca.SX.sym("qd", 5)
    q, qd = np.array([0.1, 0.9, 0.05, -0.3, 0.6]), np.array([0.2, -0.1, 0.4, 1.0, -2.0])
    T = [float(ca.Function("T", [qs, qds], [energies(_tree(a), qs, qds)[0]])(q, qd))
         for a in (0.0, 0.0275)]
    assert T[1] - T[0] == pytest.approx(0.5 * 0.0275 * qd[4] ** 2, rel=1e-12)


def test_tree_lists_its_armature_and_subtrees_keep_it():
    t = _tree(0.0275)
    assert t.armature == {"knee": 0.0275}
    assert t.subtree("thigh").armature == {"knee": 0.0275}
    assert _tree(0.0).armature == {}


@pytest.mark.parametrize(("joint", "coords", "armature", "why"), [
    ("revolute", ("knee",), -0.1, "must be >= 0"),
    ("planar", ("a", "b", "c"), 0.1, "needs a revolute joint"),
])
def test_bad_armature_is_a_model_error(joint, coords, armature, why):
    with pytest.raises(ModelError, match=why):
        Body("shin", "thigh", joint, coords, armature=armature)


def _shipped_device():
    """The shipped device: each drive's rotor_inertia is docs/subject.md's estimate (a 2.4-3
    N m peak motor's rotor, 3.3e-6 kg m^2, plus a CSD-17 wave generator, 7.9e-6), motor side."""
    return hp_model.load_device(hp_model.default_device_path())


def test_device_config_gives_each_drive_its_reflected_inertia():
    """J_rotor N^2: 1.1e-5 kg m^2 through the file's 50:1, 0.0275 kg m^2 at each joint."""
    d = _shipped_device()
    for drive in (d.prosthesis.knee, d.prosthesis.ankle):
        assert drive.armature == pytest.approx(
            drive.rotor_inertia.value * drive.gear_ratio.value ** 2, rel=1e-12)
        assert drive.armature == pytest.approx(0.0275, rel=1e-12)


def test_the_papers_graph_leaves_the_armature_out(model):
    """The paper's model has rigid links and ideal drives: on its graph the shipped device's
    rotor inertia is left out, and the model's hash is the one the paper's gaits recorded;
    the multi-contact graph keeps it, at the prosthesis knee and ankle only."""
    import json

    from hp_model.human_prosthesis import HumanProsthesisModel

    device = hp_model.load_device(hp_model.default_device_path())
    paper = HumanProsthesisModel(model.subject, device)
    assert paper.tree.armature == {}
    assert "rotor_inertia" not in paper.device.model_dump(mode="json")["prosthesis"]["knee"]
    recorded = json.loads(
        (Path(__file__).parents[1] / "characterization/data/reference_gait.json").read_text())
    assert paper.parameter_hash() == recorded["model_hash"]
    multi = HumanProsthesisModel(model.subject, device, graph="multicontact")
    assert multi.tree.armature == pytest.approx({"th_pk": 0.0275, "th_pa": 0.0275})
    q = np.random.default_rng(3).uniform(-0.5, 0.5, multi.nq)
    (D_multi, H_multi), (D_paper, H_paper) = (_D_H(m.tree, q, q) for m in (multi, paper))
    added = np.zeros(multi.nq)
    for c in ("th_pk", "th_pa"):
        added[multi.tree.coord_index(c)] = 0.0275
    np.testing.assert_allclose(D_multi - D_paper, np.diag(added), atol=1e-12)
    np.testing.assert_allclose(H_multi, H_paper, atol=1e-9)


def test_model_tree_carries_the_device_armature(model):
    """build_tree passes each drive's armature to its joint (th_pk: knee, th_pa: ankle)."""
    from hp_model.human_prosthesis import build_tree

    d = _shipped_device()
    tree = build_tree(model.subject, d)
    assert tree.armature == pytest.approx({"th_pk": d.prosthesis.knee.armature,
                                           "th_pa": d.prosthesis.ankle.armature})


def test_device_file_without_rotor_inertia_keeps_its_hash(tmp_path):
    """A device file written before the armature loads with none, and its model hash is the
    one its gaits recorded (the absent field is not in the hashed dump)."""
    import re

    from hp_model.config import load_device

    src = hp_model.default_device_path().read_text()
    old = re.sub(r"(?m)^rotor_inertia = .*\n", "", src)
    p = tmp_path / "device.toml"
    p.write_text(old)
    d = load_device(p)
    assert d.prosthesis.knee.armature == 0.0 and d.prosthesis.ankle.armature == 0.0
    assert "rotor_inertia" not in d.model_dump(mode="json")["prosthesis"]["knee"]


def test_a_device_with_its_armature_scaled():
    """The sweep's `plant.armature`: each drive's rotor inertia (so its armature) times the
    factor, nothing else; a bad factor is refused."""
    from hp_model.config import default_device_path, load_device

    dev = load_device(default_device_path())
    heavy = dev.with_armature_scaled(1.5)
    for j in ("knee", "ankle"):
        assert getattr(heavy.prosthesis, j).armature == pytest.approx(
            1.5 * getattr(dev.prosthesis, j).armature)
    assert heavy.prosthesis.shin == dev.prosthesis.shin and heavy.iwalk == dev.iwalk
    assert dev.without_armature().with_armature_scaled(2.0) == dev.without_armature()
    for bad in (0.0, -1.0, float("inf")):
        with pytest.raises(ValueError, match="armature factor"):
            dev.with_armature_scaled(bad)
