"""Closed-loop scenarios and the Sec. V experiments (numbers, not snapshots)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hp_model.simulator import SimState
from orchestrator.scenarios import (
    NOMINAL,
    Perturbation,
    Scenario,
    measurement,
    run_scenario,
    simulated_tube,
    summary,
)


@pytest.fixture(scope="module")
def tube(model, template_gait):
    t, _prof = simulated_tube(model, template_gait, 6)
    return t


def test_measurement_is_prosthesis_only():
    q, qd = np.arange(12.0), -np.arange(12.0)
    lam = np.array([1.0, 700.0, 0, 5, 6, 7])
    m = measurement((10, 11), 0.5, SimState(0.5, "ps", q, qd, 0.3, lam, 0))
    assert (m.knee_angle, m.ankle_angle, m.knee_vel, m.ankle_vel) == (10, 11, -10, -11)
    assert m.foot_load == 700.0 and m.contact
    m = measurement((10, 11), 0.5, SimState(0.5, "pns", q, qd, 0.3, lam, 0))
    assert m.foot_load == 0.0 and not m.contact


def test_run_scenario_consistent(model, template_gait, tube):
    r = run_scenario(model, template_gait, tube, Scenario("clfqp", NOMINAL, 1))
    n = r.t.size
    assert n > 10 and r.q_p.shape == (n, 2) and r.torque.shape == (n, 2)
    assert np.all(np.isfinite(r.torque)) and len(r.mode) == n
    assert r.success == (not r.failed and r.steps >= 1)
    if r.failed:
        assert r.fail_tau is not None and r.fail_domain in ("ps", "pns")
    # at t = 0 the state is the gait's: knee error is the collocation error only
    assert abs(r.q_p[0, 0] - r.knee_ref[0]) < 0.05
    s = summary(r)
    assert math.isclose(s["knee_rms_ps_rad"], r.knee_rms("ps"))


def test_perturbation_changes_the_human_only(template_gait):
    p = Perturbation("x", 0.01, 3)
    th = p.thetas(template_gait)
    assert not np.allclose(th["ps"], template_gait.theta("ps"))
    np.testing.assert_array_equal(th["ps"][-3:], template_gait.theta("ps")[-3:])


@pytest.mark.slow
def test_demo_quick_end_to_end(tmp_path):
    from orchestrator.cli import main

    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--quick"]) == 0
    for f in ("gait.json", "tube.json", "metrics.json", "report.md", "fig6_torques.png",
              "fig7_phase_portraits.png", "fig8_robustness.png"):
        assert (out / f).stat().st_size > 0, f
    m = json.loads((out / "metrics.json").read_text())
    assert m["schema_version"] == 1 and m["steps"] == 3
    run = m["nominal"]["run"]
    assert run["success"] == (not run["failed"] and run["steps_completed"] >= 3)
    e = m["exact_vs_relaxed"]
    a, b = e["clfqp-exact"]["chatter_rate_Nm_per_s"], e["clfqp"]["chatter_rate_Nm_per_s"]
    if a is not None and b:
        assert math.isclose(e["chatter_ratio_exact_over_relaxed"], a / b, rel_tol=1e-9)
    rb = m["robustness"]
    assert len(rb["cases"]) == 3
    for cc in rb["cases"].values():
        assert set(cc) == {"clfqp", "passive", "pd"}
        for s in cc.values():
            assert s["knee_rms_ps_rad"] is None or s["knee_rms_ps_rad"] >= 0
            if s["failed"]:
                assert s["fail_tau"] is not None and s["reason"]
    order = [cc["clfqp"]["knee_rms_ps_rad"] < cc["passive"]["knee_rms_ps_rad"]
             < cc["pd"]["knee_rms_ps_rad"] for cc in rb["cases"].values()]
    assert rb["knee_rms_order_clfqp_lt_passive_lt_pd"] == order
    assert rb["clfqp_succeeds_every_case"] == all(cc["clfqp"]["success"]
                                                  for cc in rb["cases"].values())
    claims = {c["id"]: c for c in m["claims"]}
    assert set(claims) == {"nominal_stable", "relaxed_smooth", "robust_order",
                           "robust_success"}
    assert claims["robust_success"]["reproduced"] == rb["clfqp_succeeds_every_case"]
    report = (out / "report.md").read_text()
    for c in m["claims"]:
        assert c["claim"] in report
    assert "NOT reproduced" in report or all(c["reproduced"] for c in m["claims"])
