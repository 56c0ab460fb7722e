"""The take's force plates (characterization.mocap.force_plates) on the real files:
GaitAnalysisToolKit's treadmill plate (tests/data/gatk-walking, one plate under the right
foot, 67.2 kg) and OpenSim's subject01 ground reactions (tests/data/opensim-walk,
``subject01_walk1_grf_60hz.mot``: 0-1.95 s of the lab's 600 Hz file at 60 Hz, NOTICE-grf.md).

Physics: over a whole stride of steady walking the feet's mean vertical force is the body
weight (the body's vertical momentum returns); the vertical force is a double hump with peaks
of 1.0-1.3 body weights; the centre of pressure moves forward along the foot.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from characterization.mocap.foot_contact import foot_contact
from characterization.mocap.force_plates import (
    double_supports,
    foot_x_on,
    mean_vertical_force,
    plate_walk,
    read_gatk_plate,
    read_grf_mot,
    stances,
)
from characterization.mocap.sagittal import sagittal_frame
from characterization.mocap.take import MocapError

DATA = Path(__file__).parent / "data"
GATK = DATA / "gatk-walking" / "rawdata.txt"
GRF = DATA / "opensim-walk" / "subject01_walk1_grf_60hz.mot"
G = 9.81


def _touchdowns(ff, level: float = 20.0) -> list[float]:
    up = np.flatnonzero(np.diff((ff.fz > level).astype(int)) == 1) + 1
    return [float(ff.time[i - 1] + (level - ff.fz[i - 1]) / (ff.fz[i] - ff.fz[i - 1])
                  * (ff.time[i] - ff.time[i - 1])) for i in up]


def test_gatk_plate_carries_half_the_body_weight_over_each_stride() -> None:
    """One plate, one foot: over a stride it carries half the body weight (both feet's
    share by symmetry), within 5 %; peaks 1.0-1.3 BW; CoP moves forward along the foot."""
    rec = read_gatk_plate(GATK)
    ff = rec.feet["right"]
    bw = 67.2 * G
    tds = _touchdowns(ff)
    assert len(tds) == 3
    for a, b in itertools.pairwise(tds):
        assert 2 * mean_vertical_force(rec, a, b) == pytest.approx(bw, rel=0.05)
    raw = np.genfromtxt(GATK, skip_header=1)
    walk = plate_walk(rec, bw, {"right": raw[:, 9]})  # RHEE x: the foot on the belt
    assert len(walk.stances["right"]) == 2
    assert walk.stride_time == pytest.approx(1.20, abs=0.01)
    for s in walk.stances["right"]:
        p1, valley, p2 = s.fz_peaks
        assert 1.0 <= p1 <= 1.3 and 1.0 <= p2 <= 1.3 and valley < min(p1, p2) - 0.1
        assert s.brake < -0.05 and s.push > 0.05  # braking, then propulsion
        assert 0.05 <= s.cop_travel <= 0.25  # m along the foot (heel marker to past MT5)
        assert 0.1 <= s.friction <= 0.35  # people's required friction about 0.2


def test_gatk_plate_events_against_the_kinematic_contact() -> None:
    """The plate's touchdowns and lift-offs (20 N, interpolated) against the marker rule
    (foot_contact): touchdowns within 2 frames, lift-offs within 3 (measured: 0.0, -1.6,
    +0.2 and +1.6, +2.3 frames, the markers' lift-offs early)."""
    rec = read_gatk_plate(GATK)
    ff = rec.feet["right"]
    raw = np.genfromtxt(GATK, skip_header=1)
    c = foot_contact(raw[:, 9:11], raw[:, 11:13], raw[:, 0])
    frame = (np.array(_touchdowns(ff)) - ff.time[0]) * 100
    assert np.max(np.abs(np.array(c.touchdowns) - frame)) <= 2
    lo = (np.array([b for _, b in stances(ff)]) - ff.time[0]) * 100
    assert np.all(lo - np.array(c.liftoffs) >= 0) and np.max(lo - np.array(c.liftoffs)) <= 3


def test_opensim_ground_reactions_give_the_labs_events_and_its_weight() -> None:
    """The lab's events (NOTICE.md: right touchdown 0.6183, left lift-off 0.7883, left
    touchdown 1.2467, right lift-off 1.4100 s at 600 Hz) within one 60 Hz frame; the feet's
    mean vertical force over the right stride equal to the weight from the left's (same
    person), 70-75 kg; peaks 1.0-1.3 BW."""
    rec = read_grf_mot(GRF, sagittal_frame("+y", "+x"))
    assert set(rec.feet) == {"left", "right"}
    (td, lo), = stances(rec.feet["right"])
    assert td == pytest.approx(0.6183, abs=1 / 60) and lo == pytest.approx(1.41, abs=1 / 60)
    ds = double_supports(rec)
    assert [d[2] for d in ds] == ["right", "left"]
    assert ds[0][1] == pytest.approx(0.7883, abs=1 / 60)
    assert ds[1][0] == pytest.approx(1.2467, abs=1 / 60)
    rtd = _touchdowns(rec.feet["right"])
    bw = mean_vertical_force(rec, rtd[0], rtd[1])
    assert 70 * G <= bw <= 75 * G
    walk = plate_walk(rec, bw)
    assert walk.stride_time == pytest.approx(rtd[1] - rtd[0])
    assert 0.12 <= walk.double_supports["right"] <= 0.22  # 10-15 % of a 1.23 s stride
    s, = walk.stances["right"]
    assert 1.0 <= s.fz_peaks[0] <= 1.3 and 1.0 <= s.fz_peaks[2] <= 1.3


def test_opensim_cop_moves_forward_along_the_foot_on_the_treadmill() -> None:
    """On the treadmill the CoP moves backward in the lab (with the belt) but forward
    relative to the heel marker."""
    from characterization.mocap.trc_io import read_trc

    rec = read_grf_mot(GRF, sagittal_frame("+y", "+x"))
    take = read_trc(DATA / "opensim-walk" / "subject01_walk1.trc")
    frame = sagittal_frame("+y", "+x")
    ff = rec.feet["right"]
    heel = foot_x_on(ff.time, take.time, frame.project(take.marker("R.Heel"))[:, 0])
    lab = plate_walk(rec, 700.0).stances["right"][0]
    foot = plate_walk(rec, 700.0, {"right": heel}).stances["right"][0]
    assert lab.cop_travel < -0.3  # the belt carries the foot back
    assert 0.05 <= foot.cop_travel <= 0.25


def test_a_file_without_ground_forces_is_one_line_error(tmp_path) -> None:
    bad = tmp_path / "x.mot"
    bad.write_text("x\nendheader\ntime\tq\n0\t1\n")
    with pytest.raises(MocapError, match="no ground-force columns"):
        read_grf_mot(bad, sagittal_frame("+y", "+x"))
