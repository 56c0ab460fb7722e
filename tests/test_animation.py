"""The walker animation (``orchestrator.experiments.animation.walker_gif``): one frame per
1/fps s of the run, the figure following the hip, the stick figure where the model's frames are."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from hp_model.domains import Domain
from orchestrator.experiments.animation import (
    ARROW_COLOUR,
    MAX_ARROW,
    WalkSeries,
    arrow_vector,
    walker_gif,
)
from orchestrator.experiments.scenarios import NOMINAL, Perturbation, Scenario, run_scenario
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


def test_the_speed_is_shown_beside_the_command(model, template_gait):
    """A walk along a commanded speed (a person walking a gait library): each frame's status
    line shows the hip's mean forward speed over the last second, (x_i - x_j) / (t_i - t_j)
    with t_j one second before, beside the speed commanded; a walk without a command shows
    no speed."""
    from matplotlib import pyplot as plt

    from orchestrator.experiments.animation import SPEED_WINDOW, walker_scene

    tube = tube_about_nominal(template_gait, (40.0, 60.0, 8.0))
    r = run_scenario(model, template_gait, tube, Scenario("phase-pd", NOMINAL, 8))
    assert r.q is not None and r.t[-1] > 2 * SPEED_WINDOW
    command = 0.5 + 0.1 * r.t
    fig, scene = walker_scene(model, WalkSeries(r.t, r.q, r.domain, r.tau, command=command),
                              fps=5.0)
    k = len(scene.idx) - 1
    scene.draw(k)
    i = scene.idx[k]
    j = int(np.searchsorted(r.t, r.t[i] - SPEED_WINDOW))
    walked = (r.q[i, 0] - r.q[j, 0]) / (r.t[i] - r.t[j])
    assert 0.1 < walked < 2.0  # it walks forward
    text = scene.label.get_text()
    assert f"speed {walked:.2f} m/s over the last 1 s, commanded {command[i]:.2f}" in text
    plt.close(fig)
    fig, scene = walker_scene(model, WalkSeries(r.t, r.q, r.domain, r.tau), fps=5.0)
    scene.draw(k)
    assert "speed" not in scene.label.get_text()
    plt.close(fig)


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
    # the recorded walk moves: the prosthesis's pixels differ 0.25 s apart (template gait:
    # a step about 0.3 s)
    gif = _gif_frames(out.read_bytes())
    assert (_orange(gif[0]) ^ _orange(gif[5])).sum() > 200
    assert (_orange(gif[5]) ^ _orange(gif[10])).sum() > 200
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


# -- the walker moves (issue 40): what each frame draws, from the artists' own data --------

DEMO = Path(__file__).resolve().parent / "data" / "controller"
FPS = 20.0


@pytest.fixture(scope="module")
def demo(model):
    """The demo subject's committed gait and force tube (tests/data/controller)."""
    from hp_model.force_tube import load_tube
    from hp_model.gait_artifact import load_gait

    gait = load_gait(DEMO / "gait_demo.json", model.parameter_hash())
    return gait, load_tube(DEMO / "tube_demo.json", gait.hash())


def _drawn(model, r, fps: float = FPS):
    """Every frame of the walker's scene of run ``r`` drawn as the GIF draws it: per frame
    the log row, the drawn points of every line (x, z; hip first in the first chain), the
    view's centre and whether the fall's banner is shown with its text."""
    from matplotlib import pyplot as plt

    from orchestrator.experiments.animation import walker_scene

    walk = WalkSeries(r.t, r.q, r.domain, r.tau, r.socket_force, r.fall)
    fig, scene = walker_scene(model, walk, fps=fps)
    frames = []
    for k in range(len(scene.idx)):
        scene.draw(k)
        pts = np.concatenate([np.column_stack(ln.get_data()) for ln in scene.lines])
        lo, hi = scene.ax.get_xlim()
        frames.append((int(scene.idx[k]), pts, 0.5 * (lo + hi), scene.banner.get_visible(),
                       scene.banner.get_text()))
    plt.close(fig)
    return frames


def _orange(img: np.ndarray) -> np.ndarray:
    """The prosthesis's pixels (#e07b00) of an RGB frame."""
    return (img[..., 0] > 200) & (img[..., 1] > 90) & (img[..., 1] < 160) & (img[..., 2] < 60)


def _gif_frames(data: bytes, durations: list[int] | None = None) -> list[np.ndarray]:
    """The RGB frames of a GIF (Pillow merges equal consecutive frames into one of the
    summed duration); their durations (ms) appended to ``durations`` if given."""
    with Image.open(io.BytesIO(data)) as im:
        out = []
        for k in range(im.n_frames):
            im.seek(k)
            out.append(np.asarray(im.convert("RGB")).astype(int))
            if durations is not None:
                durations.append(int(im.info["duration"]))
    return out


def test_the_walker_walks(model, demo):
    """Two steps of clfqp on the demo gait (the experiments' scenario path): the drawn hip
    is the run's hip (x_B, z_B of each frame's row, so it advances as the walker does, about
    0.8 m here), the view follows it, and the legs' drawn pose (relative to the hip) differs
    between any two frames a quarter stride apart, in the artists' data and in the GIF's
    pixels.  (Each frame's pose was the run's last when the frames were stacked from the
    compiled function's reused output buffer.)"""
    gait, tube = demo
    r = run_scenario(model, gait, tube, Scenario("clfqp", NOMINAL, 2))
    assert r.success and r.steps == 2
    frames = _drawn(model, r)
    ix, iz = model.coord_names.index("x_B"), model.coord_names.index("z_B")
    rows = np.array([f[0] for f in frames])
    hip = np.array([f[1][0] for f in frames])  # the first chain starts at the hip
    np.testing.assert_allclose(hip[:, 0], r.q[rows, ix], atol=1e-12)
    np.testing.assert_allclose(hip[:, 1], r.q[rows, iz], atol=1e-12)
    np.testing.assert_allclose([f[2] for f in frames], hip[:, 0], atol=1e-12)  # the view
    assert np.all(np.diff(hip[:, 0]) > 0.0)  # forward in every frame
    assert hip[-1, 0] - hip[0, 0] > 0.7
    # a stride: the time from the start (a ps touchdown) to the second touchdown
    stride = r.t[np.flatnonzero(np.diff(r.domain))[1] + 1] - r.t[0]
    quarter = round(stride / 4 * FPS)
    assert quarter >= 4
    legs = np.array([f[1] - f[1][0] for f in frames])  # every drawn point from the hip
    moved = [float(np.abs(legs[k + quarter] - legs[k]).max())
             for k in range(len(frames) - quarter)]
    assert min(moved) > 0.05, moved
    # the GIF itself: the prosthesis's pixels move between frames a quarter stride apart
    gif = _gif_frames(walker_gif(model, WalkSeries(r.t, r.q, r.domain, r.tau, r.socket_force),
                                 fps=FPS))
    assert len(gif) == len(frames)
    changed = [int((_orange(gif[k]) ^ _orange(gif[k + quarter])).sum())
               for k in range(0, len(gif) - quarter, quarter)]
    assert min(changed) > 200, changed


def test_a_fall_is_shown(model, demo):
    """A run that falls (robust-passive under a 0.05 rad human perturbation falls at its
    second step's start: the human's stance foot leaves the friction cone) ends on its
    last pose held ``FALL_HOLD`` s with a banner naming the fall: never before that row.
    (In this model a fall is a detected event, the hip still about at its walking height:
    the banner, not the pose, shows it.)"""
    from orchestrator.experiments.animation import FALL_COLOUR, FALL_HOLD

    gait, tube = demo
    r = run_scenario(model, gait, tube, Scenario("passive", Perturbation("p", 0.05, 1), 2))
    assert r.fall is not None and r.steps == 1
    frames = _drawn(model, r)
    last = r.t.size - 1
    held = [f for f in frames if f[0] == last]
    assert len(held) >= round(FALL_HOLD * FPS)
    assert all(f[3] for f in held) and not any(f[3] for f in frames if f[0] != last)
    text = held[0][4]
    assert text.startswith(f"FELL at t = {r.fall.t:.3f} s ({r.fall.domain}")
    assert " ".join(text.split("\n")[1:]) == r.fall.detail()
    for f in held:
        np.testing.assert_array_equal(f[1], held[0][1])  # the walker stays where it fell
    ms: list[int] = []
    gif = _gif_frames(walker_gif(model, WalkSeries(r.t, r.q, r.domain, r.tau, r.socket_force,
                                                   r.fall), fps=FPS), ms)
    assert sum(ms) == len(frames) * 1000 / FPS  # the held frames: one GIF frame
    assert ms[-1] >= FALL_HOLD * 1000
    rgb = np.array([int(FALL_COLOUR[i:i + 2], 16) for i in (1, 3, 5)])

    def banner(img: np.ndarray) -> int:
        return int((np.abs(img - rgb).max(axis=-1) < 40).sum())

    assert banner(gif[0]) == 0 and banner(gif[-1]) > 300


def test_a_recorded_fall(tmp_path):
    """A co-simulation recording's fall (its ``summary`` metadata, as ``hpcosim run``
    writes it: :meth:`CosimResult.to_dict` through the recorder) is the fall the animation
    shows at its last /ground_truth row; a run that did not fall has none."""
    from bus_schemas.recording.recorder import Recorder
    from hp_model.falls import FallReason
    from orchestrator.cosim.recording import read_recording
    from orchestrator.cosim.result import CosimResult
    from orchestrator.experiments.animation import _recorded_fall

    for fell in (True, False):
        path = tmp_path / f"run-{fell}.mcap"
        res = CosimResult()
        if fell:
            res.fell, res.fall_code = True, int(FallReason.FRICTION_CONE)
        with Recorder(path) as rec:
            rec.add_metadata("summary", res.to_dict())
        summary = read_recording(path, messages=False).metadata["summary"]
        fall = _recorded_fall(summary, 1.25, 1, 0.4)
        if not fell:
            assert fall is None
            continue
        assert fall is not None and fall.reason is FallReason.FRICTION_CONE
        assert (fall.t, fall.domain, fall.tau) == (1.25, Domain.PNS, 0.4)
