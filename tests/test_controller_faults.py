"""Malformed measurements and QP failures: a defined fallback torque and a flag, never an
exception, never a non-finite or out-of-limit torque, never a NaN in the diagnostics."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hp_model.domains import Domain
from prosthesis_controller import (
    ClfConfig,
    ControllerConfig,
    ControllerContext,
    ControllerName,
    Fault,
    ProsthesisMeasurement,
    make_controller,
)
from prosthesis_controller.interface import ControllerMode, QpOutcome
from tests.controller_support import stance_meas, tube_about_nominal


@pytest.fixture(scope="module")
def nominal_x(model, template_gait):
    tr = template_gait.trajectory[Domain.PS]
    i = [model.coord_names.index(c) for c in ("th_pk", "th_pa")]
    return np.r_[tr["q"][i, 5], tr["qd"][i, 5]]


def _check_output(out, limits):
    u = out.torque
    assert u.shape == (2,) and np.all(np.isfinite(u))
    assert abs(u[0]) <= limits[0] and abs(u[1]) <= limits[1]
    d = out.diagnostics
    for v in (d.tau, d.V, d.rho, *d.disturbance, d.since_touchdown):
        assert math.isfinite(v)
    assert d.domain in Domain


BAD = [
    (ProsthesisMeasurement(0.01, float("nan"), 0.1, 0.0, 0.0, 600.0, True), Fault.NON_FINITE),
    (ProsthesisMeasurement(0.01, 0.1, 0.1, float("inf"), 0.0, 600.0, True), Fault.NON_FINITE),
    (ProsthesisMeasurement(float("nan"), 0.1, 0.1, 0.0, 0.0, 600.0, True), Fault.NON_FINITE),
    (ProsthesisMeasurement(0.01, 0.1, 0.1, 0.0, 0.0, float("nan"), True), Fault.NON_FINITE),
    (ProsthesisMeasurement(0.01, 3.5, 0.1, 0.0, 0.0, 600.0, True), Fault.ANGLE_RANGE),
    (ProsthesisMeasurement(0.01, 0.1, -1.2, 0.0, 0.0, 600.0, True), Fault.ANGLE_RANGE),
    (ProsthesisMeasurement(0.01, 0.1, 0.1, 55.0, 0.0, 600.0, True), Fault.SPEED_RANGE),
    (ProsthesisMeasurement(0.01, 0.1, 0.1, 0.0, 0.0, -500.0, True), Fault.LOAD_RANGE),
    (ProsthesisMeasurement(-1.0, 0.1, 0.1, 0.0, 0.0, 600.0, True), Fault.TIME),
    (SimpleNamespace(t=0.01, knee_angle=None, ankle_angle=0.1, knee_vel=0.0, ankle_vel=0.0,
                     foot_load=600.0, contact=True), Fault.TYPE),
    (SimpleNamespace(t=0.01, knee_angle="0.1x", ankle_angle=0.1, knee_vel=0.0, ankle_vel=0.0,
                     foot_load=600.0, contact=True), Fault.TYPE),
    (ProsthesisMeasurement(0.01, 0.1, 0.1, 0.0, 0.0, 600.0, "yes"), Fault.TYPE),  # type: ignore[arg-type]
    (None, Fault.TYPE),
    ({"t": 0.01}, Fault.TYPE),
]


@pytest.mark.parametrize("name", ControllerName)
@pytest.mark.parametrize("bad,flag", BAD)
def test_malformed_measurement_gives_the_fault_fallback(ctx, nominal_x, name, bad, flag):
    ctl = make_controller(name, None, None, None, context=ctx)
    ctl.reset()
    good = ctl.tick(stance_meas(0.0, nominal_x))
    u_prev = good.torque.copy()
    n_prev = good.diagnostics.fallback_count
    out = ctl.tick(bad)
    _check_output(out, ctx.limits)
    d = out.diagnostics
    assert d.fault & flag
    assert d.mode == ControllerMode.FAULT
    assert d.fallback_count == n_prev + 1
    # the fault fallback: the previous torque moved toward zero by at most fallback_rate
    step = ctx.config.safety.fallback_rate
    expected = np.sign(u_prev) * np.maximum(np.abs(u_prev) - step, 0.0)
    np.testing.assert_allclose(out.torque, expected, atol=1e-15)
    assert d.domain == good.diagnostics.domain
    # a valid measurement afterwards is served normally (time must still increase)
    after = ctl.tick(stance_meas(0.002, nominal_x))
    assert after.diagnostics.fault == 0 and after.diagnostics.mode != ControllerMode.FAULT


def test_infeasible_qp_falls_back_toward_pd_rate_limited(model, subsystem, template_gait,
                                                       nominal_x):
    """No relaxation and a tiny rate bound: the robust row cannot be met; the torque moves
    from the previous one toward the stance PD torque by at most fallback_rate."""
    cfg = ControllerConfig(clf=ClfConfig(rho_max=0.0, delta_u=1e-4))
    c = ControllerContext(template_gait, tube_about_nominal(template_gait, (40, 60, 8)), model,
                          cfg, subsystem=subsystem)
    ctl = make_controller("clfqp-paper", None, None, None, context=c)
    pd = make_controller("pd", None, None, None, context=c)
    # the first of a few off-nominal states (growing outputs) whose QP is infeasible
    for k in (1.0, 2.0, 4.0, -1.0, -2.0, -4.0):
        x = nominal_x + k * np.array([-0.05, 0.03, -0.5, 0.5])
        ctl.reset((0.0, 0.0))
        out = ctl.tick(stance_meas(0.0, x))
        if out.diagnostics.qp_status == QpOutcome.INFEASIBLE:
            break
    pd.reset((0.0, 0.0))
    u_pd = pd.tick(stance_meas(0.0, x)).torque
    d = out.diagnostics
    assert d.qp_status == QpOutcome.INFEASIBLE and d.mode == ControllerMode.FALLBACK
    assert d.fallback_count == 1
    step = c.config.safety.fallback_rate
    np.testing.assert_allclose(out.torque, np.clip(u_pd, -step, step), atol=1e-12)
    _check_output(out, c.limits)


finite_or_not = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                          st.floats(-3, 3))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seq=st.lists(st.tuples(st.floats(0.0, 0.01), finite_or_not, finite_or_not,
                              finite_or_not, finite_or_not, st.floats(-200, 2000),
                              st.booleans()), min_size=1, max_size=25))
def test_any_measurement_sequence_gives_bounded_finite_outputs(ctx, seq):
    ctls = [make_controller(n, None, None, None, context=ctx) for n in ControllerName]
    for ctl in ctls:
        ctl.reset()
        t = 0.0
        for dt, qk, qa, vk, va, load, contact in seq:
            t += dt
            out = ctl.tick(ProsthesisMeasurement(t, qk, qa, vk, va, load, contact))
            _check_output(out, ctx.limits)
