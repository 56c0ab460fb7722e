"""A session, not a single take (issue 37): `hpcosim mocap process A B C` pools the steps of
a session's takes, reports every take, and states what a lab must record; the strides and
double supports of the real takes, the gait's targets.

Real files only: openOFM's Vicon walk (``dynamic.c3d``) and the lab's processed copy of the
same trial (``dynamic_processed.c3d``, the same markers: two takes of one session at 100
Hz), its static trial (no walking: a take that gives nothing), and the GATK treadmill take
with its force plate.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from characterization.mocap.domain_segmentation import domain_segments
from characterization.mocap.foot_contact import foot_contact, symmetric_double_support
from characterization.mocap.session import TUBE_MIN_STEPS, process_session
from characterization.mocap.step_segmentation import TAKE_GAP, take_spans
from characterization.mocap.steps_artifact import load_steps
from characterization.mocap.take import MocapError
from orchestrator.cli import main

DATA = Path(__file__).parent / "data"
OFM = DATA / "openofm-walk"


@pytest.fixture(scope="module")
def single(tmp_path_factory):
    out = tmp_path_factory.mktemp("one") / "steps.npz"
    return process_session([OFM / "dynamic.c3d"], out, mapping=OFM / "mapping.toml",
                           with_figures=False)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    out = tmp_path_factory.mktemp("session") / "steps.npz"
    return process_session([OFM / "dynamic.c3d", OFM / "static.c3d",
                            OFM / "dynamic_processed.c3d"], out,
                           mapping=OFM / "mapping.toml", with_figures=False)


def test_single_take_events_are_the_walks(single) -> None:
    """openOFM's walk: 2.46 m in 2.04 s (about 1.2 m/s); the prosthesis-side (right) foot's
    stride 28-140 (1.12 s at 100 Hz), 1.21 m/s over the ground, double supports of 140 and
    150 ms (12-13 % of the stride each: Perry's 10-12 %), in the QA report as well."""
    (t,) = single.takes
    (s,) = t.strides
    assert (s.start, s.end) == (28, 140)
    assert s.time == pytest.approx(1.12, abs=0.005)
    assert s.speed == pytest.approx(1.2, abs=0.06)
    assert s.double_support["human"] == pytest.approx(0.14, abs=0.02)
    assert s.double_support["prosthesis"] == pytest.approx(0.15, abs=0.02)
    qa = json.loads(next(p for p in single.report_paths if p.suffix == ".json").read_text())
    assert qa["strides"][0]["double_support_s"] == {"human": 0.14, "prosthesis": 0.15}
    assert [d["seconds"] for d in qa["double_supports"]] == [0.15, 0.14, 0.13]
    # one take with 2 ps steps: the tube's need is a warning naming how to get more
    assert any(f"`tube fit` needs at least {TUBE_MIN_STEPS} ps steps" in w
               and "this session has 2" in w and "mocap process A B C" in w
               for w in single.warnings)


def test_takes_pooled_without_a_step_across_two(session, single) -> None:
    """Two walking takes and a static trial: the static trial is a warning naming it and
    why; the steps of both walks are pooled, each within its take (a pause of TAKE_GAP
    between them in time), the touchdown segments too; with 4 ps steps the tube's need is
    met, no warning."""
    assert [t.processed is None for t in session.takes] == [False, True, False]
    assert "static.c3d: not walking: no periodic foot contact" in session.warnings[0]
    a, one = session.artifact, single.artifact
    spans = take_spans(a.time)
    assert spans == [(0, 205), (205, 410)]
    assert a.time[205] - a.time[204] == pytest.approx(TAKE_GAP)
    assert a.n_steps == 2 * one.n_steps
    for i in range(a.n_steps):
        k = 0 if a.step_start[i] < 205 else 1
        assert spans[k][0] <= a.step_start[i] <= a.step_end[i] < spans[k][1]
    segs, segs1 = domain_segments(a), domain_segments(one)
    assert len(segs) == 2 * len(segs1)
    assert all(s.end < 205 or s.start >= 205 for s in segs)
    assert not any("tube fit" in w for w in session.warnings)
    saved = load_steps(session.steps_path)
    assert saved.n_steps == a.n_steps and " + " in saved.source
    qa = json.loads(next(p for p in session.report_paths if p.suffix == ".json").read_text())
    assert [t["error"] is None for t in qa["session"]["takes"]] == [True, False, True]
    assert len(qa["takes"]) == 3 and qa["takes"][0]["strides"][0]["start"] == 28


def test_no_take_with_a_step_is_one_line_naming_each(tmp_path) -> None:
    with pytest.raises(MocapError, match=r"no take of the session gives a step: \S*static\.c3d: "
                       r"no step \(not walking: no periodic foot contact") as e:
        process_session([OFM / "static.c3d"], tmp_path / "s.npz",
                        mapping=OFM / "mapping.toml", with_figures=False)
    assert "\n" not in str(e.value)
    assert not list(tmp_path.iterdir())


def test_cli_pools_takes_and_prints_each(tmp_path, capsys) -> None:
    out = tmp_path / "steps.json"
    assert main(["mocap", "process", str(OFM / "dynamic.c3d"), str(OFM / "static.c3d"),
                 str(OFM / "dynamic_processed.c3d"), "--mapping", str(OFM / "mapping.toml"),
                 "--out", str(out), "--no-figures"]) == 0
    text = capsys.readouterr().out
    assert text.count("1 full stride(s), steps kept 2 ps + 1 pns") == 2
    assert "static.c3d: no step (not walking" in text
    assert "prosthesis lands 28-43 (150 ms)" in text
    assert load_steps(out).n_steps == 6
    assert main(["mocap", "process", str(OFM / "static.c3d"), "--mapping",
                 str(OFM / "mapping.toml"), "--out", str(tmp_path / "x.npz")]) != 0
    assert "no take of the session gives a step" in capsys.readouterr().err


def test_gatk_double_support_against_its_force_plate() -> None:
    """The GATK treadmill take records one side (right heel and 5th metatarsal, force plate
    FP2 under it): each double support estimated as its stance less half its stride (the
    other foot mirroring it), from the markers and from the plate (vertical force above 20
    N).  Measured: 16 and 14.5 frames from the markers, 18 and 17.5 from the plate: the
    markers' lift-offs are 2-3 frames early (test_mocap_gatk), so within 3 frames."""
    raw = np.genfromtxt(DATA / "gatk-walking" / "rawdata.txt", skip_header=1)
    t = raw[:, 0]
    c = foot_contact(raw[:, 9:11], raw[:, 11:13], t)
    on = raw[:, 14] > 20.0
    d = np.diff(on.astype(int))
    from characterization.mocap.foot_contact import FootContact
    plate = FootContact(on, tuple(np.flatnonzero(d == 1) + 1), tuple(np.flatnonzero(d == -1) + 1),
                        0.0)
    ds_m, ds_p = symmetric_double_support(c, 100.0), symmetric_double_support(plate, 100.0)
    assert len(ds_m) == len(ds_p) == 2
    assert np.allclose(ds_p, [0.18, 0.175], atol=0.006)
    assert np.max(np.abs(np.subtract(ds_m, ds_p))) <= 0.03 + 1e-9
