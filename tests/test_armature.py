"""The drives' reflected rotor inertia (armature): the mass matrix gains exactly
diag(armature) at the actuated joints, nothing else changes; the device config's values and
the model's tree carry it (Pinocchio's agreement: test_model_pinocchio.py)."""

from __future__ import annotations

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


#: the estimate docs/subject.md gives (a 2.4-3 N m peak motor's rotor, 3.3e-6 kg m^2, plus a
#: CSD-17 wave generator, 7.9e-6), motor side; the shipped device does not carry it yet
ROTOR = "rotor_inertia = { value = 1.1e-5, estimate = true, source = \"motor side\" }\n"


def _device_with_rotors(tmp_path):
    from hp_model.config import load_device

    src = hp_model.default_device_path().read_text()
    for joint in ("knee", "ankle"):
        src = src.replace(f"[prosthesis.{joint}]\n", f"[prosthesis.{joint}]\n{ROTOR}")
    path = tmp_path / "device.toml"
    path.write_text(src)
    return load_device(path)


def test_device_config_gives_each_drive_its_reflected_inertia(tmp_path):
    """J_rotor N^2: 1.1e-5 kg m^2 through the file's 50:1, 0.0275 kg m^2 at each joint."""
    d = _device_with_rotors(tmp_path)
    for drive in (d.prosthesis.knee, d.prosthesis.ankle):
        assert drive.armature == pytest.approx(
            drive.rotor_inertia.value * drive.gear_ratio.value ** 2, rel=1e-12)
        assert drive.armature == pytest.approx(0.0275, rel=1e-12)
    shipped = hp_model.load_device(hp_model.default_device_path())
    assert shipped.prosthesis.knee.armature == 0.0  # not in the shipped estimates yet


def test_model_tree_carries_the_device_armature(tmp_path, model):
    """build_tree passes each drive's armature to its joint (th_pk: knee, th_pa: ankle)."""
    from hp_model.human_prosthesis import build_tree

    d = _device_with_rotors(tmp_path)
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
