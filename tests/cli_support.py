"""What the command-line tests share: the CLI run as a user runs it, the one-line negative
result, and the co-simulation tests' FMU, gait and tube with their controllers compiled."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from hp_model.force_tube import save_tube

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "controller"
GAIT, TUBE = DATA / "gait_demo.json", DATA / "tube_demo_v2.json"


def hpcosim(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """The command line as a user runs it (a process of its own, in ``cwd``)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    return subprocess.run([sys.executable, "-m", "orchestrator.cli", *args], cwd=cwd,
                          env=env, capture_output=True, text=True, timeout=600)


def negative_line(r: subprocess.CompletedProcess, *words: str) -> str:
    """Exit 1 and one line on stderr, ``hpcosim: check failed: ...`` with ``words``."""
    assert r.returncode == 1, (r.returncode, r.stdout[-2000:], r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hpcosim: check failed: "), r.stderr
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def cosim_files(tmp_path_factory, model, template_gait):
    """The co-simulation tests' FMU, gait and tube (tests/test_cosim.py's)."""
    from prosthesis_controller.node import build_controller
    from tests.controller_support import tube_about_nominal
    from tests.fmu_support import built_fmu

    fmu, gait = built_fmu(tmp_path_factory, model, template_gait)
    tube = tmp_path_factory.mktemp("outcome") / "tube.json"
    save_tube(tube, tube_about_nominal(template_gait, (0.1, 0.15, 0.02)))
    # the controllers compiled once here, in the session's cache: the controller processes
    # then start in seconds, well within their start timeout, on a cold cache too
    for name in ("clfqp", "pd"):
        build_controller(name, str(gait), str(tube)).reset()
    return {"fmu": fmu, "gait": gait, "tube": tube}
