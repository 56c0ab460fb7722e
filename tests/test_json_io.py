"""The one JSON encoder (``hp_model.json_io``): non-finite numbers are ``null``, numpy is
converted, a stray NaN is an error; and what the pipeline's stages write (the synthetic
take's options, the steps and QA files, the gait, the tube, the sweep's manifest and report)
parses with a strict parser, JavaScript's rules (no NaN, no Infinity).  The demo's own
files are checked in tests/test_experiments.py (its end-to-end run)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from hp_model import json_io
from hp_model.artifacts import FieldReader
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.force_tube import load_tube, save_tube
from hp_model.gait_artifact import load_gait, save_gait
from hp_model.json_io import dumps, finite_or_none, to_jsonable, write_json
from tests.strict_json import assert_strict_json_files, strict_loads

ROOT = Path(__file__).resolve().parents[1]
DEMO_GAIT = ROOT / "tests/data/controller/gait_demo.json"
DEMO_TUBE = ROOT / "tests/data/controller/tube_demo_v2.json"


def test_non_finite_numbers_are_null_and_numpy_is_converted():
    doc = {Domain.PS: np.array([[1.5, np.inf], [np.nan, -np.inf]]), "f32": np.float32(0.5),
           "i": np.int64(3), "b": np.bool_(True), "t": (math.nan, 2.0, "x", None),
           "nested": [{"x": float("-inf")}], "ints": np.arange(3), "nan64": np.float64("nan")}
    assert to_jsonable(doc) == {
        "ps": [[1.5, None], [None, None]], "f32": 0.5, "i": 3, "b": True,
        "t": [None, 2.0, "x", None], "nested": [{"x": None}], "ints": [0, 1, 2],
        "nan64": None}
    text = dumps(doc, indent=1)
    assert "NaN" not in text and "Infinity" not in text
    assert strict_loads(text)["ps"] == [[1.5, None], [None, None]]
    # finite values are written exactly as the json module writes them
    assert dumps({"a": [0.1, 1e-300, 12345678.9]}) == '{"a": [0.1, 1e-300, 12345678.9]}'


def test_a_stray_nan_is_an_error_not_nan_text(monkeypatch):
    monkeypatch.setattr(json_io, "to_jsonable", lambda v: v)  # a conversion that missed it
    with pytest.raises(ValueError, match="not JSON compliant"):
        json_io.dumps({"x": math.nan})
    with pytest.raises(TypeError):
        dumps({"x": object()})


def test_finite_or_none():
    assert finite_or_none(2) == 2.0 and finite_or_none(np.float32(0.5)) == 0.5
    assert finite_or_none(None) is None and finite_or_none(math.inf) is None
    assert finite_or_none(np.nan) is None


def test_write_json_is_strict_with_a_newline(tmp_path):
    p = tmp_path / "x.json"
    write_json(p, {"a": np.array([1.0, np.nan])})
    assert p.read_text() == '{\n "a": [\n  1.0,\n  null\n ]\n}\n'


def _unbounded_gait():
    """The demo gait with its touchdown bounds off (+inf), as ``gait fit`` makes it."""
    g = load_gait(DEMO_GAIT)
    return dataclasses.replace(g, options={**g.options, "touchdown_slip": math.inf,
                                           "touchdown_pitch_rate": math.inf})


def test_a_gait_with_unbounded_options_is_written_without_infinity(tmp_path):
    """The bounds that are off are written as null and read back as +inf
    (``FieldReader.settings``); the gait's numbers and hash are unchanged."""
    g = _unbounded_gait()
    p = tmp_path / "gait.json"
    save_gait(p, g)
    doc = strict_loads(p.read_text())
    assert doc["options"]["touchdown_slip"] is None
    assert FieldReader(str(p), doc).settings("options") == dict(g.options)
    back = load_gait(p)
    assert back.hash() == g.hash()
    for d in PAPER_DOMAINS:
        np.testing.assert_array_equal(back.theta(d), g.theta(d))
        for k, v in g.trajectory[d].items():
            np.testing.assert_array_equal(back.trajectory[d][k], v)


def test_a_gait_round_trip_keeps_the_unbounded_options(tmp_path):
    """``load_gait`` reads the options with ``FieldReader.settings``: null is +inf again."""
    g = _unbounded_gait()
    save_gait(tmp_path / "gait.json", g)
    assert load_gait(tmp_path / "gait.json").options == dict(g.options)


def test_a_tube_is_written_strictly(tmp_path):
    t = load_tube(DEMO_TUBE)
    save_tube(tmp_path / "tube.json", t)
    strict_loads((tmp_path / "tube.json").read_text())
    back = load_tube(tmp_path / "tube.json")
    np.testing.assert_array_equal(back.upper, t.upper)
    assert back.model_error is not None and t.model_error is not None
    np.testing.assert_array_equal(back.model_error.upper, t.model_error.upper)


def test_committed_json_files_parse_strictly():
    """The committed artifacts (gaits, tubes, Foxglove layout) hold no NaN or Infinity."""
    files = [ROOT / "characterization/data/reference_gait.json",
             *(ROOT / "tests/data").rglob("*.json"), *(ROOT / "examples").rglob("*.json"),
             *(ROOT / "foxglove").rglob("*.json")]
    bad = []
    for f in files:
        try:
            strict_loads(f.read_text())
        except ValueError as e:
            bad.append(f"{f.relative_to(ROOT)}: {e}")
    assert not bad, "\n".join(bad)


@pytest.mark.slow
def test_mocap_stages_write_strict_json(tmp_path, capsys):
    """``mocap synth`` (options.json) and ``mocap process`` to a ``.json`` steps file (NaN in
    unfilled gaps as null) with its QA summary: every file strict, the steps read back."""
    from characterization.mocap.steps_artifact import load_steps
    from orchestrator.cli import main

    synth = tmp_path / "synth"
    assert main(["mocap", "synth", "--out", str(synth), "--steps", "6"]) == 0
    steps = tmp_path / "steps.json"
    assert main(["mocap", "process", str(synth / "take.csv"), "--mapping",
                 str(synth / "mapping.toml"), "--out", str(steps), "--no-figures"]) == 0
    capsys.readouterr()
    written = assert_strict_json_files(tmp_path)
    assert {f.name for f in written} == {"options.json", "steps.json", "steps.qa.json"}
    a = load_steps(steps)
    assert a.n_steps > 0 and np.isnan(a.q).any() == ("null" in steps.read_text())


def test_sweep_manifest_and_report_are_strict(tmp_path):
    """A sweep folder whose runs hold a NaN and a missing number: sweep.json and report.json
    are strict."""
    from orchestrator.sweep.draws import Draw
    from orchestrator.sweep.report import write_report
    from orchestrator.sweep.store import KIND, SCHEMA_VERSION, ResultStore

    st = ResultStore(tmp_path)
    st.write_manifest({"kind": KIND, "schema_version": SCHEMA_VERSION, "artifact_hashes": {},
                       "spec": {"name": "x", "controllers": ["pd"], "families": {"f": {}},
                                "draws": 3, "seed": 0, "steps": 10, "backend": "simulator"},
                       "sessions": []})
    st.results.mkdir()
    base = {"controller": "pd", "family": "f", "session": "s", "seq": 0, "success": True,
            "failed": False, "steps_completed": 10, "duration_s": 5.0, "reason": "",
            "fall_reason": None}
    rows = [{**base, **Draw("f", i).columns(), "key": f"pd/f/{i}", "draw": i,
             "knee_rms_ps_rad": rms} for i, rms in enumerate([0.001, math.nan, None])]
    st.write_part(rows, "s", 0)
    write_report(tmp_path)
    assert {f.name for f in assert_strict_json_files(tmp_path)} == {"sweep.json",
                                                                    "report.json"}
