"""Motive CSV and C3D readers, sagittal projection, bad input and the ``hpcosim mocap`` CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hp_model
from characterization.mocap.c3d_io import read_c3d, write_c3d
from characterization.mocap.mapping import LIMBS, default_mapping
from characterization.mocap.motive_csv import read_motive_csv, write_motive_csv
from characterization.mocap.pipeline import limb_pitches, resolve_frame
from characterization.mocap.sagittal import SagittalFrame, axis_vector
from characterization.mocap.steps_artifact import load_steps
from characterization.mocap.synthetic_subject import SynthOptions, synthesize
from characterization.mocap.take import MocapError
from hp_model.domains import PAPER_DOMAINS
from orchestrator.cli import main


@pytest.fixture(scope="module")
def synth():
    return synthesize(hp_model.load_model(), SynthOptions(n_strides=6, seed=5))


@pytest.fixture(scope="module")
def files(synth, tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("take")
    write_motive_csv(d / "take.csv", synth.take)
    write_c3d(d / "take.c3d", synth.take_c3d)
    return {"csv": d / "take.csv", "c3d": d / "take.c3d"}


def _pitches(take, mapping=None):
    m = mapping or default_mapping()
    return limb_pitches(take, m, resolve_frame(take, m))


def test_csv_round_trip(synth, files) -> None:
    t = read_motive_csv(files["csv"])
    assert t.frame_rate == pytest.approx(120.0)
    assert set(t.markers) == set(synth.take.markers)
    assert set(t.rigid_bodies) == set(synth.take.rigid_bodies)
    for k, v in synth.take.markers.items():
        np.testing.assert_allclose(t.markers[k], v, atol=1e-6)  # 6 decimals in metres
        np.testing.assert_array_equal(np.isnan(t.markers[k]), np.isnan(v))
    for k, rb in synth.take.rigid_bodies.items():
        np.testing.assert_allclose(t.rigid_bodies[k].quaternion, rb.quaternion, atol=1e-6)
        np.testing.assert_allclose(t.rigid_bodies[k].position, rb.position, atol=1e-6)


def test_units_and_euler_rotations_read_the_same(synth, tmp_path) -> None:
    ref = _pitches(synth.take)
    write_motive_csv(tmp_path / "mm.csv", synth.take, units="Millimeters",
                     rotation_type="ZYX", decimals=5)
    t = read_motive_csv(tmp_path / "mm.csv")
    np.testing.assert_allclose(t.markers["LShank:Marker1"],
                               synth.take.markers["LShank:Marker1"], atol=1e-7)
    got = _pitches(t)
    for limb in LIMBS:
        np.testing.assert_allclose(got[limb].theta, ref[limb].theta, atol=1e-5)


def test_c3d_and_csv_readers_give_the_same_angles(files) -> None:
    """C3D holds markers only: the same marker-pair angles as the CSV read without rigid
    bodies (C3D stores float32 mm; spline-filled frames amplify that to < 1e-4 rad); and within
    noise of the CSV's rigid-body angles."""
    csv = read_motive_csv(files["csv"])
    c3d = read_c3d(files["c3d"])
    assert c3d.up_axis == "+z" and csv.up_axis == "+y"
    a = _pitches(csv.replace(rigid_bodies={}))
    b = _pitches(c3d)
    full = _pitches(csv)
    for limb in LIMBS:
        ok = np.isfinite(a[limb].theta) & np.isfinite(b[limb].theta)
        assert ok.sum() > 0.95 * len(ok)
        np.testing.assert_allclose(a[limb].theta[ok], b[limb].theta[ok], atol=1e-4)
        np.testing.assert_array_equal(a[limb].source, b[limb].source)
        ok &= np.isfinite(full[limb].theta)
        rms = np.degrees(np.sqrt(np.mean((full[limb].theta[ok] - b[limb].theta[ok]) ** 2)))
        assert rms < 0.3, (limb, rms)


def test_sagittal_projection_and_quaternion_pitch() -> None:
    """A rigid body rotated by +0.3 rad about the walker's left (lab +Z when walking along
    lab -X with Y up) has pitch +0.3: its up axis tilts toward the walking direction."""
    from scipy.spatial.transform import Rotation

    f = SagittalFrame(forward=axis_vector("-x"), up=axis_vector("+y"))
    np.testing.assert_allclose(f.lateral, [0, 0, 1])
    q = Rotation.from_rotvec([[0, 0, 0.3]]).as_quat()
    assert f.pitch_from_quaternion(q, "up")[0] == pytest.approx(0.3)
    assert f.pitch_from_quaternion(q, "forward")[0] == pytest.approx(0.3)
    up = Rotation.from_quat(q).apply([0, 1, 0])
    assert f.project(up[None])[0, 0] > 0  # tilted forward
    np.testing.assert_allclose(f.project(np.array([[2.0, 1.0, 5.0]])), [[-2.0, 1.0]])


HEADER = ("Format Version,1.23,Take Name,t,Export Frame Rate,120.000000,Rotation Type,"
          "Quaternion,Length Units,Meters,Coordinate Space,Global\n\n"
          ",Type,Marker,Marker,Marker\n,Name,A,A,A\n,ID,1,1,1\n,,Position,Position,Position\n"
          "Frame,Time (Seconds),X,Y,Z\n")


def _bad_csv(files, tmp_path, kind: str) -> Path:
    text = files["csv"].read_text()
    p = tmp_path / f"{kind}.csv"
    if kind == "truncated":
        p.write_text(text[: len(text) - 2000])
    elif kind == "units":
        p.write_text(text.replace("Length Units,Meters", "Length Units,Furlongs", 1))
    elif kind == "missing_marker":
        p.write_text(text.replace("LShank:Marker2", "LShank:MarkerX"))
    elif kind == "missing_rigid_body":
        lines = text.splitlines(keepends=True)
        lines[3] = ",".join("Shin" if c == "LShank" else c for c in lines[3].split(","))
        p.write_text("".join(lines))
    elif kind == "no_header":
        lines = text.splitlines(keepends=True)
        p.write_text(lines[0] + "".join(lines[7:]))
    elif kind == "not_a_number":
        lines = text.splitlines(keepends=True)
        cells = lines[100].split(",")
        cells[5] = "abc"
        lines[100] = ",".join(cells)
        p.write_text("".join(lines))
    return p


@pytest.mark.parametrize("kind,expect", [
    ("truncated", "truncated"),
    ("units", "unknown units 'Furlongs'"),
    ("missing_marker", "no marker column 'LShank:Marker2'"),
    ("missing_rigid_body", "no rigid body column 'LShank'"),
    ("no_header", "no header rows"),
    ("not_a_number", "not a number 'abc'"),
])
def test_bad_input_one_line_error_no_output(files, tmp_path, capsys, kind, expect) -> None:
    bad = _bad_csv(files, tmp_path, kind)
    out = tmp_path / "steps.npz"
    code = main(["mocap", "process", str(bad), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("hpcosim: error: ")
    assert str(bad) in err and expect in err
    if kind == "truncated":
        assert "line " in err and "frame " in err
    if kind == "not_a_number":
        assert "column 6" in err
    assert sorted(x.name for x in tmp_path.iterdir()) == [bad.name]


def test_all_empty_limb_is_an_error(synth, tmp_path, capsys) -> None:
    t = synth.take
    markers = {k: (np.full_like(v, np.nan) if k.startswith("PShin:") else v)
               for k, v in t.markers.items()}
    bodies = {k: (type(v)(v.position, np.full_like(v.quaternion, np.nan), None)
                  if k == "PShin" else v) for k, v in t.rigid_bodies.items()}
    p = tmp_path / "empty.csv"
    write_motive_csv(p, t.replace(markers=markers, rigid_bodies=bodies))
    code = main(["mocap", "process", str(p), "--out", str(tmp_path / "s.npz")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "limb 'p_shin'" in err and "empty in every frame" in err
    assert str(p) in err and len(err.splitlines()) == 1
    assert sorted(x.name for x in tmp_path.iterdir()) == ["empty.csv"]


def test_minimal_csv_and_unknown_rotation_type(tmp_path) -> None:
    p = tmp_path / "m.csv"
    p.write_text(HEADER + "0,0.0,1,2,3\n1,0.008333,,,\n2,0.016667,1000,2,3\n")
    t = read_motive_csv(p)
    np.testing.assert_array_equal(t.markers["A"][0], [1, 2, 3])
    assert np.all(np.isnan(t.markers["A"][1]))
    p.write_text(HEADER.replace("Quaternion", "Matrix") + "0,0.0,1,2,3\n")
    with pytest.raises(MocapError, match="unknown rotation type 'Matrix'"):
        read_motive_csv(p)


def test_cli_synth_then_process(tmp_path, capsys) -> None:
    d = tmp_path / "syn"
    assert main(["mocap", "synth", "--out", str(d), "--steps", "4", "--seed", "2"]) == 0
    assert {"take.csv", "take.c3d", "truth.npz", "mapping.toml"} <= {x.name for x in
                                                                    d.iterdir()}
    out = tmp_path / "steps.npz"
    assert main(["mocap", "process", str(d / "take.csv"), "--out", str(out), "--mapping",
                 str(d / "mapping.toml")]) == 0
    a = load_steps(out)
    truth = np.load(d / "truth.npz")
    assert a.step_domain.tolist() == truth["step_domain"].tolist()
    for name in ("steps.qa.md", "steps.qa.json", "steps_joint_angles.png",
                 "steps_phase_portraits.png"):
        assert (tmp_path / name).stat().st_size > 0
    out2 = tmp_path / "steps_c3d.json"
    assert main(["mocap", "process", str(d / "take.c3d"), "--out", str(out2),
                 "--no-figures"]) == 0
    b = load_steps(out2)
    assert b.n_steps >= a.n_steps - 2  # marker-only: a long pair gap may drop a step
    assert not list(tmp_path.glob(".*tmp*"))


def test_mapping_config_errors_and_explicit_axes(files, tmp_path) -> None:
    from characterization.mocap.mapping import load_mapping
    from characterization.mocap.synthetic_subject import mapping_toml

    good = mapping_toml(default_mapping())
    p = tmp_path / "mapping.toml"
    p.write_text(good.replace('[limbs.hat]', '[limbs.head]', 1))
    with pytest.raises(MocapError, match=r"mapping.toml: field 'limbs': .*unknown limb 'head'"):
        load_mapping(p)
    p.write_text(good.replace("lowpass_hz = 15.0", "lowpass_hz = -1"))
    with pytest.raises(MocapError, match=r"field 'processing.lowpass_hz'"):
        load_mapping(p)
    # explicit axes give the same pitches as auto-detection (walking along lab -X)
    p.write_text('up = "+z"\nforward = "-x"\n' + good.replace('up = "auto"\n', "")
                 .replace('forward = "auto"\n', ""))
    m = load_mapping(p)
    c3d = read_c3d(files["c3d"])
    auto = _pitches(c3d)
    explicit = _pitches(c3d, m)
    # auto-detection takes the trunk's net travel (about 5 m here, 0.5 mm noise at each end),
    # so it is off the lab axis by ~1e-4 rad of yaw; a yaw error e moves a pitch by about
    # e x (the pair's lateral noise / its length), 1e-6 rad: 1e-5 allowed
    for limb in LIMBS:
        np.testing.assert_allclose(auto[limb].theta, explicit[limb].theta, atol=1e-5)
    # walking the other way round flips every pitch's sign (the frame made directly) ...
    from characterization.mocap.sagittal import sagittal_frame

    back = limb_pitches(c3d, m, sagittal_frame("+z", "+x"))
    np.testing.assert_allclose(back["l_shank"].theta, -explicit["l_shank"].theta, atol=1e-12)
    # ... which is why a mapping that says so, against the feet, is refused
    with pytest.raises(MocapError, match=r"take.c3d: walking direction: the mapping gives "
                       r"forward = \"\+x\" but the feet point the other way"):
        resolve_frame(c3d, m.model_copy(update={"forward": "+x"}))


def test_a_motive_export_with_timecode_reads_the_same(synth, files, tmp_path) -> None:
    """Motive's optional TimeCode column (third, ``hh:mm:ss:ff``, an empty cell in every
    descriptor row) was refused ("not a number"); it is dropped and its first value kept."""
    lines = files["csv"].read_text().splitlines()
    out = []
    for i, ln in enumerate(lines):
        cells = ln.split(",")
        if i == 0 or not ln.strip():
            out.append(ln)
            continue
        if cells[0] == "Frame":
            extra = "TimeCode"
        elif cells[0] == "":
            extra = ""
        else:
            k = int(cells[0])
            extra = f"00:00:{k // 120:02d}:{k % 120 // 4:02d}.{k % 4}"
        out.append(",".join([*cells[:2], extra, *cells[2:]]))
    p = tmp_path / "timecode.csv"
    p.write_text("\n".join(out) + "\n")
    ref, got = read_motive_csv(files["csv"]), read_motive_csv(p)
    np.testing.assert_array_equal(got.time, ref.time)
    for k, v in ref.markers.items():
        np.testing.assert_array_equal(got.markers[k], v)
    for k, rb in ref.rigid_bodies.items():
        np.testing.assert_array_equal(got.rigid_bodies[k].quaternion, rb.quaternion)
    assert got.metadata["TimeCode start"] == "00:00:00:00.0"


def test_c3d_labels_beyond_point_used_are_spare(files) -> None:
    """POINT:LABELS may name more markers than the file stores (POINT:USED; the c3d.org gait
    samples do): the labels of the stored markers are read, the spare ones ignored; LABELS2
    continues LABELS.  Before, such files were refused (markers != labels)."""
    import ezc3d

    from characterization.mocap.c3d_io import point_labels, take_from_c3d

    c = ezc3d.c3d(str(files["c3d"]))
    ref = read_c3d(files["c3d"])
    names = list(c["parameters"]["POINT"]["LABELS"]["value"])
    n = len(names)
    # the parsed file with two spare labels and POINT:USED as stored
    par = {"LABELS": {"value": [*names, "Spare1", "Spare2"]}, "USED": {"value": [n]},
           "UNITS": c["parameters"]["POINT"]["UNITS"], "RATE": c["parameters"]["POINT"]["RATE"]}
    parsed = {"parameters": {"POINT": par}, "data": c["data"], "header": c["header"]}
    got = take_from_c3d(parsed, "spare.c3d")
    assert list(got.markers) == list(ref.markers)
    for k, v in ref.markers.items():
        np.testing.assert_array_equal(got.markers[k], v)
    # LABELS2 continues LABELS; more labels than markers with USED saying so is still an error
    split = {"LABELS": {"value": names[:3]}, "LABELS2": {"value": names[3:]},
             "USED": {"value": [n]}}
    assert point_labels(split, n) == [s.strip() for s in names]
    bad = dict(par, USED={"value": [n + 2]})
    with pytest.raises(MocapError, match="POINT:LABELS names"):
        take_from_c3d({"parameters": {"POINT": bad}, "data": c["data"],
                       "header": c["header"]}, "bad.c3d")


def test_a_jump_in_the_frame_times_is_refused(files, tmp_path) -> None:
    """Frame times that jump (35 s after data row 100; a concatenation of takes) were read
    as continuous frames; now one line names the rows and the jump.  A few dropped frames
    (3 periods) are not a jump."""
    lines = files["csv"].read_text().splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("Frame,")) + 1

    def shifted(k0: int, by: float) -> Path:
        out = list(lines)
        for i in range(start + k0, len(out)):
            cells = out[i].split(",")
            cells[1] = f"{float(cells[1]) + by:.6f}"
            out[i] = ",".join(cells)
        p = tmp_path / f"jump{by:g}.csv"
        p.write_text("\n".join(out) + "\n")
        return p

    with pytest.raises(MocapError, match=r"rows \d+-\d+: the time jumps by 35\.0\d* s"):
        read_motive_csv(shifted(100, 35.0))
    assert read_motive_csv(shifted(100, 2 / 120)).time[101] == pytest.approx(101 / 120 + 2 / 120)


def test_trc_round_trip_and_processing(synth, tmp_path) -> None:
    """OpenSim's TRC (tab separated, mm, Y up): the synthetic take written and read back
    (to the 1e-6 mm the writer prints), lost samples kept lost; processed end to end through
    the CLI; bad files are one-line errors naming the line."""
    from characterization.mocap.trc_io import read_trc, write_trc
    from orchestrator.cli import main

    take = synth.take.replace(rigid_bodies={}, rigid_body_markers={})
    p = tmp_path / "walk.trc"
    write_trc(p, take)
    back = read_trc(p)
    assert back.frame_rate == take.frame_rate and back.up_axis == "+y"
    assert list(back.markers) == list(take.markers)
    for k, v in take.markers.items():
        np.testing.assert_array_equal(np.isnan(back.markers[k]), np.isnan(v))
        np.testing.assert_allclose(back.markers[k], v, atol=1e-9, equal_nan=True)
    out = tmp_path / "steps.npz"
    assert main(["mocap", "process", str(p), "--out", str(out), "--no-figures"]) == 0
    text = p.read_text().splitlines()
    cases = {
        "header": (["PathFileTypo", *text[1:]], r"line 1: not a TRC file"),
        "units": ([*text[:2], text[2].replace("\tmm\t", "\tinch\t"), *text[3:]],
                  r"line 3: unknown Units 'inch'"),
        "number": ([*text[:8], text[8].replace(text[8].split("\t")[3], "x1.2", 1), *text[9:]],
                   r"line 9: not a number 'x1.2'"),
        "jump": ([*text[:8], text[8].replace(text[8].split("\t")[1], "99.0", 1), *text[9:]],
                 r"data rows \d+-\d+: the time"),
    }
    for name, (lines, msg) in cases.items():
        bad = tmp_path / f"{name}.trc"
        bad.write_text("\n".join(lines) + "\n")
        with pytest.raises(MocapError, match=msg):
            read_trc(bad)


def test_motive_exports_with_markers_only_or_rigid_bodies_only(synth, tmp_path) -> None:
    """Motive exports either kind alone.  Markers only: every pitch from the marker pairs,
    every step kept.  Rigid bodies only (their solved markers still exported): a
    rigid-body loss has no marker pair to fall back on, so the steps it spans are dropped,
    each with the limb and the frames in the reason."""
    from characterization.mocap.pipeline import process_take

    coef = {d: hp_model.load_model().hip_progress_coefficients(d) for d in PAPER_DOMAINS}
    full = process_take(synth.take, default_mapping(), coef)
    p = tmp_path / "markers.csv"
    write_motive_csv(p, synth.take.replace(rigid_bodies={}, rigid_body_markers={}))
    mk = process_take(read_motive_csv(p), default_mapping(), coef)
    assert len(mk.steps) >= len(full.steps) - 1 and not mk.dropped
    p = tmp_path / "bodies.csv"
    write_motive_csv(p, synth.take.replace(markers={}))
    rb = process_take(read_motive_csv(p), default_mapping(), coef)
    assert rb.steps and rb.dropped
    for d in rb.dropped:
        assert "has no pitch source for" in d.reason and "frames" in d.reason


def test_a_lowpass_at_or_above_nyquist_is_a_one_line_error(files, tmp_path, capsys) -> None:
    """The take is 120 Hz: a 60 Hz low-pass has no Butterworth design (it was a traceback)."""
    m = tmp_path / "m.toml"
    assert main(["mocap", "inspect", str(files["csv"]), "--mapping-out", str(m)]) == 0
    m.write_text(m.read_text().replace("lowpass_hz = 15.0", "lowpass_hz = 60.0"))
    capsys.readouterr()
    code = main(["mocap", "process", str(files["csv"]), "--out", str(tmp_path / "s.npz"),
                 "--mapping", str(m)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "'processing.lowpass_hz' = 60 Hz" in err and "Nyquist frequency (60 Hz" in err
    assert sorted(x.name for x in tmp_path.iterdir()) == ["m.toml"]


@pytest.mark.parametrize("body", ["1,2,3", "1,,3", "1,2,", "1,,,\n2,,3,", ",1,,2\n3,4,5,,",
                                  "1,,\n,,\n", "a,,,,,b,,\n,", "", ",", "\n", "1,\u00b0,,2"])
def test_empty_cells_read_as_nan_like_the_regex(body: str) -> None:
    """The numpy filling of empty cells equals the regex it replaced."""
    import re

    from characterization.mocap.motive_csv import _fill_empty

    want = re.sub(r"(?<=,)(?=,|$)", "nan", body, flags=re.MULTILINE)
    assert _fill_empty(body) == want.encode()
