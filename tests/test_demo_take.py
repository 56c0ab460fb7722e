"""``hpcosim demo --take``: the pipeline on a lab's take (openOFM's walk, tests/data) with
the person's multi-contact gait, each stage the verb a user would type: mocap process, gait
fit --domains multicontact, tube fit, experiments, fmu build, run (the co-simulation,
recorded),
replay; report.md sums it up.  The gait is the person's (every criterion of the comparison
holds) and every stage holds but the tube: the take's two prosthesis single supports
certify nothing, so the demo ends with the tube fit's negative verdict (exit 1) after every
stage ran."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from orchestrator.cli import main as hpcosim

TAKE = Path(__file__).parent / "data" / "openofm-walk"


@pytest.mark.slow
@pytest.mark.serial  # its co-simulation's replies are judged against wall-clock deadlines
def test_demo_on_a_real_take(tmp_path, capsys):
    out = tmp_path / "demo"
    rc = hpcosim(["demo", "--take", str(TAKE / "dynamic.c3d"), "--mapping",
                  str(TAKE / "mapping.toml"), "--out", str(out), "--steps", "4",
                  "--draws", "0"])
    captured = capsys.readouterr()
    text = captured.out
    report = (out / "report.md").read_text()
    for stage in ("mocap processing", "gait fit", "experiments", "fmu build",
                  "co-simulation", "replay"):
        assert f"| {stage} |" in report and report.split(f"| {stage} |")[1].split(
            "\n")[0].rstrip().endswith("| holds |"), stage
    gait = json.loads((out / "gait.json").read_text())
    # the person's gait: speed, stride, double supports, every angle within 3 deg RMS
    assert gait["check"]["passed"] and not gait["mismatch_allowed"], gait["check"]
    assert gait["solver"]["angle_limit_stage"].startswith("Solve_Succeeded")
    assert rc == 1 and "tube fit: negative" in captured.err
    # the co-simulation walked its steps and replays with no difference
    assert "completed" in text
    assert "largest torque difference 0 N m" in text
    assert (out / "run.mcap").stat().st_size > 0 and (out / "human.fmu").is_file()
    metrics = json.loads((out / "experiments" / "metrics.json").read_text())
    assert metrics["nominal"]["clfqp"]["walk"]["walks"]
    # the take's two single supports give a tube (exit 1: two certify nothing), and the
    # experiments measure the walks against it
    assert (out / "tube.json").is_file() and "tube" in metrics


def test_a_mapping_without_a_take_is_refused(tmp_path, capsys):
    assert hpcosim(["demo", "--mapping", str(TAKE / "mapping.toml"), "--out",
                    str(tmp_path / "d")]) == 2
    assert "--mapping goes with --take" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.serial  # its co-simulation's replies are judged against wall-clock deadlines
def test_the_main_job_on_the_synthetic_person(tmp_path, capsys):
    """``demo --domains multicontact``: the synthetic person with double support (12 strides
    of the packaged person) through every stage, each holding (exit 0): its fitted gait is
    the person's and `clfqp` walks it, the tube of its 12 single supports holds some of them
    left out (openOFM's two hold none), the co-simulation walks and replays with no
    difference."""
    out = tmp_path / "person"
    rc = hpcosim(["demo", "--domains", "multicontact", "--out", str(out), "--steps", "6",
                  "--draws", "0"])
    text = capsys.readouterr().out
    assert rc == 0, text[-2000:]
    report = (out / "report.md").read_text()
    for stage in ("synthetic person", "mocap processing", "gait fit", "tube fit",
                  "experiments", "fmu build", "co-simulation", "replay"):
        assert f"| {stage} |" in report and f"| {stage} | `" in report
    gait = json.loads((out / "gait.json").read_text())
    assert gait["check"]["passed"] and not gait["mismatch_allowed"]
    assert [r["gait"] for r in gait["check"]["rows"] if r["criterion"].startswith("double")]
    tube = json.loads((out / "tube.json").read_text())
    assert tube["n_steps"] >= 10 and tube["credibility"]["leave_one_out"]["coverage"] > 0
    metrics = json.loads((out / "experiments" / "metrics.json").read_text())
    assert metrics["nominal"]["clfqp"]["walk"]["walks"]
    # the baseline too: with the struck heel unloaded at the strike (touchdown_load 0) the
    # loop's heel started at about -60 N and contact-pd fell at its 2nd step
    assert metrics["nominal"]["contact-pd"]["walk"]["walks"]
    assert "largest torque difference 0 N m" in text


def test_the_paper_graph_and_a_take_do_not_go_together(tmp_path, capsys):
    assert hpcosim(["demo", "--take", str(TAKE / "dynamic.c3d"), "--domains", "paper",
                    "--out", str(tmp_path / "d")]) == 2
    assert "--take runs the person's multi-contact gait" in capsys.readouterr().err


def test_the_demo_stops_after_a_gait_that_does_not_walk(tmp_path):
    """A gait file whose cycle does not walk even under the held oracle (gaitalytics' take
    before the landing ankle's bound, docs/gait-design.md): the later stages are not run,
    and the demo says why; a gait that walks, or a file from before the reference walk was
    stored, goes on."""
    import json

    from orchestrator.cli.experiments import _no_walk

    gait = tmp_path / "gait.json"
    fall = "t = 0.452 s, pns, tau = -0.323: landed on heel or toe (foot pitch -0.175 rad)"
    gait.write_text(json.dumps({"closed_loop_reference": {"walks": False, "fall": fall}}))
    why = _no_walk(gait)
    assert fall in why and "held oracle" in why
    gait.write_text(json.dumps({"closed_loop_reference": {"walks": True, "fall": None}}))
    assert _no_walk(gait) == ""
    gait.write_text(json.dumps({}))
    assert _no_walk(gait) == ""
