"""The walker animation (``orchestrator.experiments.animation.walker_gif``): one frame per
1/fps s of the run, the figure following the hip, the stick figure where the model's frames are."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from orchestrator.experiments.animation import walker_gif
from orchestrator.experiments.scenarios import NOMINAL, Scenario, run_scenario
from tests.controller_support import tube_about_nominal


def test_walker_gif_of_a_short_run(model, template_gait):
    tube = tube_about_nominal(template_gait, (40.0, 60.0, 8.0))
    r = run_scenario(model, template_gait, tube, Scenario("phase-pd", NOMINAL, 2))
    assert r.q is not None and r.q.shape == (r.t.size, model.nq)
    data = walker_gif(model, r.t, r.q, r.domain, r.tau, r.socket_force, fps=20.0,
                      title="test")
    with Image.open(io.BytesIO(data)) as im:
        n = im.n_frames
        size = im.size
        im.seek(0)
        first = np.asarray(im.convert("RGB"))
        im.seek(n - 1)
        last = np.asarray(im.convert("RGB"))
    assert n == int(np.floor((r.t[-1] - r.t[0]) * 20.0 + 1e-9)) + 1
    assert size == (384, 256)
    # the figure is drawn (human blue, prosthesis orange pixels) and changes over the run
    for img in (first, last):
        assert np.any((img[..., 2] > 150) & (img[..., 0] < 80))  # blue
        assert np.any((img[..., 0] > 200) & (img[..., 1] > 90) & (img[..., 2] < 60))  # orange
    assert np.abs(first.astype(int) - last.astype(int)).sum() > 0
    with pytest.raises(ValueError, match="empty run"):
        walker_gif(model, r.t[:0], r.q[:0], r.domain[:0], r.tau[:0])



def test_hpcosim_animate_a_recording(model, template_gait, tmp_path, capsys):
    """``hpcosim animate RUN.mcap``: the walker of a recording's /ground_truth channel (here
    written by the recorder from an in-process run, as the co-simulation writes it, with
    the Foxglove channels /walker/* beside it)."""
    from bus_schemas.mcap_schemas import Recorder
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
