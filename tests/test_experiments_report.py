"""report.md of ``hpcosim experiments`` / ``hpcosim demo`` (issue 40: it reads for a lab
engineer who has not read the paper): a glossary of its words and symbols, torques in motor
N m with the device's gear ratio (text and Fig. 6's axes), a baseline that never completed a
step marked as such wherever it is compared, and every "NOT reproduced" claim with its
reason.  The metrics are a real ``hpcosim demo`` run's (tests/data/experiments), the claims
judged again by the current code."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hp_model.domains import Domain
from orchestrator.experiments.claims import claims
from orchestrator.experiments.report import render

DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture
def metrics() -> dict[str, Any]:
    m = json.loads((DATA / "experiments" / "metrics_demo.json").read_text())
    m["claims"] = claims(m)
    return m


def _section(text: str, title: str) -> str:
    """The body of the ``## title`` section."""
    body = text.split(f"\n## {title}\n", 1)[1]
    return body.split("\n## ", 1)[0]


def _rows(section: str) -> list[list[str]]:
    """The cells of the section's first table, header and separator left out."""
    lines = [x for x in section.splitlines() if x.startswith("|")]
    return [[c.strip() for c in x.strip("|").split(" | ")] for x in lines[2:]]


def _claim_rows(text: str) -> dict[str, list[str]]:
    """The claims table by claim text."""
    return {r[0]: r for r in _rows(_section(text, "The paper's claims"))}


def test_the_glossary_explains_every_term(metrics):
    """A Terms section, linked from the introduction before any result, explains the
    domains, the phase, V, rho, the CLF-QP, the force tube, the socket force, the knee RMS,
    motor torque and gear ratio, and names every controller the report shows; each table
    row has two cells (no '|' broke it)."""
    text = render(metrics)
    assert text.index("[Terms](#terms)") < text.index("## The paper's claims")
    rows = _rows(_section(text, "Terms"))
    assert all(len(r) == 2 and r[1] for r in rows), rows
    named = {w.strip("`() ") for r in rows for w in r[0].replace("(", ", ").split(", ")}
    for term in (Domain.PS, Domain.PNS, "tau", "V", "rho", "CLF-QP", "force tube", "F_s",
                 "knee RMS", "motor torque", "gear ratio", "never completed a step", "chatter",
                 "fallback ticks", "y1", "y2", "oracle"):
        assert term in named, (term, sorted(named))
    shown = {c for cc in metrics["robustness"]["cases"].values() for c in cc}
    assert shown | {"clfqp-exact"} <= named, shown - named


def test_torques_are_motor_n_m_with_the_gear_ratio(metrics):
    """The units paragraph, before the first number, says the torques are motor-side N m
    and gives each joint's gear ratio and motor limit from the device config; every torque
    the claims table quotes is called a motor torque."""
    from hp_model.config import default_device_path, load_device

    p = load_device(default_device_path()).prosthesis
    text = render(metrics)
    units = text[:text.index("## The paper's claims")]
    assert "**Torques are prosthesis motor torques**" in units
    assert (f"gear ratio knee {p.knee.gear_ratio.value:g}, ankle "
            f"{p.ankle.gear_ratio.value:g}") in units
    assert (f"motor torque limit knee {p.knee.torque_limit.value:g} N m, ankle "
            f"{p.ankle.torque_limit.value:g} N m") in units
    for row in _claim_rows(text).values():
        for i in range(len(row[2])):
            if row[2].startswith("torque", i):
                assert row[2][max(0, i - 6):i] in ("motor ", "motor-"), row[2]


def test_fig6_axes_are_motor_and_joint_torque(model):
    """Fig. 6: the left axes in motor N m, the right ones the joint torque through the
    device's gear ratio (the right axis' limits are the left's times the ratio)."""
    from hp_model.force_tube import load_tube
    from hp_model.gait_artifact import load_gait
    from orchestrator.experiments.figures import fig6_figure, gear_ratios
    from orchestrator.experiments.scenarios import NOMINAL, Scenario, run_scenario

    gait = load_gait(DATA / "controller" / "gait_demo.json", model.parameter_hash())
    tube = load_tube(DATA / "controller" / "tube_demo.json", gait.hash())
    runs = {c: run_scenario(model, gait, tube, Scenario(c, NOMINAL, 1))
            for c in ("clfqp-exact", "clfqp")}
    gear = gear_ratios(model)
    assert gear == (model.device.prosthesis.knee.gear_ratio.value,
                    model.device.prosthesis.ankle.gear_ratio.value)
    fig = fig6_figure(runs, gear)
    fig.canvas.draw()
    main_axes = [a for a in fig.axes if a.get_ylabel().startswith(("knee motor",
                                                                  "ankle motor"))]
    assert len(main_axes) == 2
    for ax, n in zip(main_axes, gear, strict=True):
        assert "N m, motor side" in ax.get_ylabel()
        (sec,) = [c for c in ax.child_axes if "joint torque (N m)" in c.get_ylabel()]
        assert f"= {n:g} x motor (gear ratio)" in sec.get_ylabel()
        np.testing.assert_allclose(sec.get_ylim(), np.multiply(ax.get_ylim(), n))
    from matplotlib import pyplot as plt

    plt.close(fig)


def test_a_baseline_that_never_stepped_is_marked(metrics):
    """In the demo pd falls at t = 0.004 s in two of the three cases, before its first
    touchdown: the robustness table gives its steps (0/20) and says it never completed a
    step, its knee RMS is marked 'no step'; the order claim names it NOT COMPARED with the
    reason in that case and counts the baseline runs actually compared."""
    rb = metrics["robustness"]
    never = [(case, c) for case, cc in rb["cases"].items() for c, s in cc.items()
             if s["steps_completed"] == 0 and not s["success"]]
    assert [c for _, c in never] == ["pd", "pd"]  # the demo's
    text = render(metrics)
    table = {(r[0], r[1]): r for r in _rows(_section(text, "Robustness (Fig. 8)"))}
    assert len(table) == sum(len(cc) for cc in rb["cases"].values())
    for key, r in table.items():
        s = rb["cases"][key[0]][key[1]]
        assert r[2] == f"{s['steps_completed']}/{s['steps_requested']}"
        assert (key in never) == r[5].startswith("**never completed a step**: fell at t = ")
        assert (key in never) == r[3].endswith("s: no step)")
    order = next(c for c in metrics["claims"] if c["id"] == "robust_order")
    row = _claim_rows(text)[order["claim"]]
    per_case = dict(x.split(": ", 1) for x in row[2].split("; ")[:len(rb["cases"])])
    for case, c in never:
        assert f"{c} NOT COMPARED: never completed a step" in per_case[case]
    assert row[2].count("never completed a step") == len(never)
    completed = sum(cc[c]["success"] for cc in rb["cases"].values()
                    for c in rb["controllers"][1:])
    total = len(rb["cases"]) * (len(rb["controllers"]) - 1)
    assert f"{completed} of {total} baseline runs completed their case and were compared" \
        in row[2]
    assert order["headline"].endswith(f"{completed} of {total} baseline runs compared")
    # human-2: neither baseline completed, so the case compares nothing, and says so
    assert per_case["human-2 (seed 2)"].endswith("(no baseline completed: nothing to compare)")


def _failed_like(summary: dict[str, Any], other: dict[str, Any]) -> dict[str, Any]:
    """``summary`` ended as the real failed run ``other`` did."""
    keys = ("steps_completed", "success", "failed", "reason", "fall_reason", "fail_t",
            "fail_tau", "fail_domain", "duration_s")
    return {**summary, **{k: other[k] for k in keys}}


def test_every_claim_not_reproduced_says_why(metrics):
    """Every NOT reproduced row carries its one-sentence reason (``why_not``), a
    reproduced one none: on the demo's metrics (the paper's literal formulation falls) and
    with every other claim made to fail from the demo's own failed runs."""
    text = render(metrics)
    rows = _claim_rows(text)
    for c in metrics["claims"]:
        res = rows[c["claim"]][1]
        assert (res == "reproduced") == c["reproduced"] == (c["why_not"] == "")
    lit = next(c for c in metrics["claims"] if c["id"] == "paper_literal")
    assert not lit["reproduced"]
    assert rows[lit["claim"]][1] == f"**NOT reproduced**: {lit['why_not']}"
    pr = metrics["paper_literal"]["run"]
    assert lit["why_not"].startswith(f"the nominal run fell at t = {pr['fail_t']:.3g} s")
    assert "it fails 3 of 3 perturbed cases" in lit["why_not"]

    m = copy.deepcopy(metrics)
    m["nominal"]["run"] = _failed_like(m["nominal"]["run"], pr)
    m["nominal"]["stable_orbit"] = False
    m["exact_vs_relaxed"]["chatter_ratio_exact_over_relaxed"] = 3.0
    rb = m["robustness"]
    case = "human-2 (seed 2)"
    cc = rb["cases"][case]
    cc["clfqp"] = _failed_like(cc["clfqp"], cc["clfqp-paper"])
    rb["clfqp_succeeds_every_case"] = False
    rb["clfqp_below_each_completed_baseline"][1] = False
    m["claims"] = claims(m)
    why = {c["id"]: c["why_not"] for c in m["claims"]}
    assert all(not c["reproduced"] for c in m["claims"])
    assert why["nominal_stable"].startswith(f"the run fell at t = {pr['fail_t']:.3g} s")
    assert why["relaxed_smooth"] == ("the exact law's chatter is only 3x the relaxed law's "
                                     "(< 5x)")
    fail_t = cc["clfqp-paper"]["fail_t"]
    assert why["robust_success"].startswith(f"{case}: fell at t = {fail_t:.3g} s")
    assert why["robust_order"] == f"{case}: clfqp did not complete"
    rows = _claim_rows(render(m))
    for c in m["claims"]:
        assert rows[c["claim"]][1] == f"**NOT reproduced**: {c['why_not']}"
