"""``hpcosim tube fit``: the happy path and bad input (one-line errors, exit 2, no output)."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from characterization.mocap.steps_artifact import save_steps
from characterization.tube.playback import PlaybackError, TubeOptions, fit_force_tube
from characterization.tube.playback_truth import TruthOptions, synthesize
from hp_model.artifacts import ArtifactError
from hp_model.force_tube import load_tube
from hp_model.gait_artifact import save_gait
from tests.playback_helpers import GAIT, subset_steps

ROOT = Path(__file__).resolve().parents[1]


def hpcosim(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "orchestrator.cli", *args], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def gait(playback_gait):
    return playback_gait


@pytest.fixture(scope="module")
def take(model, gait):
    return synthesize(model, gait, TruthOptions(n_ps=6, sigma=0.03, seed=3))


@pytest.fixture(scope="module")
def steps_file(take, tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("steps") / "steps.npz"
    save_steps(p, take.steps)
    return p


def _one_line_error(r: subprocess.CompletedProcess, *needles: str) -> str:
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hpcosim: error: "), r.stderr
    assert "Traceback" not in r.stderr + r.stdout
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


def test_tube_fit_writes_tube_figure_and_report(steps_file, gait, tmp_path):
    out = tmp_path / "tube.json"
    r = hpcosim("tube", "fit", str(steps_file), "--gait", str(GAIT), "--out", str(out),
                "--steps", "5", "--degree", "2")
    # 5 steps, every one on a bound: no step lies inside the tube fitted without it, a
    # negative result (issue 40: exit 1, one line; the outputs written all the same)
    assert r.returncode == 1, r.stdout + r.stderr
    assert r.stderr.strip().splitlines() == [
        "hpcosim: check failed: force tube: leave-one-out coverage 0 (no step lies inside the "
        "fit without it); written all the same"]
    said = " ".join(r.stdout.split())  # the console wraps long paths at its width
    assert "5 ps steps played back" in said and "wrote" in said
    tube = load_tube(out, gait.hash())
    assert tube.n_steps == 5 and tube.degree == 2
    assert tube.credibility["certificate"]["inside"]
    assert (tmp_path / "tube_fig5.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (tmp_path / "tube.md").read_text()
    assert "# Socket-force tube" in report and "Force-tube credibility" in report
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tube.json", "tube.md",
                                                          "tube_fig5.png"]


def test_no_ps_step_is_a_one_line_error(take, tmp_path):
    pns = [i for i in range(take.steps.n_steps) if take.steps.step_domain[i] == "pns"]
    bad = tmp_path / "pns_only.npz"
    save_steps(bad, subset_steps(take.steps, pns))
    out = tmp_path / "out" / "tube.json"
    out.parent.mkdir()
    _one_line_error(hpcosim("tube", "fit", str(bad), "--gait", str(GAIT), "--out", str(out)),
                    "no prosthesis-stance (ps) step")
    assert not any(out.parent.iterdir())


def test_gait_of_another_model_is_a_one_line_error(steps_file, gait, tmp_path):
    other = tmp_path / "other_gait.json"
    save_gait(other, replace(gait, model_hash="0123456789abcdef"))
    out = tmp_path / "out" / "tube.json"
    out.parent.mkdir()
    _one_line_error(hpcosim("tube", "fit", str(steps_file), "--gait", str(other), "--out",
                            str(out)), "model_hash", "0123456789abcdef")
    assert not any(out.parent.iterdir())


def test_degree_too_high_for_the_steps_is_a_one_line_error(steps_file, tmp_path):
    out = tmp_path / "out" / "tube.json"
    out.parent.mkdir()
    line = _one_line_error(hpcosim("tube", "fit", str(steps_file), "--gait", str(GAIT),
                                   "--out", str(out), "--steps", "3", "--degree", "3"),
                           "degree-3", "degree + 1 = 4")
    assert "3 ps step(s)" in line
    assert not any(out.parent.iterdir())


def test_bad_output_path_is_a_one_line_error(steps_file, tmp_path):
    _one_line_error(hpcosim("tube", "fit", str(steps_file), "--gait", str(GAIT), "--out",
                            str(tmp_path / "missing" / "tube.json")), "no such folder")
    _one_line_error(hpcosim("tube", "fit", str(steps_file), "--gait", str(GAIT), "--out",
                            str(tmp_path / "tube.txt")), ".json")
    assert not any(tmp_path.iterdir())


# ------------------------------------------------------------ the same, as a library

def test_library_errors(model, gait, take):
    pns = [i for i in range(take.steps.n_steps) if take.steps.step_domain[i] == "pns"]
    with pytest.raises(PlaybackError, match=r"no prosthesis-stance \(ps\) step"):
        fit_force_tube(model, gait, subset_steps(take.steps, pns))
    with pytest.raises(ArtifactError, match="model_hash"):
        fit_force_tube(model, replace(gait, model_hash="0123456789abcdef"), take.steps)
    with pytest.raises(PlaybackError, match="need at least degree"):
        fit_force_tube(model, gait, take.steps, TubeOptions(degree=6))
    other = replace(take.steps, hip_coefficients=take.steps.hip_coefficients * 1.1)
    with pytest.raises(PlaybackError, match="hip_coefficients"):
        fit_force_tube(model, gait, other)


def test_steps_without_single_support_are_skipped(model, gait, take):
    s = take.steps
    ps = [i for i in range(s.n_steps) if s.step_domain[i] == "ps"]
    ss_a, ss_b = s.step_ss_start.copy(), s.step_ss_end.copy()
    ss_a[ps[0]] = ss_b[ps[0]] = -1
    res = fit_force_tube(model, gait, replace(s, step_ss_start=ss_a, step_ss_end=ss_b),
                         TubeOptions(degree=2))
    assert ps[0] not in res.used and len(res.used) == len(ps) - 1
    assert res.playback.skipped == [(ps[0], "no single support found by the foot-marker "
                                            "rule")]
    assert np.isfinite(res.tube.lower).all()
