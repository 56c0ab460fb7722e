"""The QA report's numbers rounded to their meaning (issue 40): a C3D with the lab's gait
events, whose times the file holds as float32, made the report print differences like
"3.094718933104872 frames"; residuals, offsets and angles carried digits no marker has."""

from __future__ import annotations

import json
import re

import pytest

from characterization.mocap.c3d_io import read_c3d, write_c3d
from characterization.mocap.mapping import default_mapping
from characterization.mocap.pipeline import process_take
from characterization.mocap.report import qa_markdown, qa_summary, render_report
from characterization.mocap.synthetic_subject import SynthOptions, synthesize
from characterization.mocap.take import LabEvent
from tests.report_numbers import digits_beyond_meaning


@pytest.fixture(scope="module")
def with_events(model, coef, tmp_path_factory):
    """The synthetic subject's C3D with its true contact events as the lab's EVENT group
    (float32 times), read back and processed."""
    s = synthesize(model, SynthOptions(n_strides=4, seed=5))
    ev = [LabEvent(label, side, float(t)) for key, label, side in (
        ("h_land", "Foot Strike", "Left"), ("h_lift", "Foot Off", "Left"),
        ("p_land", "Foot Strike", "Right"), ("p_lift", "Foot Off", "Right"))
        for t in s.truth[key]]
    path = tmp_path_factory.mktemp("events") / "events.c3d"
    write_c3d(path, s.take_c3d.replace(events=tuple(sorted(ev, key=lambda e: e.time))))
    return process_take(read_c3d(path), default_mapping(), coef)


def test_lab_event_differences_are_tenths_of_a_frame(with_events) -> None:
    p = with_events
    diffs = [d for kinds in p.lab_events.values() for v in kinds.values()
             for d in v["diff_frames"] if d is not None]
    assert len(diffs) >= 16
    assert all(d == round(d, 1) for d in diffs)
    assert any(d != round(d) for d in diffs)  # not integers: float32 times, 0.1 frame kept
    md = qa_markdown(qa_summary(p))
    rows = re.findall(r"^\| (human|prosthesis) \| (touchdown|liftoff) \| \d+ \| (\S+) \| (\S+) \|$",
                      md, re.M)
    assert len(rows) == 4
    assert all(re.fullmatch(r"\d+\.\d", x) for r in rows for x in r[2:])
    notes = [n for n in [*p.notes, *p.warnings] if "lab events" in n]
    assert len(notes) == 4
    assert all(re.search(r"within \d+\.\d frames \(median \d+\.\d\)", n) for n in notes)


def test_the_report_has_no_number_beyond_its_meaning(with_events, tmp_path) -> None:
    files = render_report(tmp_path / "steps.npz", with_events, with_figures=False)
    md = next(v for k, v in files.items() if k.name.endswith(".qa.md")).decode()
    assert digits_beyond_meaning(md) == []
    summary = json.loads(next(v for k, v in files.items() if k.name.endswith(".qa.json")))
    for joint in summary["joints"].values():
        assert joint["residual_mm"] == round(joint["residual_mm"], 1)
        assert all(x == round(x, 4) for x in joint["lambda_proximal_m"])
    for st in summary["step_intervals"]:
        assert st["t_start_s"] == round(st["t_start_s"], 3)


def test_the_checker_finds_what_the_old_report_printed() -> None:
    """The regex check itself: the old report's numbers are found, the rounded ones pass."""
    old = ("| human | liftoff | 5 | 3.094718933104872 | 2.6401977539042036 |",
           "- joint 'hip_l': fitted on 205 frames, residual 8.91 mm RMS, rotation SD 15.0 deg",
           "- calibration (pitch offsets subtracted, deg): hat +4.36, l_thigh +4.22",
           "- found from the markers within 1.0000076293946734 frames (median 1.0)")
    header = ("| foot | event | in the file | max abs | median abs |", "|---|---|---|---|---|")
    assert len(digits_beyond_meaning("\n".join([*header, old[0]]))) == 2
    for line in old[1:]:
        assert digits_beyond_meaning(line), line
    new = ("| human | liftoff | 5 | 3.1 | 2.6 |", "residual 8.9 mm RMS, rotation SD 15.0 deg",
           "- calibration (pitch offsets subtracted, deg): hat +4.4, l_thigh +4.2",
           "times 2.180-2.730 s, walking direction [-0.020, -1.000, 0.000]")
    assert digits_beyond_meaning("\n".join([*header, *new])) == []
