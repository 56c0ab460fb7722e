"""``hpcosim mocap inspect``'s skeleton knows the legs' anatomical landmarks by name: a
walking take that carries both epicondyles and malleoli of each leg and the pelvis's spines
gets virtual markers (each leg segment on its anatomical axis in every frame), and a static
trial given with ``--static`` that carries them gets calibration landmarks.  The skeletons
are checked against what was written by hand for the real takes in tests/data."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from characterization.mocap.landmark_names import leg_landmarks, pelvis_landmarks, side_and_stem
from characterization.mocap.mapping import load_mapping
from tests.cli_support import hpcosim

DATA = Path(__file__).parent / "data"


@pytest.mark.parametrize(("name", "side", "stem"), [
    ("LLEK", "l", "lek"), ("L.Knee.Lat", "l", "kneelat"), ("RKNE", "r", "kne"),
    ("Right_Ankle_Med", "r", "anklemed"), ("V.Sacral", None, "vsacral"),
    ("Subject:LMMA", "l", "mma"), ("C7", None, "c7")])
def test_a_names_side_and_stem(name, side, stem):
    assert side_and_stem(name) == (side, stem)


def test_landmarks_only_where_every_one_is_named_once():
    both = ["LKNE", "LKNM", "LANK", "LMMA", "RKNE", "RKNM", "RANK", "RMMA"]
    assert leg_landmarks(both)["l"] == {"knee_lat": "LKNE", "knee_med": "LKNM",
                                        "ankle_lat": "LANK", "ankle_med": "LMMA"}
    assert set(leg_landmarks([n for n in both if n != "RKNM"])) == {"l"}  # a knee lacks one
    assert leg_landmarks([*both, "LLEK"]).get("l") is None  # two lateral epicondyles
    assert pelvis_landmarks(["LASI", "RASI", "SACR"]) == (["LASI", "RASI"], ["SACR"])
    assert pelvis_landmarks(["LASI", "RASI", "LPSI", "RPSI", "SACR"])[1] == ["LPSI", "RPSI"]
    assert pelvis_landmarks(["LASI", "LPSI", "RPSI"]) is None  # one ASIS


def _skeleton(tmp_path: Path, take: Path, *more: str) -> Path:
    out = tmp_path / "mapping.toml"
    r = hpcosim("mocap", "inspect", str(take), "--mapping-out", str(out), *more)
    assert r.returncode == 0, r.stderr
    return out


def test_a_take_with_its_landmarks_on_gets_the_legs_anatomical_axes(tmp_path):
    """gaitalytics' treadmill take: the skeleton's virtual markers, leg limbs and trunk (PSIS
    midpoint -> C7) are the hand-written mapping's, and it processes as is into the same 21
    steps."""
    take = DATA / "gaitalytics-treadmill" / "treadmill_events.c3d"
    out = _skeleton(tmp_path, take)
    ours, shipped = load_mapping(out), load_mapping(take.parent / "mapping.toml")
    for name in ("HJC", "LKJC", "RKJC", "LAJC", "RAJC"):
        assert ours.virtual_markers[name] == shipped.virtual_markers[name], name
    for limb in ("hat", "l_thigh", "l_shank", "r_thigh", "p_shin"):
        assert ours.limbs[limb].markers == shipped.limbs[limb].markers, limb
    assert ours.virtual_markers["PSIS"] == shipped.virtual_markers["PSIS"]  # the trunk:
    # along the back (an ASIS -> C7 pair read the trunk 21.5 deg off)
    steps = tmp_path / "steps.npz"
    r = hpcosim("mocap", "process", str(take), "--mapping", str(out), "--out", str(steps),
                "--no-figures")
    assert r.returncode == 0, r.stderr
    assert "(21 steps)" in r.stdout


def test_a_static_trial_with_landmarks_gives_the_calibration(tmp_path):
    """OpenSim's strides with their static trial: the skeleton's calibration is the one
    written by hand (landmarks and pelvis), the trial's path relative to the mapping."""
    take = DATA / "opensim-walk-strides"
    out = _skeleton(tmp_path, take / "subject01_walk1.trc",
                    "--static", str(take / "subject01_static.trc"))
    raw = tomllib.loads(out.read_text())
    assert "virtual_markers" not in raw  # the walking take has no medial markers
    assert (out.parent / raw["calibration"]["static_trial"]).resolve() == \
        (take / "subject01_static.trc").resolve()
    ours = load_mapping(out).calibration
    shipped = load_mapping(take / "mapping.toml").calibration
    assert ours is not None and shipped is not None
    assert ours.landmarks == shipped.landmarks
    assert ours.pelvis is not None and shipped.pelvis is not None
    assert set(ours.pelvis.asis) == set(shipped.pelvis.asis)
    assert ours.pelvis.sacrum == shipped.pelvis.sacrum


def test_a_static_trial_without_landmarks_keeps_upright(tmp_path):
    """openOFM's static trial names no medial epicondyle: its path only, said so."""
    take = DATA / "openofm-walk"
    out = _skeleton(tmp_path, take / "dynamic.c3d", "--static", str(take / "static.c3d"))
    text = out.read_text()
    assert "no leg landmarks named in it" in text and "landmarks." not in text
    assert load_mapping(out).calibration is not None


def test_static_without_a_mapping_out_is_one_line(tmp_path):
    take = DATA / "openofm-walk"
    r = hpcosim("mocap", "inspect", str(take / "dynamic.c3d"), "--static",
                str(take / "static.c3d"))
    assert r.returncode != 0
    assert "--mapping-out" in r.stderr and len(r.stderr.strip().splitlines()) == 1
