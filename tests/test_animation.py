"""The walker animation (``orchestrator.experiments.animation.walker_gif``): one frame per
1/fps s of the run, the figure following the hip, the stick figure where the model's frames are."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from orchestrator.experiments.animation import (
    ARROW_COLOUR,
    MAX_ARROW,
    WalkSeries,
    arrow_vector,
    walker_gif,
)
from orchestrator.experiments.scenarios import NOMINAL, Scenario, run_scenario
from tests.controller_support import tube_about_nominal


def test_walker_gif_of_a_short_run(model, template_gait):
    tube = tube_about_nominal(template_gait, (40.0, 60.0, 8.0))
    r = run_scenario(model, template_gait, tube, Scenario("phase-pd", NOMINAL, 2))
    assert r.q is not None and r.q.shape == (r.t.size, model.nq)
    data = walker_gif(model, WalkSeries(r.t, r.q, r.domain, r.tau, r.socket_force), fps=20.0,
                      title="test")
    with Image.open(io.BytesIO(data)) as im:
        n = im.n_frames
        size = im.size
        im.seek(0)
        first = np.asarray(im.convert("RGB"))
        im.seek(n - 1)
        last = np.asarray(im.convert("RGB"))
    assert n == int(np.floor((r.t[-1] - r.t[0]) * 20.0 + 1e-9)) + 1
    assert size == (600, 400)
    # the figure is drawn (human blue, prosthesis orange pixels) and changes over the run
    for img in (first, last):
        assert np.any((img[..., 2] > 150) & (img[..., 0] < 80))  # blue
        assert np.any((img[..., 0] > 200) & (img[..., 1] > 90) & (img[..., 2] < 60))  # orange
    assert np.abs(first.astype(int) - last.astype(int)).sum() > 0
    with pytest.raises(ValueError, match="empty run"):
        walker_gif(model, WalkSeries(r.t[:0], r.q[:0], r.domain[:0], r.tau[:0]))


def _frame(data: bytes) -> np.ndarray:
    with Image.open(io.BytesIO(data)) as im:
        return np.asarray(im.convert("RGB")).astype(int)


def test_socket_force_arrow_drawn_at_peak_load(model, template_gait):
    """The arrow stays in the frame when the socket force is large (an annotation whose tip
    leaves the axes is not drawn by default): the stance frame of the run's largest |F_s|,
    the force multiplied by 5, one frame rendered with and without the force."""
    tube = tube_about_nominal(template_gait, (40.0, 60.0, 8.0))
    r = run_scenario(model, template_gait, tube, Scenario("phase-pd", NOMINAL, 1))
    assert r.socket_force is not None
    mag = np.where(r.domain == 0, np.hypot(r.socket_force[:, 0], r.socket_force[:, 1]), 0.0)
    k = int(np.argmax(mag))
    assert r.domain[k] == 0 and mag[k] > 300.0
    force = 5.0 * r.socket_force[k:k + 1]
    assert np.hypot(*arrow_vector(force[0, 0], force[0, 1])) == pytest.approx(MAX_ARROW)
    args = (r.t[k:k + 1], r.q[k:k + 1], r.domain[k:k + 1], r.tau[k:k + 1])
    with_force = _frame(walker_gif(model, WalkSeries(*args, force)))
    without = _frame(walker_gif(model, WalkSeries(*args)))
    rgb = np.array([int(ARROW_COLOUR[i:i + 2], 16) for i in (1, 3, 5)])

    def arrow_pixels(img: np.ndarray) -> int:
        return int((np.abs(img - rgb).max(axis=-1) < 40).sum())

    assert arrow_pixels(without) == 0
    assert arrow_pixels(with_force) > 150  # the shaft, the head and the magnitude's label


def test_hpcosim_animate_a_recording(model, template_gait, tmp_path, capsys):
    """``hpcosim animate RUN.mcap``: the walker of a recording's /ground_truth channel (here
    written by the recorder from an in-process run, as the co-simulation writes it, with
    the Foxglove channels /walker/* beside it)."""
    from bus_schemas.recording.recorder import Recorder
    from orchestrator.cli import main
    from orchestrator.loop import ControllerLink, SimulatorPlant, run_loop
    from orchestrator.loop.foxglove import WalkerFoxglove
    from orchestrator.loop.recorder import GroundTruthRecorder
    from prosthesis_controller import make_controller
    from tests.fmu_support import simulator, start_state

    tube = tube_about_nominal(template_gait, (40.0, 60.0, 8.0))
    plant = SimulatorPlant(simulator(model, template_gait), *start_state(template_gait))
    link = ControllerLink(make_controller("phase-pd", template_gait, tube, model))
    path = tmp_path / "run.mcap"
    with Recorder(path) as rec:
        rec.register_all()
        walker = WalkerFoxglove(model, template_gait, tube)
        log = run_loop(plant, link, steps=2,
                       recorder=GroundTruthRecorder(rec, walker=walker))
    assert log.steps == 2 and log.fall is None
    assert rec.message_count > 1.25 * log.periods  # /ground_truth and every 10 ms /walker/*
    out = tmp_path / "walker.gif"
    assert main(["animate", str(path), "--out", str(out), "--seconds", "0.5", "--fps",
                 "20"]) == 0
    with Image.open(out) as im:
        assert im.n_frames == 11
    empty = tmp_path / "empty.mcap"
    with Recorder(empty) as rec:
        rec.register_all()
    capsys.readouterr()
    assert main(["animate", str(empty), "--out", str(tmp_path / "e.gif")]) == 2
    assert "0 /ground_truth messages" in capsys.readouterr().err
    assert not (tmp_path / "e.gif").exists()


def test_parse_scenario(model):
    """The experiments' scenarios by name (``hpcosim animate SCENARIO``)."""
    from orchestrator.experiments.paper import parse_scenario

    sc = parse_scenario(model, "phase-pd/human:0.01:2+offset", 1)
    assert (sc.controller, sc.perturbation.amplitude, sc.perturbation.seed) == (
        "phase-pd", 0.01, 2)
    assert sc.initial_offset[0] == pytest.approx(0.02) and sc.steps == 1
    sc = parse_scenario(model, "clfqp", 4)
    assert (sc.perturbation.amplitude, sc.initial_offset, sc.steps) == (0.0, (0.0, 0.0), 4)
    assert parse_scenario(model, "oracle/nominal", 2).controller == "oracle"
    for bad, msg in (("nope/nominal", "controller 'nope'"), ("pd/human:x", "human:AMPLITUDE"),
                     ("pd/drop:3", "human:AMPLITUDE"), ("pd+later", "only suffix"),
                     ("pd/human:0.5", "outside")):
        with pytest.raises(ValueError, match=msg):
            parse_scenario(model, bad, 1)


def test_hpcosim_animate_a_scenario(tmp_path, capsys):
    """``hpcosim animate SCENARIO``: a scenario of the experiments run in process (the demo
    subject's committed gait and tube, 1 step, a perturbed human, the robustness cases'
    offset start); a bad name or a missing --gait is a one-line error, no file written."""
    from orchestrator.cli import main

    data = Path(__file__).resolve().parent / "data" / "controller"
    gt = ["--gait", str(data / "gait_demo.json"), "--tube", str(data / "tube_demo.json")]
    out = tmp_path / "walker.gif"
    assert main(["animate", "phase-pd/human:0.01:2+offset", *gt, "--steps", "1", "--fps",
                 "10", "--seconds", "0.5", "--out", str(out)]) == 0
    with Image.open(out) as im:
        assert im.n_frames == 6
    capsys.readouterr()
    assert main(["animate", "nope/nominal", *gt, "--out", str(tmp_path / "b.gif")]) == 2
    err = capsys.readouterr().err
    assert "controller 'nope'" in err and len(err.strip().splitlines()) == 1, err
    assert main(["animate", "pd", "--out", str(tmp_path / "b.gif")]) == 2
    assert "needs --gait and --tube" in capsys.readouterr().err
    assert not (tmp_path / "b.gif").exists()
