"""OpenSim's subject01 treadmill walk over two strides with both feet's force plates
(``tests/data/opensim-walk-strides``, NOTICE.md) through ``hpcosim mocap process``'s path,
its take-side figures against what the plates say.

Physics and the sources' own numbers behind the tolerances:

* Over a whole stride of steady walking the body's vertical momentum returns, so the feet's
  mean vertical force is the body weight; the weight here is independent of the plates, the
  72.6 kg of OpenSim's scale setup for this subject (measured: 1.000-1.004 of it per stride;
  bound 2 %, the treadmill's stride-to-stride variation).
* The lab's own events at 600 Hz (``tests/data/opensim-walk/NOTICE.md``: right touchdown
  0.6183, left lift-off 0.7883, left touchdown 1.2467, right lift-off 1.4100 s) are found
  from the 60 Hz rows within one 60 Hz frame.
* The markers' contact rule (``foot_contact``) sees a touchdown when the heel marker comes
  to rest on the belt, after the plate's 20 N (measured +1.6 to +3.0 frames at 60 Hz; bound
  3, the issue's event tolerance, as tests/test_mocap_real.py), and a lift-off when the toe
  leaves, at or after the plate's last 20 N (measured +0.6 to +1.4; bound 2).  A stride,
  touchdown to touchdown, is then within 1.5 frames of the plates' (measured 0.6 and 1.0).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from characterization.mocap.files import process_file, read_take
from characterization.mocap.foot_contact import strides
from characterization.mocap.force_plates import (
    PlateRecord,
    mean_vertical_force,
    plate_walk,
    read_grf_mot,
    stances,
)
from characterization.mocap.sagittal import sagittal_frame
from hp_model import COORDS
from hp_model.domains import Domain

DATA = Path(__file__).parent / "data"
TAKE = DATA / "opensim-walk-strides"
SHORT = DATA / "opensim-walk"
G = 9.81
#: kg, opensim-core Applications/Scale/test/subject01_Setup_Scale.xml
MASS = 72.6
RATE = 60.0
#: foot of the model -> the subject's side (mapping.toml)
SIDE = {"human": "left", "prosthesis": "right"}


def _plates() -> PlateRecord:
    return read_grf_mot(TAKE / "subject01_walk1_grf_60hz.mot", sagittal_frame("+y", "+x"))


def _crossings(record: PlateRecord, side: str, up: bool, level: float = 20.0) -> list[float]:
    """s: the plate's touchdowns (``up``) or lift-offs, linear between rows."""
    ff = record.feet[side]
    on = (ff.fz > level).astype(int)
    idx = np.flatnonzero(np.diff(on) == (1 if up else -1)) + 1
    return [float(ff.time[i - 1] + (level - ff.fz[i - 1]) / (ff.fz[i] - ff.fz[i - 1])
                  * (ff.time[i] - ff.time[i - 1])) for i in idx]


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    """The take processed as ``hpcosim mocap process TAKE --mapping mapping.toml`` does."""
    out = tmp_path_factory.mktemp("strides") / "steps.npz"
    return process_file(TAKE / "subject01_walk1.trc", out, mapping=TAKE / "mapping.toml",
                        with_figures=False).processed


def test_the_take_extends_the_short_fixture_unchanged() -> None:
    """184 frames at 60 Hz, 0.300-3.350 s; the frames and rows the two fixtures share are
    the same numbers (both copied from the same sources)."""
    take, short = read_take(TAKE / "subject01_walk1.trc"), read_take(SHORT / "subject01_walk1.trc")
    assert take.n_frames == 184 and take.frame_rate == RATE and len(take.markers) == 24
    assert take.time[0] == pytest.approx(0.300) and take.time[-1] == pytest.approx(3.350)
    n = short.n_frames
    for name, xyz in short.markers.items():
        np.testing.assert_array_equal(take.marker(name)[:n], xyz)
    long_rows = (TAKE / "subject01_walk1_grf_60hz.mot").read_text().splitlines()
    short_rows = (SHORT / "subject01_walk1_grf_60hz.mot").read_text().splitlines()
    assert long_rows[5:len(short_rows)] == short_rows[5:]  # column names and 0-1.95 s
    assert len(long_rows) - 6 == 203


def test_plates_carry_the_scale_setups_weight_over_every_stride() -> None:
    """Both feet's mean vertical force over each full stride of either foot is 72.6 kg's
    weight; two full stances per foot, each a double hump of 1.0-1.3 BW peaks."""
    rec = _plates()
    bw = MASS * G
    n = 0
    for side in ("left", "right"):
        for a, b in itertools.pairwise(_crossings(rec, side, up=True)):
            assert mean_vertical_force(rec, a, b) == pytest.approx(bw, rel=0.02), (side, a)
            n += 1
    assert n == 3  # two right strides, one left
    walk = plate_walk(rec, bw)
    assert {f: len(s) for f, s in walk.stances.items()} == {"left": 2, "right": 2}
    for s in itertools.chain(*walk.stances.values()):
        p1, valley, p2 = s.fz_peaks
        assert 1.0 <= p1 <= 1.3 and 1.0 <= p2 <= 1.3 and valley < min(p1, p2) - 0.1
    assert walk.stride_time == pytest.approx(1.22, abs=0.02)


def test_plates_give_the_labs_600_hz_events() -> None:
    rec = _plates()
    (r_td, r_lo), _ = stances(rec.feet["right"])
    assert r_td == pytest.approx(0.6183, abs=1 / RATE) and r_lo == pytest.approx(1.41, abs=1 / RATE)
    (l_td, _), _ = stances(rec.feet["left"])
    assert l_td == pytest.approx(1.2467, abs=1 / RATE)
    assert _crossings(rec, "left", up=False)[0] == pytest.approx(0.7883, abs=1 / RATE)


def test_marker_events_against_the_plates(processed) -> None:
    """Every plate event inside the take has its marker event, touchdowns 0-3 frames and
    lift-offs 0-2 frames after it (module docstring)."""
    rec = _plates()
    t0 = processed.time[0]
    for foot, side in SIDE.items():
        c = processed.contacts[foot]
        for kind, found, up, hi in (("touchdown", c.touchdowns, True, 3.0),
                                    ("liftoff", c.liftoffs, False, 2.0)):
            plate = [(t - t0) * RATE for t in _crossings(rec, side, up)]
            plate = [f for f in plate if 0 <= f < len(processed.time)]
            assert len(found) == len(plate), (foot, kind, found, plate)
            lag = np.asarray(found, float) - np.asarray(plate)
            assert np.all(lag >= 0) and np.all(lag <= hi), (foot, kind, lag)


def test_strides_and_steps_against_the_plates(processed) -> None:
    """Two prosthesis (right) strides, each within 1.5 frames of the plates'; the steps a
    gait fit takes: two of each single-support domain."""
    rec = _plates()
    st = strides(processed.contacts, processed.q[:, COORDS.index("x_B")], processed.frame_rate)
    plate = np.diff(_crossings(rec, "right", up=True))
    assert len(st) == len(plate) == 2
    np.testing.assert_allclose([s.time for s in st], plate, atol=1.5 / RATE)
    assert all(0.9 <= s.speed <= 1.4 for s in st)  # m/s over the belt: a person's walk
    domains = [s.domain for s in processed.steps]
    assert domains.count(Domain.PS) == 2 and domains.count(Domain.PNS) == 2


def test_the_paper_domains_are_found_on_the_treadmill(tmp_path) -> None:
    """On a treadmill the stance ankle moves with the belt, so the landing foot's ankle comes
    to rest against the belt (``ground_speed``), not in the lab: each of the paper's domains
    (prosthesis (right) -> ps, human (left) -> pns) starts in the double support the plates
    show after its foot's touchdown, between that touchdown and the other foot's lift-off
    (3 frames of the markers' lag allowed)."""
    from characterization.mocap.domain_segmentation import domain_segments
    from characterization.mocap.steps_artifact import load_steps

    process_file(TAKE / "subject01_walk1.trc", tmp_path / "steps.npz",
                 mapping=TAKE / "mapping.toml", with_figures=False)
    steps = load_steps(tmp_path / "steps.npz")
    assert steps.ground_speed is not None and abs(steps.ground_speed) > 0.5  # a belt
    segs = domain_segments(steps)
    rec = _plates()
    feet = {Domain.PS: ("right", "left"), Domain.PNS: ("left", "right")}
    assert {s.domain for s in segs} == {Domain.PS, Domain.PNS} and len(segs) >= 3
    for s in segs:
        t = float(steps.time[s.start])
        own, other = feet[s.domain]
        landed = max(c for c in _crossings(rec, own, up=True) if c <= t)
        left = min(c for c in _crossings(rec, other, up=False) if c >= landed)
        assert landed <= t <= left + 3.0 / RATE, (s, t, landed, left)


def test_the_static_calibration_takes_the_legs_standing_pitch_from_their_landmarks() -> None:
    """The mapping's ``calibration.landmarks``: each leg segment's offset is its marker pair's
    standing pitch less its landmarks' axis (the epicondyles' and the malleoli's midpoints;
    the hip by Harrington et al. 2007).  The subject stood with the shanks 4.5-4.7 deg
    forward (the knees ahead of the ankles, as people stand) and the thighs 6-10 deg; the
    other limbs keep the upright assumption.  A wrong landmark is one line naming it."""
    from characterization.mocap.mapping import load_mapping
    from characterization.mocap.pipeline import static_offsets
    from characterization.mocap.take import MocapError

    mapping = load_mapping(TAKE / "mapping.toml")
    static = read_take(TAKE / "subject01_static.trc")
    plain = static_offsets(static, mapping.model_copy(update={
        "calibration": mapping.calibration.model_copy(update={"landmarks": {}})}))
    landmarked = static_offsets(static, mapping)
    shift = {k: np.degrees(plain[k] - landmarked[k]) for k in plain}
    assert shift["l_shank"] == pytest.approx(4.5, abs=0.2)
    assert shift["p_shin"] == pytest.approx(4.7, abs=0.2)
    assert 5.0 < shift["l_thigh"] < 11.0 and 5.0 < shift["r_thigh"] < 11.0
    for limb in ("hat", "l_foot", "p_foot"):
        assert shift[limb] == 0.0
    bad = mapping.model_copy(update={"calibration": mapping.calibration.model_copy(
        update={"landmarks": {"l_shank": (["L.Knee.Lat"], ["L.Ankle.Nowhere"])}})})
    with pytest.raises(MocapError, match=r"landmarks\.l_shank: no marker 'L\.Ankle\.Nowhere'"):
        static_offsets(static, bad)


@pytest.mark.parametrize("text, words", [
    ('landmarks.l_thigh = ["hip", ["L.Knee.Lat"]]\n', "'hip' needs [calibration.pelvis]"),
    ('landmarks.l_foot = [["L.Heel"], ["L.Toe.Tip"]]\n', "unknown landmark limb 'l_foot'"),
])
def test_a_bad_landmark_calibration_is_one_line(tmp_path, text, words) -> None:
    from characterization.mocap.mapping import load_mapping
    from characterization.mocap.take import MocapError

    src = (TAKE / "mapping.toml").read_text()
    start = src.index("[calibration]")
    end = src.index("[force_plates]")
    path = tmp_path / "mapping.toml"
    path.write_text(src[:start] + '[calibration]\nstatic_trial = "x.trc"\n' + text + "\n"
                    + src[end:])
    with pytest.raises(MocapError) as e:
        load_mapping(path)
    assert words in str(e.value) and "\n" not in str(e.value)
