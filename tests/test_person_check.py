"""The person check (characterization.gait.person_check) with the GATK treadmill take as the
person: its plate's stance forces and its lab's joint angles (refresults) over a stride.  A
gait equal to the take passes; each criterion, broken alone by a margin beyond its limit,
fails by name with its numbers, and within the limit passes."""

from __future__ import annotations

import io
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console
from scipy.io import loadmat

from characterization.gait.person_check import (
    StanceForce,
    WalkSummary,
    check_person,
    cop_heel_to_toe,
    hump,
    print_check,
)
from characterization.mocap.force_plates import plate_walk, read_gatk_plate, stances

DATA = Path(__file__).parent / "data" / "gatk-walking"
BW = 67.2 * 9.81


@pytest.fixture(scope="module")
def person() -> WalkSummary:
    rec = read_gatk_plate(DATA / "rawdata.txt")
    walk = plate_walk(rec, BW)
    s = walk.stances["right"][0]
    (td, _), (td2, _) = stances(rec.feet["right"])
    ref = loadmat(DATA / "refresults.mat")["refresults"]
    t = rec.feet["right"].time
    cyc = np.linspace(td, td2, 101)
    angles = {j: np.degrees(np.interp(cyc, t, ref[:, k])) for j, k in
              (("hip", 0), ("knee", 1), ("ankle", 2))}
    return WalkSummary(speed=0.98, stride_time=walk.stride_time, double_supports=(0.13, 0.13),
                       joint_angles=angles,
                       grf={"right": StanceForce(s.fx_bw * BW, s.fz_bw * BW,
                                                 0.02 + 0.22 * np.linspace(0, 1, 101),
                                                 (0.0, 0.26))},
                       body_weight=BW, source="gatk")


def test_the_take_itself_is_the_persons_gait(person) -> None:
    c = check_person(person, replace(person, source="same"))
    assert c.passed, c.verdict()
    names = [r.criterion for r in c.rows]
    assert names[:4] == ["mean speed", "stride time", "double support 1", "double support 2"]
    assert {"hip RMS", "knee RMS", "ankle RMS", "right F_z correlation",
            "right required friction", "right CoP heel to toe"} <= set(names)
    json.dumps(c.to_json())  # JSON-able


@pytest.mark.parametrize(("change", "name"), [
    ({"speed": 0.98 * 1.12}, "mean speed"), ({"speed": 0.98 * 0.88}, "mean speed")])
def test_speed_beyond_ten_percent_fails_by_name(person, change, name) -> None:
    c = check_person(person, replace(person, **change))
    assert not c.passed and [r.criterion for r in c.failures] == [name]
    assert "limit 10" in c.verdict()
    assert check_person(person, replace(person, speed=0.98 * 1.08)).passed


def test_double_support_within_30_ms(person) -> None:
    g = replace(person, double_supports=(0.13 + 0.025, 0.13 - 0.035))
    c = check_person(person, g)
    assert [r.criterion for r in c.failures] == ["double support 2"]
    assert c.failures[0].error == pytest.approx(35.0)
    # the paper's two domains: no double support at all
    c2 = check_person(person, replace(person, double_supports=()))
    assert {r.criterion for r in c2.failures} == {"double support 1", "double support 2"}


def test_a_joint_off_by_a_constant_fails_beyond_3_deg(person) -> None:
    knee = person.joint_angles["knee"]
    ok = replace(person, joint_angles={**person.joint_angles, "knee": knee + 2.9})
    bad = replace(person, joint_angles={**person.joint_angles, "knee": knee + 3.1})
    assert check_person(person, ok).passed
    c = check_person(person, bad)
    assert [r.criterion for r in c.failures] == ["knee RMS"]
    assert c.failures[0].error == pytest.approx(3.1)


def test_ground_force_shape_and_peaks(person) -> None:
    s = person.grf["right"]
    flat = StanceForce(s.fx, np.full_like(s.fz, BW * 0.95), s.cop_x, s.sole)
    c = check_person(person, replace(person, grf={"right": flat}))
    assert "right F_z correlation" in {r.criterion for r in c.failures}
    # the same shape 20 % of body weight higher: correlation 1, both peaks fail
    high = StanceForce(s.fx, s.fz + 0.2 * BW, s.cop_x, s.sole)
    names = {r.criterion for r in check_person(person, replace(person,
                                                               grf={"right": high})).failures}
    assert {"right F_z first peak", "right F_z second peak"} <= names


def test_the_gaits_own_forces_cop_and_friction(person) -> None:
    s = person.grf["right"]
    heel_edge = StanceForce(s.fx, s.fz, np.full(101, 0.0), s.sole)  # the demo gait's CoP
    ok, travel, why = cop_heel_to_toe(heel_edge, BW)
    assert not ok and travel == 0 and "heel margin" in why
    slippery = StanceForce(s.fx * 3.0, s.fz, s.cop_x, s.sole)  # |F_x|/F_z about 0.6
    c = check_person(person, replace(person, grf={"right": slippery}))
    assert "right required friction" in {r.criterion for r in c.failures}
    c2 = check_person(person, replace(person, grf={}))
    assert {"right F_z", "ground forces"} <= {r.criterion for r in c2.failures}


def test_the_table_and_verdict_print(person) -> None:
    buf = io.StringIO()
    print_check(Console(file=buf, width=140), check_person(person, replace(person, speed=0.5)))
    out = buf.getvalue()
    assert "mean speed" in out and "FAIL" in out and "not the person's gait" in out


def test_a_double_hump_is_told_from_an_impact_spike(person) -> None:
    """The GATK plate's stance is a double hump (1.05 / 0.87 / 1.06 BW); a force that starts
    on its largest value (a rigid heel strike's, 1.8 BW) is not, nor a flat one; with no
    plates on the take side the gait's peaks are shown, not judged."""
    fz = person.grf["right"].fz / BW
    p1, valley, p2, two = hump(fz)
    assert two and p1 == pytest.approx(1.05, abs=0.02) and p2 == pytest.approx(1.06, abs=0.02)
    assert valley == pytest.approx(0.87, abs=0.02)
    spike = np.r_[1.8, np.linspace(1.2, 0.8, 50), np.linspace(0.8, 1.1, 40), np.zeros(10)]
    assert not hump(spike)[3]
    assert not hump(np.full(101, 1.0))[3]
    no_plates = replace(person, grf={})
    rows = {r.criterion: r for r in check_person(no_plates, person).rows}
    assert rows["right F_z peaks"].passed is None
    assert "a double hump" in rows["right F_z peaks"].note
