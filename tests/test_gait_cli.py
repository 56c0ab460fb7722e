"""``hpcosim gait fit`` end to end on the synthetic subject (issue 4)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.test_cli import run

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def steps_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("gaitcli")
    r = run("mocap", "synth", "--out", str(d), "--seed", "1")
    assert r.returncode == 0, r.stderr
    r = run("mocap", "process", str(d / "take.csv"), "--out", str(d / "steps.npz"),
            "--no-figures")
    assert r.returncode == 0, r.stderr
    return d / "steps.npz"


def test_ipopt_failure_is_reported_and_writes_nothing(steps_file, tmp_path):
    out = tmp_path / "gait.json"
    r = run("gait", "fit", str(steps_file), "--out", str(out), "--max-iter", "3")
    assert r.returncode == 2
    assert "IPOPT status 'Maximum_Iterations_Exceeded'" in r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists() and not list(tmp_path.iterdir())


def test_fit_writes_a_verified_gait(steps_file, tmp_path, model):
    out = tmp_path / "gait.json"
    r = run("gait", "fit", str(steps_file), "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "gait.png").stat().st_size > 10_000
    doc = json.loads(out.read_text())
    assert doc["kind"] == "hpcosim-gait" and doc["model_hash"] == model.parameter_hash()
    v = doc["verification"]
    assert v["stable_20_steps"] and v["spectral_radius"] < 1
    # the regression reproduces the recorded steps to within mocap noise + model mismatch
    for d in ("ps", "pns"):
        assert max(doc["domains"][d]["fit"]["rms"]) < np.radians(8)
        # optimized outputs close to the data: reported; on this subject about 1-4 deg
        assert max(v["output_rms_deg"][d]) < 5.0
