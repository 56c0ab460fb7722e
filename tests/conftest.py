"""Shared fixtures: the default model and subsystem are built and compiled once per session."""

from __future__ import annotations

import numpy as np
import pytest

import hp_model
from hp_model import HumanProsthesisModel, ProsthesisSubsystem


@pytest.fixture(scope="session")
def model() -> HumanProsthesisModel:
    return hp_model.load_model()


@pytest.fixture(scope="session")
def subsystem(model: HumanProsthesisModel) -> ProsthesisSubsystem:
    return ProsthesisSubsystem(model)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20201025)


def random_state(model, rng, on_socket: bool = True, scale: float = 0.4):
    """A random posture about upright and random velocities; q_f = 0 if ``on_socket``."""
    q = rng.normal(scale=scale, size=model.nq)
    q[1] += 0.9
    qd = rng.normal(scale=1.0, size=model.nq)
    if on_socket:
        q[7:10] = 0.0
        qd[7:10] = 0.0
    return q, qd


@pytest.fixture(scope="session")
def template_gait(model):
    """A converged gait of the default model, optimized once per session from a human-like
    template (about 20 s)."""
    from characterization.gait_design import build_gait
    from characterization.phzd import PHZDOptions, optimize_gait
    from tests.gait_template import template_targets

    # the paper's cost and IPOPT's adaptive barrier: the gait the controller, FMU and
    # co-simulation tests were written against
    opt = PHZDOptions(w_offset=0.0, mu_strategy="adaptive")
    targets = template_targets()
    result = optimize_gait(model, targets, opt)
    assert result.success, result.status
    return build_gait(model, result, targets, opt)


@pytest.fixture(scope="module")
def ctx(model, subsystem, template_gait):
    """A controller context on the template gait with a +/-(40 N, 60 N, 8 N m) tube about
    its nominal socket force."""
    from prosthesis_controller import ControllerContext
    from tests.controller_support import tube_about_nominal

    return ControllerContext(template_gait, tube_about_nominal(template_gait, (40, 60, 8)),
                             model, subsystem=subsystem)
