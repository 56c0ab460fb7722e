"""Shared fixtures: the default model and subsystem are built and compiled once per session."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import hp_model
from hp_model import HumanProsthesisModel, ProsthesisSubsystem
from hp_model.domains import PAPER_DOMAINS
from tests.committed_gaits import load_committed


@pytest.fixture(scope="session", autouse=True)
def private_cache(tmp_path_factory) -> Iterator[Path]:
    """A cache of compiled models and FMUs for this test run only (HPCOSIM_CACHE, inherited by
    the CLI and controller processes the tests start): the suite never reads or writes the
    user's ~/.cache/hpcosim, and never reuses a build from another checkout.  The parallel
    workers of one run (pytest-xdist) share it, in the run's own temporary folder, and so do
    the two phases of ``make test`` (``HPCOSIM_TEST_CACHE``, a folder it makes for the run):
    each library and FMU is built once per run (the builders lock and rename, so a worker
    waits for another's build and never sees half of it)."""
    if os.environ.get("HPCOSIM_TEST_CACHE"):
        # make test's two phases (Makefile): a folder it made for this run, removed after
        path = Path(os.environ["HPCOSIM_TEST_CACHE"])
        path.mkdir(parents=True, exist_ok=True)
    elif os.environ.get("PYTEST_XDIST_WORKER"):
        # <run's basetemp>/popen-gwN is this worker's; its parent is the run's, shared
        path = tmp_path_factory.getbasetemp().parent / "hpcosim-cache"
        path.mkdir(exist_ok=True)
    else:
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
    return {d: model.hip_progress_coefficients(d) for d in PAPER_DOMAINS}


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


# --------------------------------------------------------------- parallel runs (pytest-xdist)

#: ``make test`` runs the tests not marked ``serial`` on pytest-xdist workers with
#: ``--dist loadfile``: the tests of one file go to one worker (its module fixtures are built
#: once), except the tests named here (a file, or one test), which form the group given
#: (:func:`pytest_xdist_make_scheduler`).  test_phzd checks the template gait's optimization
#: that test_committed_gaits[template] reruns (the session fixture ``regenerated``): one
#: worker solves it once for both.  The other two recipes are each heavy enough to go beside
#: the rest of their file.
XDIST_GROUPS = {
    "tests/test_phzd.py": "template-gait",
    "tests/test_committed_gaits.py::test_recipe_makes_the_committed_gait[template]":
        "template-gait",
    "tests/test_committed_gaits.py::test_recipe_makes_the_committed_gait[reference]":
        "reference-gait",
    "tests/test_committed_gaits.py::test_recipe_makes_the_committed_gait[playback]":
        "playback-gait",
}

#: The heaviest groups' cost (s of one core, from ``--durations``, setup included, on a loaded
#: machine): workers take groups in this order, longest first, and the short files fill in at
#: the end.  Only the order depends on it (a group missing here goes after these, in
#: collection order).
XDIST_COST: dict[str, float] = {
    "tests/test_experiments.py": 300,  # hpcosim demo end to end
    "tests/test_sweep.py": 160,
    "tests/test_gait_cli.py": 100,
    "tests/test_controller_closed_loop.py": 100,
    "template-gait": 80,
    "playback-gait": 65,
    "tests/test_sweep_families.py": 60,
    "tests/test_fmu_build.py": 50,
    "reference-gait": 45,
    "tests/test_animation.py": 40,
    "tests/test_fmu_equivalence.py": 30,
    "tests/test_cosim.py": 25,  # its tests that are not serial
    "tests/test_model_error.py": 22,
    "tests/test_playback_truth.py": 18,
    "tests/test_mocap_checks.py": 18,
    "tests/test_mocap_readers.py": 16,
    "tests/test_mocap_synthetic.py": 16,
    "tests/test_playback_cli.py": 16,
    "tests/test_fmu_multicontact.py": 40,  # the multi-contact FMU's build and walks
    "tests/test_person_walks.py": 30,
    "tests/test_contact_tube.py": 45,  # the multi-contact closed loop's build, 2 playbacks
    "tests/test_sweep_contact.py": 65,  # a Dask worker's set-up, 12 runs, 3 replays
    "tests/test_person_synth.py": 110,  # the person's walk, its take processed and fitted
    "tests/test_person_reference.py": 80,  # the packaged person's recipe, processed and fitted
    "tests/test_gait_tables.py": 10,
    "tests/test_take_closure.py": 30,  # the packaged person's walk, its take processed
}


def xdist_group(nodeid: str) -> str:
    """The group of the test ``nodeid`` in a parallel run: its file, unless
    :data:`XDIST_GROUPS` names it (or its file)."""
    nodeid = nodeid.split("@", 1)[0]
    path = nodeid.split("::", 1)[0]
    return XDIST_GROUPS.get(nodeid) or XDIST_GROUPS.get(path) or path


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """``--dist loadfile`` with the groups of :func:`xdist_group` (xdist's own ``loadgroup``
    marks the test ids, which pytest 9 no longer lets a plugin change)."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class GroupScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return xdist_group(nodeid)

    return GroupScheduling(config, log)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """On a worker, the collection in :data:`XDIST_COST` order (the scheduler hands out the
    groups in the order of the collection, with ``--no-loadscope-reorder``)."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return  # one process: the files' order, unchanged
    group = {it.nodeid: xdist_group(it.nodeid) for it in items}
    first_seen = {g: i for i, g in enumerate(dict.fromkeys(group.values()))}
    items.sort(key=lambda it: (-XDIST_COST.get(group[it.nodeid], 0.0),
                               first_seen[group[it.nodeid]]))
