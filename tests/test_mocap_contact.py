"""Stance from contact (issue 19): each foot's touchdowns and lift-offs against the
synthetic subject's truth, the lab's events, the failure of the paper's delta_p_hip rule,
and the "take contains walking" check.

Tolerance (frames) of the marker rule on the synthetic subject, derived per take: the rule
sees a foot land once its markers move slower than ``speed_tol`` and lift off once they
move faster, so it cannot be closer to the truth's impact than the frames the noise-free
foot (its ankle centre in the truth) spends between rest and ``speed_tol``; plus the
half-width of the 10 Hz zero-phase low-pass, rate / (4 * 10 Hz) = 3 frames at 120 Hz.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat

from characterization.mocap.foot_contact import ContactOptions
from characterization.mocap.mapping import default_mapping
from characterization.mocap.pipeline import process_take
from characterization.mocap.step_segmentation import segment_steps
from characterization.mocap.synthetic_subject import SynthOptions, static_trial, synthesize
from characterization.mocap.take import LabEvent, MocapError
from hp_model.outputs import HipProgress
from tests.contact_helpers import FEET, lag_frames

GATK = Path(__file__).parent / "data" / "gatk-walking"


@pytest.fixture(scope="module", params=["model", "template"])
def synth(model, request):
    """The audit's take: the default 37 strides, seed 0 (``hpcosim mocap synth``)."""
    return synthesize(model, SynthOptions(n_strides=37, seed=0, source=request.param))


@pytest.fixture(scope="module")
def contact(synth, coef):
    return process_take(synth.take, default_mapping(), coef)


def _matched(found: tuple[int, ...], truth_frames: np.ndarray) -> np.ndarray:
    """found - truth (frames) for each truth event, one found event each."""
    f = np.asarray(found, float)
    assert len(f) == len(truth_frames), (len(f), len(truth_frames))
    return f - np.sort(truth_frames)


def test_every_touchdown_and_liftoff_of_the_truth(contact, synth) -> None:
    """Every truth touchdown and lift-off inside the take is found once (no spurious event:
    the audit found 4 + 2 with velocity alone), within the derived tolerance."""
    tr, rate = synth.truth, contact.frame_rate
    n = len(contact.time)
    filt = rate / (4 * ContactOptions().cutoff_hz)
    for foot, (_, land, lift) in FEET.items():
        tol = lag_frames(tr, foot, rate, ContactOptions().speed_tol, 40) + filt
        c = contact.contacts[foot]
        assert c.source == "markers"
        assert c.rolled == ()  # its feet leave the ground flat: no roll over the toes
        for kind, found in ((land, c.touchdowns), (lift, c.liftoffs)):
            true = tr[kind] * rate
            err = _matched(found, true[(true > 1) & (true < n - 2)])
            assert np.max(np.abs(err)) <= tol, (foot, kind, err, tol)
        # the cadence: the truth's mean stride to one frame
        assert c.stride_time == pytest.approx(np.mean(np.diff(tr[land])), abs=1.5 / rate)


def test_contact_is_the_default_and_cuts_no_short_step(contact, synth) -> None:
    """74 steps alternating ps/pns, each from a found touchdown; none cut short (the audit:
    6 of 74 steps of 11-14 frames): every step is longer than half the median."""
    assert contact.segmentation == "contact"
    doms = [s.domain for s in contact.steps]
    assert len(doms) == len(synth.truth["step_domain"]) == 74
    assert all(a != b for a, b in itertools.pairwise(doms))
    lengths = np.array([s.end - s.start + 1 for s in contact.steps])
    assert lengths.min() > 0.5 * np.median(lengths), lengths.min()
    for s in contact.steps:
        foot = "prosthesis" if s.domain == "ps" else "human"
        assert s.start in contact.contacts[foot].touchdowns


def test_paper_rule_puts_swing_into_ps_where_contact_does_not(contact, synth, coef) -> None:
    """The failure mode: delta_p_hip keeps rising after the human foot lands, so every ps
    step of the paper's rule runs into the prosthesis swing (model source: its lift-off is
    the human touchdown); the contact rule's ps steps hold at most the tolerance's frames of
    swing."""
    tr, rate = synth.truth, contact.frame_rate
    n = len(contact.time)
    t = np.arange(n)
    swing = np.zeros(n, bool)
    for lo in tr["p_lift"] * rate:  # from each lift-off to the next touchdown
        nxt = tr["p_land"][tr["p_land"] * rate > lo]
        swing |= (t >= lo) & (t < (nxt[0] * rate if nxt.size else n))
    paper = process_take(synth.take, default_mapping("paper"), coef)
    tol = lag_frames(tr, "prosthesis", rate, ContactOptions().speed_tol, 40) + 3
    paper_swing = [int(swing[s.start:s.end + 1].sum()) for s in paper.steps if s.domain == "ps"]
    contact_swing = [int(swing[s.start:s.end + 1].sum()) for s in contact.steps
                     if s.domain == "ps"]
    if str(tr["source"]) == "model":
        assert min(paper_swing) >= 10, paper_swing  # measured 18-22 frames
    else:  # double support: the paper's ps ends in double support or in the swing
        assert max(paper_swing) > tol, paper_swing
    assert max(contact_swing) <= tol, contact_swing


def test_paper_rule_on_a_real_take_labels_a_whole_swing_ps() -> None:
    """The issue's real-take finding on tests/data/gatk-walking: with the lab's own knee and
    ankle angles (flexion, plantarflexion positive as the model's) the paper's rule makes a
    ps step that lies wholly in the swing (force plate below 20 N), while the markers'
    contact is the plate's stance to a few frames at each event (touchdowns within 2,
    lift-offs within 3: ``test_mocap_gatk.py``)."""
    import hp_model
    from characterization.mocap.foot_contact import foot_contact

    raw = np.genfromtxt(GATK / "rawdata.txt", skip_header=1)
    ref = loadmat(GATK / "refresults.mat")["refresults"]
    on = raw[:, 14] > 20.0
    model = hp_model.load_model()
    delta = HipProgress(*model.hip_progress_coefficients("ps"))(ref[:, 1], ref[:, 2])
    ps = [s for s in segment_steps(delta, 0.05) if s.domain == "ps"]
    assert any(not on[s.start:s.end + 1].any() for s in ps), ps
    c = foot_contact(raw[:, 9:11], raw[:, 11:13], raw[:, 0])
    assert np.sum(c.contact & ~on) <= 2 * len(c.touchdowns)  # touchdowns within 2 frames
    assert np.sum(on & ~c.contact) <= 3 * len(c.liftoffs) + 2 * len(c.touchdowns)


def test_lab_events_give_the_contact(synth, coef) -> None:
    """A file with the lab's gait events (C3D EVENT: "Foot Strike" / "Foot Off") has its
    contact from them; the markers' events are compared with them in the QA data."""
    tr = synth.truth
    take = synth.take
    ev = [LabEvent(lab, side, float(x)) for kind, lab, side in (
        ("p_land", "Foot Strike", "Right"), ("p_lift", "Foot Off", "Right"),
        ("h_land", "Foot Strike", "Left"), ("h_lift", "Foot Off", "Left"))
        for x in tr[kind] if take.time[0] <= x <= take.time[-1]]
    p = process_take(take.replace(events=tuple(sorted(ev, key=lambda e: e.time))),
                     default_mapping(), coef)
    rate = p.frame_rate
    for foot, (_, land, _) in FEET.items():
        c = p.contacts[foot]
        assert c.source == "lab events"
        true = tr[land][(tr[land] >= 0) & (tr[land] <= take.time[-1])] * rate
        np.testing.assert_array_equal(c.touchdowns, np.round(true).astype(int))
        lab = p.lab_events[foot]["touchdown"]
        assert lab["lab_events"] == len(true) and lab["max_abs_frames"] <= 7
    assert any("from the lab's events" in n for n in p.notes)


def test_not_walking_is_a_one_line_error(model, coef, contact) -> None:
    """Standing still for 8 s: no periodic contact; both feet in phase (hopping): the
    touchdowns do not alternate; the hip not progressing over the ground; each a one-line
    error naming the take and the numbers."""
    from characterization.mocap.checks import check_walking

    still = static_trial(model, SynthOptions(seed=0), seconds=8.0).take
    with pytest.raises(MocapError, match=r"synthetic: not walking: no periodic foot contact "
                       r"over 8\.0 s") as e:
        process_take(still, default_mapping(), coef)
    assert "\n" not in str(e.value)
    c, t, x = contact.contacts, contact.time, contact.q[:, 0]
    check_walking("take.c3d", c, x, t)  # the walking itself passes
    hop = {"human": c["prosthesis"], "prosthesis": c["prosthesis"]}
    with pytest.raises(MocapError, match=r"take.c3d: not walking: the feet's touchdowns do "
                       r"not alternate \(\d+ of \d+ follow one of the same foot; the "
                       r"prosthesis lands 0.00 of a"):
        check_walking("take.c3d", hop, x, t)
    with pytest.raises(MocapError, match=r"take.c3d: not walking: the hip moves at 0.0\d m/s "
                       r"over the ground"):
        check_walking("take.c3d", c, np.full_like(x, 3.0), t)


@pytest.fixture(scope="module")
def short_take(model):
    """10 strides of the template subject (quick to make)."""
    return synthesize(model, SynthOptions(n_strides=10, seed=0, source="template")).take


def test_treadmill_walking_passes(short_take, coef) -> None:
    """Walking with the hip held in place (every marker moved back by the hip's mean
    travel: a steady treadmill belt) is walking: the ground moves at minus the walking
    speed, and every step is found."""
    take = short_take
    hip = take.marker("HAT:Marker1")[:, 0]
    ok = np.isfinite(hip)
    travel = np.polyval(np.polyfit(take.time[ok], hip[ok], 1), take.time)  # a steady belt
    mk = {k: v - np.column_stack([travel, 0 * travel, 0 * travel]) for k, v in
          take.markers.items()}
    p = process_take(take.replace(markers=mk, rigid_bodies={}, rigid_body_markers={}),
                     default_mapping(), coef)
    assert len(p.steps) + len(p.dropped) == 20  # dropped: marker gaps (no rigid bodies)
    assert p.contacts["human"].ground_speed < -0.5


def test_frame_time_gaps_are_a_warning(synth, coef) -> None:
    """Frames missing from the export (a gap of 2-10 periods): processed, with one warning
    line in the QA data naming the take and the gap."""
    from characterization.mocap.report import qa_summary

    take = synth.take
    keep = np.ones(take.n_frames, bool)
    keep[1000:1003] = False  # 3 frames missing: a step of 4 periods
    cut = take.replace(time=take.time[keep], markers={k: v[keep] for k, v in take.markers.items()},
                       rigid_bodies={}, rigid_body_markers={})
    p = process_take(cut, default_mapping(), coef)
    w = [x for x in p.warnings if "frame times" in x]
    assert len(w) == 1 and "3 frame(s) missing" in w[0] and "4.0 periods" in w[0]
    assert w[0].startswith("synthetic: ") and "\n" not in w[0]
    assert qa_summary(p)["warnings"] == list(p.warnings)


def test_warnings_are_printed_one_line_each(short_take, tmp_path, capsys) -> None:
    """``hpcosim mocap process`` prints each warning as one line (exit 0), as in the QA
    report: a Motive CSV with 2 frames missing."""
    import json

    from characterization.mocap.motive_csv import write_motive_csv
    from orchestrator.cli import main

    keep = np.ones(short_take.n_frames, bool)
    keep[500:502] = False
    cut = short_take.replace(time=short_take.time[keep],
                             markers={k: v[keep] for k, v in short_take.markers.items()},
                             rigid_bodies={}, rigid_body_markers={})
    write_motive_csv(tmp_path / "gap.csv", cut)
    out = tmp_path / "steps.npz"
    assert main(["mocap", "process", str(tmp_path / "gap.csv"), "--out", str(out),
                 "--no-figures"]) == 0
    lines = [x for x in capsys.readouterr().out.splitlines() if x.startswith("warning: ")]
    assert len(lines) == 1 and "gap.csv: frame times: 1 gap(s), about 2 frame(s) missing " \
        "(largest 3.0 periods between frames 499 and 500" in lines[0], lines
    qa = json.loads((tmp_path / "steps.qa.json").read_text())
    assert qa["warnings"] == [lines[0].removeprefix("warning: ")]
    assert "## Warnings" in (tmp_path / "steps.qa.md").read_text()


def test_a_take_sampled_below_twice_the_contact_cutoff_is_not_filtered() -> None:
    """At 16 Hz the contact low-pass (10 Hz) is above Nyquist: the markers are used as
    sampled (the filter would refuse the cutoff) and the stance is still found."""
    from characterization.mocap.foot_contact import foot_contact

    t = np.arange(0, 6.0, 1 / 16)
    phase = (t / 1.2) % 1.0
    stance = phase < 0.6
    # heel and toe: at rest on the floor in stance, moving forward 1.3 m/s and up in swing
    x = np.cumsum(np.where(stance, 0.0, 1.3 / 16))
    z = np.where(stance, 0.0, 0.08 * np.sin(np.pi * (phase - 0.6) / 0.4))
    heel = np.column_stack([x, z + 0.05])
    toe = np.column_stack([x + 0.2, z + 0.03])
    fc = foot_contact(heel, toe, t, ContactOptions(cutoff_hz=10.0))
    assert fc.contact[stance].mean() > 0.8 and fc.contact[~stance].mean() < 0.3
