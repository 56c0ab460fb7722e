"""The gait artifact: round trip, hash, refusal of a gait for other parameters or edited by
hand or of an older version, one-line errors naming the field; the controllers' curves
stored by ``gait fit``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from characterization.gait.controller_curves import (
    SOCKET_PITCH_DEGREE,
    STANCE_TORQUE_DEGREE,
    fit_controller_curves,
)
from hp_model.artifacts import ArtifactError
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.gait_artifact import load_gait, save_gait
from tests.committed_gaits import RECIPES, ROOT


def test_round_trip_keeps_everything(tmp_path, model, template_gait):
    p = tmp_path / "gait.json"
    save_gait(p, template_gait)
    g = load_gait(p, model.parameter_hash())
    assert g.hash() == template_gait.hash()
    for d in PAPER_DOMAINS:
        np.testing.assert_allclose(g.params[d].alpha, template_gait.params[d].alpha)
    np.testing.assert_allclose(g.socket_force(0.5), template_gait.socket_force(0.5))
    assert g.solver["status"] == "Solve_Succeeded"


def test_nominal_socket_force_carries_the_body_weight(model, template_gait):
    """Mid-stance, the vertical socket force is about the weight above the socket."""
    fz = template_gait.socket_force(0.5)[1]
    w = (66.132 - model.prosthesis_mass) * 9.81
    assert -1.6 * w < fz < -0.4 * w


def test_other_model_parameters_are_refused(tmp_path, template_gait):
    p = tmp_path / "gait.json"
    save_gait(p, template_gait)
    with pytest.raises(ArtifactError, match="model_hash"):
        load_gait(p, "0123456789abcdef")


@pytest.mark.parametrize("edit, field", [
    (lambda d: d.update(schema_version=99), "schema_version"),
    (lambda d: d["domains"][Domain.PS].update(v_hip=-1.0), "domains.ps.v_hip"),
    (lambda d: d["domains"][Domain.PNS].update(alpha=[[0.0]]), "domains.pns.alpha"),
    (lambda d: d["domains"][Domain.PS]["alpha"][0].__setitem__(0, 0.3), "gait_hash"),
    (lambda d: d.pop("model_hash"), "model_hash"),
])
def test_bad_fields_are_named(tmp_path, template_gait, edit, field):
    p = tmp_path / "gait.json"
    save_gait(p, template_gait)
    doc = json.loads(p.read_text())
    edit(doc)
    p.write_text(json.dumps(doc))
    with pytest.raises(ArtifactError, match=field.replace(".", r"\.")) as e:
        load_gait(p)
    assert "\n" not in str(e.value)


def test_round_trip_keeps_the_controller_curves(tmp_path, template_gait):
    p = tmp_path / "gait.json"
    save_gait(p, template_gait)
    g = load_gait(p)
    for name in ("socket_pitch", "stance_torque"):
        np.testing.assert_array_equal(getattr(g.controller_curves, name),
                                      getattr(template_gait.controller_curves, name))


def test_a_version_1_gait_is_refused_with_the_command_that_remakes_it(tmp_path,
                                                                      template_gait):
    p = tmp_path / "old.json"
    save_gait(p, template_gait)
    doc = json.loads(p.read_text())
    doc["schema_version"] = 1
    doc.pop("controller_curves")
    p.write_text(json.dumps(doc))
    with pytest.raises(ArtifactError, match="hpcosim gait fit") as e:
        load_gait(p)
    assert str(p) in str(e.value) and "\n" not in str(e.value)


def test_bad_controller_curves_are_named(tmp_path, template_gait):
    p = tmp_path / "gait.json"
    save_gait(p, template_gait)
    doc = json.loads(p.read_text())
    doc["controller_curves"]["stance_torque"]["coeffs"] = [[0.0]]
    p.write_text(json.dumps(doc))
    with pytest.raises(ArtifactError, match=r"controller_curves\.stance_torque\.coeffs"):
        load_gait(p)


@pytest.mark.parametrize("name", sorted(RECIPES))
def test_committed_gaits_carry_the_curves_fitted_from_their_trajectory(model, name):
    """``gait fit`` stores what :mod:`characterization.gait.controller_curves` fits from the
    gait's own trajectory (bit for bit): the controllers read these instead of refitting."""
    g = load_gait(ROOT / RECIPES[name].path, model.parameter_hash())
    fitted = fit_controller_curves(model, g.params, g.trajectory)
    assert g.controller_curves.socket_pitch.shape == (1, SOCKET_PITCH_DEGREE + 1)
    assert g.controller_curves.stance_torque.shape == (2, STANCE_TORQUE_DEGREE + 1)
    np.testing.assert_array_equal(g.controller_curves.socket_pitch, fitted.socket_pitch)
    np.testing.assert_array_equal(g.controller_curves.stance_torque, fitted.stance_torque)
