"""The controllers' defaults on the default subject: along the nominal stance of the gait
fitted from the default synthetic subject, with the force tube fitted from that subject's own
steps (tests/data/controller/NOTICE.md), every controller keeps to its normal mode on every
1 kHz tick.  For the relaxed robust CLF-QP that means its QP stays feasible: the paper adds
rho "to ensure the QP is always solvable", and rho_max must be large enough for a realistic
tube (measured: the largest rho used is 3.7e3; with the former default rho_max = 100, 30 % of
the ticks were infeasible and fell back)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hp_model.force_tube import load_tube
from prosthesis_controller import (
    ClfConfig,
    ControllerConfig,
    ControllerContext,
    ControllerName,
    make_controller,
)
from tests.controller_support import stance_ticks

DATA = Path(__file__).parent / "data" / "controller"
TICKS = 2000  # 1 kHz: two and a half stances of 0.81 s


@pytest.fixture(scope="module")
def demo(model, subsystem, demo_gait):
    gait = demo_gait
    tube = load_tube(DATA / "tube_demo.json", gait.hash())
    return gait, tube


def run_ticks(ctl, meas, u0):
    ctl.reset(u0)
    outs = [ctl.tick(m) for m in meas]
    modes = [o.diagnostics.mode for o in outs]
    return outs, modes


@pytest.mark.parametrize("name", ControllerName)
def test_defaults_keep_every_controller_in_stance_on_the_default_subject(model, subsystem,
                                                                        demo, name):
    gait, tube = demo
    ctx = ControllerContext(gait, tube, model, subsystem=subsystem)
    ctl = make_controller(name, None, None, None, context=ctx)
    outs, modes = run_ticks(ctl, *stance_ticks(model, gait, TICKS))
    if name == "clfqp-exact":
        # no relaxation: where the hard CLF row and the contact rows cannot hold together
        # (noisy velocities ask for a fast decrease) the QP is infeasible and it falls back
        assert set(modes) <= {"stance", "fallback"}
        assert modes.count("fallback") <= 0.01 * len(modes), modes.count("fallback")
        assert {o.diagnostics.qp_status for o in outs if o.diagnostics.mode == "fallback"} \
            <= {"failed"}
    else:
        assert set(modes) == {"stance"}, {m: modes.count(m) for m in set(modes)}
    u = np.array([o.torque for o in outs])
    assert np.all(np.isfinite(u)) and np.all(np.abs(u) <= np.array(ctx.limits) + 1e-12)
    if name == "clfqp-paper":
        rho = np.array([o.diagnostics.rho for o in outs])
        assert np.all(rho <= ctx.config.clf.rho_max)
        assert rho.max() > 100.0  # the former default would not have been enough
    if name == "clfqp":  # the interaction-aware relaxed QP: solved on every tick
        assert {o.diagnostics.qp_status for o in outs} == {"solved"}


def test_former_rho_max_made_the_relaxed_qp_infeasible_on_the_default_subject(model,
                                                                               subsystem,
                                                                               demo):
    gait, tube = demo
    cfg = ControllerConfig(clf=ClfConfig(rho_max=100.0))
    ctx = ControllerContext(gait, tube, model, cfg, subsystem=subsystem)
    ctl = make_controller("clfqp-paper", None, None, None, context=ctx)
    outs, modes = run_ticks(ctl, *stance_ticks(model, gait, TICKS))
    fallback = modes.count("fallback") / len(modes)
    assert fallback > 0.1, fallback
    assert {o.diagnostics.qp_status for o in outs if o.diagnostics.mode == "fallback"} \
        == {"infeasible"}
