"""The co-simulation of a multi-contact gait: ``hpcosim run --controller clfqp`` with the
committed openOFM cycle's gait file builds the FMU of its six domains and the controller's
file, starts the controller process over zenoh (AMPRO3's CAN frames), walks 10 steps,
records them; the recording replays through the recorded controller with no difference, the
same run in process (the same controller file, measurements and torques quantized as on the
bus) walks the same walk, and the force tube refits from the recording."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bus_schemas.recording.reader import read_messages
from characterization.gait.contact_gait import start_state
from orchestrator.cli import main as hpcosim
from orchestrator.cosim.config import CosimConfig
from orchestrator.cosim.contact_controllers import (
    ensure_controller_file,
    load_contact_run,
    loop_simulator,
)
from orchestrator.cosim.master import run_cosim
from orchestrator.cosim.recording import replay
from orchestrator.loop import ControllerLink, SimulatorPlant, run_loop
from prosthesis_controller.gait_tables import load_contact_controller
from tests.multicontact_cycle import write_gait_file

STEPS = 10  # the note measures 20; 10 cover the stride's every transition five times
serial = pytest.mark.serial  # wall-clock limits of a lockstep run (tests/test_cosim.py)


@pytest.fixture(scope="module")
def gait_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("mccosim") / "openofm_multicontact.json"
    write_gait_file(path)
    return path


@pytest.fixture(scope="module")
def walked(gait_file):
    rec = gait_file.parent / "run.mcap"
    res = run_cosim(CosimConfig(controller="clfqp", gait=gait_file, tube=None,
                                steps=STEPS, record=rec))
    return res, rec


@serial
def test_clfqp_walks_the_multicontact_cosimulation(walked):
    res, _ = walked
    assert not res.faulted and not res.fell, res
    assert res.steps == STEPS and res.missed == 0
    assert res.torque_clamped == 0
    assert res.node["ticks"] == res.ticks and res.node["reason"] == "plant gone"
    assert all(v == 0 for v in res.plant_rejects.values())


@serial
def test_the_recording_replays_and_equals_the_run_in_process(walked, gait_file):
    res, rec = walked
    assert replay(rec).max_torque_diff == 0.0
    run = load_contact_run(gait_file)
    ctl, _ = load_contact_controller(ensure_controller_file(gait_file, run))
    q0, qd0 = start_state(run.trajectory)
    plant = SimulatorPlant(loop_simulator(run.model, run.gait, run.tracked.gains), q0, qd0)
    log = run_loop(plant, ControllerLink(ctl, quantize=True), steps=STEPS)
    assert log.fall is None and log.steps == STEPS
    gt = np.array([o["q"] for _, _, o in read_messages(rec, ["/ground_truth"])])
    assert len(gt) == res.ticks
    q = np.array(log.q)
    n = min(len(gt), len(q))
    assert n >= res.ticks - 1
    # the same generated C, the same controller file, the same quantization: the prosthesis
    # angles agree to rounding over the steps
    assert np.abs(gt[:n, 10:12] - q[:n, 10:12]).max() <= 1e-6


@serial
def test_the_tube_refits_from_the_recording(walked, gait_file, capsys):
    """``tube refit`` of a multi-contact recording: the ground truth's socket force over the
    flat single supports entered from a double support (every one but the run's first, in
    which the run starts), around the gait's F* in the controllers' stance phase.  The
    closed loop walks the gait itself: its socket force stays within a quarter of the
    socket's peak load (874 N) of F* at the same phase (misplaced phases would put it
    hundreds of N off: F* falls from 874 to 552 N over the first third)."""
    from characterization.gait.multicontact_artifact import load_contact_cycle
    from characterization.tube.contact_playback import gait_nominal
    from hp_model.force_tube import load_tube

    _, rec = walked
    out = gait_file.parent / "refit.json"
    assert hpcosim(["tube", "refit", str(rec), "--gait", str(gait_file), "--out", str(out),
                    "--degree", "1"]) in (0, 1)
    assert "'steps': 4" in " ".join(capsys.readouterr().out.split())  # 5 stances, 4 entered
    tube = load_tube(out, load_contact_cycle(gait_file).hash)
    assert tube.source["domain_graph"] == "multicontact" and tube.n_steps == 4
    cert = tube.credibility["certificate"]
    assert cert["inside"] and cert["optimal"]
    nominal = gait_nominal(load_contact_cycle(gait_file))
    s = np.linspace(tube.tau_lo, tube.tau_hi, 50)
    peak = np.abs(nominal.socket).max(axis=0)
    star = np.column_stack([np.interp(s, nominal.phase, nominal.socket[:, c])
                            for c in range(3)])
    assert np.all(np.abs(tube.nominal_force(s) - star) < 0.02 * peak)  # the same F*
    lo, hi = tube.delta_bounds(s)
    assert np.all(np.maximum(np.abs(lo), np.abs(hi)) < 0.25 * peak[1])
    assert hpcosim(["tube", "refit", str(rec), "--gait", str(gait_file), "--out",
                    str(gait_file.parent / "x.json"), "--model-error"]) == 2


@serial
def test_the_papers_baselines_run_the_multicontact_cosimulation(gait_file):
    """``--controller pd`` and ``passive`` on a multi-contact gait: the controller process
    runs the file of that law (docs/sweeps.md: on this cycle `pd` walks two steps, `passive`
    falls in its first swing, as in process), recorded and replayed with no difference."""
    for law, walks in (("pd", True), ("passive", False)):
        rec = gait_file.parent / f"{law}.mcap"
        res = run_cosim(CosimConfig(controller=law, gait=gait_file, tube=None, steps=2,
                                    record=rec))
        assert not res.faulted and res.fell != walks and res.missed == 0, (law, res)
        assert replay(rec).max_torque_diff == 0.0


@pytest.mark.parametrize("extra, words", [
    (["--tube", "tests/data/controller/tube_demo_v2.json"], "refit the tube"),
    (["--subject", "hp_model/configs/subject_example.toml"], "carries its subject"),
    (["--controller", "clfqp-paper"], "a multi-contact gait runs clfqp, phase-pd, pd, passive")])
def test_what_a_multicontact_run_refuses(gait_file, capsys, extra, words):
    args = ["run", "--gait", str(gait_file), "--steps", "1", *extra]
    if "--controller" not in extra:
        args += ["--controller", "clfqp"]
    assert hpcosim(args) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1
