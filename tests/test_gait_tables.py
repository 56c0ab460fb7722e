"""The multi-contact controllers' file (:mod:`prosthesis_controller.gait_tables`; ``clfqp``,
contact-pd and the paper's baselines on the graph): saved and loaded back, it is the same
controller (the same torque and diagnostics, tick by tick,
over a walk's measurements); a bad file is a one-line error naming the file and field."""

from __future__ import annotations

import json

import numpy as np
import pytest

from characterization.gait.contact_gait import contact_gait_of, start_state
from characterization.gait.multicontact import GRAPH
from hp_model.artifacts import ArtifactError
from orchestrator.cosim.contact_controllers import contact_clfqp, loop_simulator
from orchestrator.loop.link import measurement
from orchestrator.loop.plant import SimulatorPlant
from prosthesis_controller.gait_tables import load_contact_controller, save_contact_controller
from tests.multicontact_cycle import load_cycle


@pytest.fixture(scope="module")
def made():
    """The controller with a robust term (a model-error box over the middle of its flat
    single support), so that the file carries one."""
    from hp_model.force_tube import ModelErrorBound

    model, traj, durations, _ = load_cycle()
    gait = contact_gait_of(model, traj, durations)
    box = ModelErrorBound(0.3, 0.5, np.array([[-3.0, -1.0], [-2.0, -2.0]]),
                          np.array([[1.0, 3.0], [2.0, 4.0]]), components=("qdd_pk", "qdd_pa"))
    ctl = contact_clfqp(model, gait, traj, model_error=box)
    assert np.any(ctl.stance.d_radius > 0)
    return model, traj, gait, ctl


@pytest.mark.parametrize("swing_phase", ["time", "thigh"])
def test_a_loaded_controller_ticks_as_the_one_saved(tmp_path, made, swing_phase):
    model, traj, gait, ctl = made
    if swing_phase != ctl.law.swing_phase:
        ctl = contact_clfqp(model, gait, traj, swing_phase=swing_phase)
    path = tmp_path / "clfqp.npz"
    save_contact_controller(path, ctl, model, "gaithash")
    loaded, loaded_model = load_contact_controller(path, model.parameter_hash())
    assert loaded_model.parameter_hash() == model.parameter_hash()
    assert loaded.law.swing_phase == swing_phase
    # up to two steps of the walk, each measurement ticked by both
    stance = _ticks_alike(model, traj, gait, ctl, loaded, 2)
    # the QP ran through a stance (the thigh's swing on this cycle lands 1 ms after the
    # person's foot slips, at tau 1.06 of its toe's single support: the same for both)
    assert stance > 300


def _ticks_alike(model, traj, gait, a_ctl, b_ctl, steps: int) -> int:
    """Walk ``steps`` steps of ``gait`` on ``a_ctl``, ticking ``b_ctl`` on each measurement
    too, their torques and diagnostics equal; the stance ticks."""
    q0, qd0 = start_state(traj)
    plant = SimulatorPlant(loop_simulator(model, gait, (20.0, 1600.0, 80.0)), q0, qd0,
                           GRAPH.domains[0])
    a_ctl.reset()
    stance = 0
    while plant.run.steps < steps and plant.fall is None:
        m = measurement(plant.observe())
        a, b = a_ctl.tick(m), b_ctl.tick(m)
        assert np.array_equal(a.torque, b.torque)
        assert a.diagnostics == b.diagnostics
        stance += a.diagnostics.mode == "stance"
        plant.actuate(a.torque)
        if plant.fall is None:
            plant.advance()
    return stance


@pytest.mark.parametrize("law", ["phase-pd", "pd", "passive"])
def test_a_baselines_file_ticks_as_the_one_saved(tmp_path, made, law):
    """The file of contact-pd and of the paper's baselines on this graph holds its law: the
    loaded controller is the same one, tick by tick over its walk (``passive`` with its
    reference accelerations and gains); the node builds it by that name only."""
    from orchestrator.cosim.contact_controllers import make_baseline, make_contact_pd
    from prosthesis_controller.gait_tables import law_of
    from prosthesis_controller.node import build_controller

    model, traj, gait, _ = made
    ctl = (make_contact_pd(model, gait, traj) if law == "phase-pd"
           else make_baseline(law, model, gait, traj))
    path = tmp_path / f"{law}.npz"
    save_contact_controller(path, ctl, model, "gaithash")
    loaded, _ = load_contact_controller(path, model.parameter_hash())
    assert type(loaded) is type(ctl) and law_of(loaded) == law
    assert _ticks_alike(model, traj, gait, ctl, loaded, 1) > 300
    assert law_of(build_controller(law, None, None, tables=str(path))) == law
    with pytest.raises(ValueError, match=f"holds {law}"):
        build_controller("clfqp", None, None, tables=str(path))


def test_bad_files_are_one_line_errors(tmp_path, made):
    model, _, _, ctl = made
    path = tmp_path / "clfqp.npz"
    save_contact_controller(path, ctl, model, "gaithash")
    with pytest.raises(ArtifactError, match="model_hash"):
        load_contact_controller(path, "another")
    junk = tmp_path / "junk.npz"
    junk.write_text("not a file of arrays")
    with pytest.raises(ArtifactError, match=r"junk\.npz: not a controller file"):
        load_contact_controller(junk)
    with np.load(path) as z:
        data = {k: z[k] for k in z.files}
    meta = json.loads(str(data["meta"]))
    meta["kind"] = "hpcosim-gait"
    wrong = tmp_path / "wrong.npz"
    np.savez(wrong, **{**data, "meta": np.array(json.dumps(meta))})
    with pytest.raises(ArtifactError, match="field 'kind'"):
        load_contact_controller(wrong)
    meta = json.loads(str(data["meta"]))
    meta["config"]["strike_window"] = 0  # the heel strike sensor refuses it
    bad = tmp_path / "bad.npz"
    np.savez(bad, **{**data, "meta": np.array(json.dumps(meta))})
    with pytest.raises(ArtifactError, match="field 'meta': heel strike window"):
        load_contact_controller(bad)
    meta = json.loads(str(data["meta"]))
    meta["law"] = "clfqp-paper"  # the paper's graph's
    bad = tmp_path / "law.npz"
    np.savez(bad, **{**data, "meta": np.array(json.dumps(meta))})
    with pytest.raises(ArtifactError, match="field 'meta': law 'clfqp-paper'"):
        load_contact_controller(bad)
    del data["qp.G"]
    cut = tmp_path / "cut.npz"
    np.savez(cut, **data)
    with pytest.raises(ArtifactError, match="field 'qp'"):
        load_contact_controller(cut)


def test_a_speed_following_file_ticks_as_the_setup_saved(tmp_path, made):
    """A gait library's controller file (:class:`FollowingSetup`: controllers at two
    speeds, the estimate's calibration) loads as the same speed-following controller: the
    same torques, diagnostics, estimates and switches, tick by tick over three steps; the
    file kinds are told apart, and a damaged one is a one-line error naming its field."""
    from prosthesis_controller.gait_tables import (
        load_controller_file,
        load_speed_following,
        save_speed_following,
    )
    from prosthesis_controller.speed_following import FollowingSetup

    model, traj, gait, robust = made
    plain = contact_clfqp(model, gait, traj)
    # the hip's flat-stance rate r reads as 0.9 + 0.2 (r - 0.5) m/s: about 1.0 on this gait,
    # so the controller starting at 0.9 m/s switches at the second heel strike
    setup = FollowingSetup((robust, plain), (0.9, 1.1), 0.05, (0.9, 1.1), (0.5, 1.5))
    path = tmp_path / "following.npz"
    save_speed_following(path, setup, model, "libhash")
    back, back_model, library_hash = load_speed_following(path, model.parameter_hash())
    assert library_hash == "libhash" and back_model.parameter_hash() == model.parameter_hash()
    assert back.speeds == setup.speeds and back.rates == setup.rates
    a, b = setup.controller(0.9), load_controller_file(path, 0.9)
    assert len(a.controllers) == len(b.controllers) == 5  # 0.9, 0.95, ..., 1.1
    q0, qd0 = start_state(traj)
    plant = SimulatorPlant(loop_simulator(model, gait, (20.0, 1600.0, 80.0)), q0, qd0,
                           GRAPH.domains[0])
    actives = set()
    while plant.run.steps < 3:
        m = measurement(plant.observe())
        x, y = a.tick(m), b.tick(m)
        assert np.array_equal(x.torque, y.torque) and x.diagnostics == y.diagnostics
        assert (a.speed, a.active) == (b.speed, b.active)
        actives.add(a.active)
        plant.actuate(x.torque)
        assert plant.fall is None
        plant.advance()
    assert len(actives) >= 2 and 0.95 < a.speed < 1.1  # it read the walk and switched
    assert load_controller_file(path).initial_speed == 0.9  # default: the slowest
    single = tmp_path / "clfqp.npz"
    save_contact_controller(single, plain, model, "gaithash")
    with pytest.raises(ValueError, match="single gait"):
        load_controller_file(single, 1.0)
    with pytest.raises(ArtifactError, match="field 'kind'"):
        load_speed_following(single)
    with np.load(path) as z:
        data = {k: z[k] for k in z.files}
    del data["c1.qp.G"]
    cut = tmp_path / "cut.npz"
    np.savez(cut, **data)
    with pytest.raises(ArtifactError, match=r"field 'c1\.qp'"):
        load_controller_file(cut, 1.0)
