"""Shared fixtures: the default model and subsystem are built and compiled once per session."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import hp_model
from hp_model import HumanProsthesisModel, ProsthesisSubsystem
from hp_model.domains import DOMAINS
from tests.committed_gaits import load_committed


@pytest.fixture(scope="session", autouse=True)
def private_cache(tmp_path_factory) -> Iterator[Path]:
    """A cache of compiled models and FMUs for this session only (HPCOSIM_CACHE, inherited by
    the CLI and controller processes the tests start): the suite never reads or writes the
    user's ~/.cache/hpcosim, and never reuses a build from another checkout."""
    path = tmp_path_factory.mktemp("hpcosim-cache")
    before = os.environ.get("HPCOSIM_CACHE")
    os.environ["HPCOSIM_CACHE"] = str(path)
    yield path
    if before is None:
        os.environ.pop("HPCOSIM_CACHE", None)
    else:
        os.environ["HPCOSIM_CACHE"] = before


@pytest.fixture(scope="session")
def model() -> HumanProsthesisModel:
    return hp_model.load_model()


@pytest.fixture(scope="session")
def subsystem(model: HumanProsthesisModel) -> ProsthesisSubsystem:
    return ProsthesisSubsystem(model)


@pytest.fixture(scope="module")
def coef(model) -> dict[str, tuple[float, float]]:
    """The model's hip-progress coefficients per domain (what mocap processing takes)."""
    return {d: model.hip_progress_coefficients(d) for d in DOMAINS}


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
    """The quick template gait (ps about 0.3 s), committed test data (tests/data/gaits,
    regenerated and checked by tests/test_phzd.py), checked to walk."""
    return load_committed(model, "template")


@pytest.fixture(scope="session")
def regenerated(model):
    """``regenerated(name)``: the committed gait ``name`` made anew by its recipe, once per
    session (the solve is shared by the tests that check it)."""
    from tests.committed_gaits import regenerate

    made: dict = {}

    def get(name: str):
        if name not in made:
            made[name] = regenerate(name, model)
        return made[name]

    return get


@pytest.fixture(scope="session")
def playback_gait(model):
    """The playback tests' gait (ps about 0.8 s), committed test data, checked to walk."""
    return load_committed(model, "playback")


@pytest.fixture(scope="session")
def demo_gait(model):
    """The demo subject's gait, committed test data, checked to walk."""
    return load_committed(model, "demo")


@pytest.fixture(scope="module")
def ctx(model, subsystem, template_gait):
    """A controller context on the template gait with a +/-(40 N, 60 N, 8 N m) tube about
    its nominal socket force."""
    from prosthesis_controller import ControllerContext
    from tests.controller_support import tube_about_nominal

    return ControllerContext(template_gait, tube_about_nominal(template_gait, (40, 60, 8)),
                             model, subsystem=subsystem)
