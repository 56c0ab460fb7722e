"""A take's force plates carried by ``mocap process`` into the steps file, for ``gait fit``'s
comparison of ground forces (issue 37, item 4), on OpenSim's subject01 treadmill walk over
two strides (``tests/data/opensim-walk-strides``, NOTICE.md; its mapping names the plates).

The independent side: the ``.mot`` read here with numpy (columns by name, OpenSim's Y up),
each stance cut at the lab's 20 N crossings (linear between the 60 Hz rows).  Tolerances:

* a stance's mean vertical force: the raw rows' trapezoid over the stance against the stored
  101-point curve's (the same piecewise-linear force sampled twice as finely as the rows; the
  difference is the curve's resampling, measured 0.03 N; bound 0.5 % BW);
* the peaks: the stored curve is the mean of two stances on the normalized stance, so its
  peak is at most the mean of the stances' own peak rows, lower by how far apart in the
  stance they fall (measured 0.1-0.4 % BW; bound 2 % BW, a tenth of the issue's 15 %);
* the plates' weight over whole strides: the scale setup's 72.6 kg (NOTICE.md: 1.000-1.004
  per stride; bound 2 %, the treadmill's stride-to-stride variation).
"""

from __future__ import annotations

import dataclasses
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from characterization.mocap.files import read_take
from characterization.mocap.force_plates import STANCE_SAMPLES, mapped_plates
from characterization.mocap.mapping import load_mapping
from characterization.mocap.sagittal import sagittal_frame
from characterization.mocap.session import process_session
from characterization.mocap.steps_artifact import (
    PLATES,
    StepsFileError,
    load_steps,
    plate_forces,
    save_steps,
)
from characterization.mocap.take import MocapError
from tests.cli_support import hpcosim

TAKE = Path(__file__).parent / "data" / "opensim-walk-strides"
TRC, MOT, MAPPING = (TAKE / "subject01_walk1.trc", TAKE / "subject01_walk1_grf_60hz.mot",
                     TAKE / "mapping.toml")
#: N: 72.6 kg (opensim-core's scale setup for subject01) at the model's 9.81 m/s^2
WEIGHT = 72.6 * 9.81
#: model foot -> the .mot's force prefix (the mapping: left leg human, right prosthesis)
COLUMNS = {"human": "l_ground_force_", "prosthesis": "ground_force_"}
LEVEL = 20.0  # N, the lab's threshold


def _mot() -> tuple[list[str], np.ndarray]:
    lines = MOT.read_text().splitlines()
    k = next(i for i, s in enumerate(lines) if s.strip() == "endheader")
    return lines[k + 1].split(), np.loadtxt(MOT, skiprows=k + 2)


def _direct_stances(foot: str, t0: float, t1: float) -> list[dict[str, float]]:
    """Each full stance of ``foot`` inside [t0, t1] s from the raw rows: its mean vertical
    force and its peak rows in the first and second half (N)."""
    names, rows = _mot()
    t = rows[:, names.index("time")]
    fy = rows[:, names.index(COLUMNS[foot] + "vy")]

    def cross(j: int | np.integer) -> float:
        return float(t[j - 1] + (LEVEL - fy[j - 1]) / (fy[j] - fy[j - 1]) * (t[j] - t[j - 1]))

    on = (fy > LEVEL).astype(int)
    ups, downs = np.flatnonzero(np.diff(on) == 1) + 1, np.flatnonzero(np.diff(on) == -1) + 1
    out = []
    for u in ups:
        later = downs[downs > u]
        if not later.size:
            continue
        td, lo = cross(u), cross(later[0])
        if td < t0 or lo > t1:
            continue
        m = (t > td) & (t < lo)
        tt = np.concatenate([[td], t[m], [lo]])
        ff = np.concatenate([[LEVEL], fy[m], [LEVEL]])
        mid = (td + lo) / 2
        out.append({"mean": float(np.trapezoid(ff, tt) / (lo - td)),
                    "p1": float(fy[m & (t < mid)].max()), "p2": float(fy[m & (t >= mid)].max())})
    return out


@pytest.fixture(scope="module")
def steps_file(tmp_path_factory) -> Path:
    """The take processed as ``hpcosim mocap process TRC --mapping mapping.toml`` does."""
    out = tmp_path_factory.mktemp("plates") / "steps.npz"
    process_session([TRC], out, mapping=MAPPING, with_figures=False)
    return out


def test_both_feet_stance_forces_match_the_plates_read_directly(steps_file) -> None:
    a = load_steps(steps_file)
    assert a.plate_source is not None and Path(a.plate_source).name == MOT.name
    got = plate_forces(a, str(steps_file))
    assert got is not None
    grf, bw = got
    assert set(grf) == {"human", "prosthesis"}
    assert bw == pytest.approx(WEIGHT, rel=0.02)
    assert a.plate_weight == bw
    s = np.linspace(0.0, 1.0, STANCE_SAMPLES)
    half = STANCE_SAMPLES // 2
    for foot, stance in grf.items():
        direct = _direct_stances(foot, float(a.time[0]), float(a.time[-1]))
        assert stance.count == len(direct) == 2, foot  # two full stances of each foot
        assert np.trapezoid(stance.fz, s) == pytest.approx(
            np.mean([d["mean"] for d in direct]), abs=0.005 * WEIGHT), foot
        for got_peak, key in ((stance.fz[:half].max(), "p1"), (stance.fz[half:].max(), "p2")):
            want = np.mean([d[key] for d in direct])
            assert want - 0.02 * WEIGHT <= got_peak <= want + 1e-9, (foot, key)
        # the ground on the foot in the walking direction: braking, then push-off
        assert stance.fx[:half].min() < -0.1 * WEIGHT and stance.fx[half:].max() > 0.1 * WEIGHT


def test_the_report_says_the_plates_were_read(steps_file) -> None:
    qa = json.loads(steps_file.with_suffix(".qa.json").read_text())
    plates = qa["force_plates"]
    assert plates["full_stances"] == {"human": 2, "prosthesis": 2}
    assert plates["weight_n"] == pytest.approx(WEIGHT, rel=0.02)
    assert any("force plates" in n and "2 full stance(s)" in n for n in qa["notes"])


def test_default_columns_follow_the_segmentation_sides(tmp_path) -> None:
    """Without column prefixes the plates' left foot is the mapping's human side (Left by
    default); with ``human_side = "Right"`` the human foot gets the right plate's force."""
    take, frame = read_take(TRC), sagittal_frame("+y", "+x")
    named = mapped_plates(take, load_mapping(MAPPING), frame)
    text = MAPPING.read_text().replace(f'"{MOT.name}"', f'"{MOT}"').replace(
        '"subject01_static.trc"', f'"{TAKE / "subject01_static.trc"}"')
    text = "\n".join(s for s in text.splitlines()
                     if not s.startswith(("human =", "prosthesis =")))
    by_side = tmp_path / "sides.toml"
    by_side.write_text(text)
    default = mapped_plates(take, load_mapping(by_side), frame)
    assert named is not None and default is not None
    for foot in COLUMNS:
        np.testing.assert_array_equal(default.feet[foot].fz, named.feet[foot].fz)
    swapped = tmp_path / "swapped.toml"
    swapped.write_text(text.replace('method = "contact"',
                                    'method = "contact"\nhuman_side = "Right"\n'
                                    'prosthesis_side = "Left"'))
    sw = mapped_plates(take, load_mapping(swapped), frame)
    assert sw is not None
    np.testing.assert_array_equal(sw.feet["human"].fz, named.feet["prosthesis"].fz)


def _mapping_with(tmp_path: Path, old: str, new: str) -> Path:
    text = MAPPING.read_text().replace('"subject01_static.trc"',
                                       f'"{TAKE / "subject01_static.trc"}"')
    text = text.replace(f'"{MOT.name}"', f'"{MOT}"').replace(old, new)
    p = tmp_path / "mapping.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(("old", "new", "words"), [
    (str(MOT), str(TAKE / "missing.mot"), ("force_plates.file", "missing.mot", "no such file")),
    ('human = "l_ground_force_"', 'human = "left_force_"',
     ("force_plates.human", "left_force_vx", MOT.name)),
    (str(MOT), str(TRC), ("force_plates.file", "subject01_walk1.trc", ".mot")),
])
def test_a_bad_plates_entry_is_one_line_naming_it(tmp_path, old, new, words) -> None:
    m = _mapping_with(tmp_path, old, new)
    with pytest.raises(MocapError) as e:
        load_mapping(m)
    assert "\n" not in str(e.value) and str(m) in str(e.value)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_the_command_line_refuses_a_missing_plates_file_in_one_line(tmp_path) -> None:
    m = _mapping_with(tmp_path, str(MOT), str(TAKE / "missing.mot"))
    r = hpcosim("mocap", "process", str(TRC), "--mapping", str(m), "--out",
                str(tmp_path / "steps.npz"), "--no-figures")
    lines = r.stderr.strip().splitlines()
    assert r.returncode != 0 and len(lines) == 1, r.stderr
    assert "force_plates.file" in lines[0] and "missing.mot" in lines[0]
    assert not (tmp_path / "steps.npz").exists()


def test_an_older_steps_file_without_plates_loads(steps_file, tmp_path) -> None:
    """The plates' fields left out (a file made before them): it loads, without plates;
    some of them only: one line naming the missing field."""
    old = tmp_path / "old.npz"
    with zipfile.ZipFile(steps_file) as src, zipfile.ZipFile(old, "w") as dst:
        for item in src.infolist():
            if item.filename.removesuffix(".npy") not in PLATES:
                dst.writestr(item, src.read(item))
    a = load_steps(old)
    assert all(getattr(a, k) is None for k in PLATES) and plate_forces(a) is None
    part = tmp_path / "part.npz"
    with zipfile.ZipFile(steps_file) as src, zipfile.ZipFile(part, "w") as dst:
        for item in src.infolist():
            if item.filename != "plate_fz.npy":
                dst.writestr(item, src.read(item))
    with pytest.raises(StepsFileError, match=r"field 'plate_fz': missing"):
        load_steps(part)


def test_json_round_trip_and_the_subjects_weight_without_a_whole_stride(steps_file,
                                                                        tmp_path) -> None:
    """A ``.json`` steps file keeps the plates (a NaN weight as null); without the plates'
    own weight the stored subject's 72.6 kg gives it."""
    a = dataclasses.replace(load_steps(steps_file), plate_weight=float("nan"))
    js = tmp_path / "steps.json"
    save_steps(js, a)
    b = load_steps(js)
    assert b.plate_weight is not None and np.isnan(b.plate_weight)
    assert b.plate_fz is not None and a.plate_fz is not None
    np.testing.assert_allclose(b.plate_fz, a.plate_fz, rtol=1e-12)
    got = plate_forces(b, str(js))
    assert got is not None and got[1] == pytest.approx(WEIGHT, rel=1e-9)


def test_a_c3d_whose_own_plates_cannot_be_read_is_processed_without_them(
        tmp_path, monkeypatch) -> None:
    """A C3D's own plates are optional: a plate layout the reader does not know (here: the
    reader made to fail on openOFM's Vicon take, as if it had plates) is a warning naming the
    file, and the take's steps are written without plates."""
    from characterization.mocap import force_plates
    from characterization.mocap.files import process_file

    def unknown_layout(*_args, **_kwargs):
        raise KeyError("CAL_MATRIX")

    monkeypatch.setattr(force_plates, "c3d_plate_count", lambda _path: 2)
    monkeypatch.setattr(force_plates, "read_c3d_plates", unknown_layout)
    ofm = Path(__file__).parent / "data" / "openofm-walk"
    res = process_file(ofm / "dynamic.c3d", tmp_path / "steps.npz",
                       mapping=ofm / "mapping.toml", with_figures=False)
    said = [w for w in res.processed.warnings if "force plates could not be read" in w]
    assert len(said) == 1 and "dynamic.c3d" in said[0] and "CAL_MATRIX" in said[0], \
        res.processed.warnings
    a = load_steps(tmp_path / "steps.npz")
    assert a.plate_source is None and len(a.step_domain) > 0
