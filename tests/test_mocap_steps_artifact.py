"""The steps artifact: round trip in both formats, validation with one-line errors."""

from __future__ import annotations

import io
import json
from dataclasses import replace

import numpy as np
import pytest

import hp_model
from characterization.mocap.mapping import default_mapping
from characterization.mocap.pipeline import process_take, to_artifact
from characterization.mocap.steps_artifact import (
    StepsFileError,
    load_steps,
    save_steps,
    steps_bytes,
)
from characterization.mocap.synthetic_subject import SynthOptions, synthesize
from hp_model.domains import PAPER_DOMAINS


@pytest.fixture(scope="module")
def artifact():
    model = hp_model.load_model()
    s = synthesize(model, SynthOptions(n_strides=4, seed=1))
    coef = {d: model.hip_progress_coefficients(d) for d in PAPER_DOMAINS}
    return to_artifact(process_take(s.take, default_mapping(), coef))


@pytest.mark.parametrize("ext", [".npz", ".json"])
def test_round_trip(artifact, tmp_path, ext) -> None:
    p = tmp_path / f"steps{ext}"
    save_steps(p, artifact)
    a = load_steps(p)
    assert a.n_steps == artifact.n_steps >= 6
    np.testing.assert_array_equal(a.step_domain, artifact.step_domain)
    np.testing.assert_allclose(a.q, artifact.q)
    np.testing.assert_allclose(a.tau, artifact.tau)
    for i in range(a.n_steps):
        tau = a.step_tau(i)
        assert len(tau) == len(a.step_q(i))
        assert tau[0] == pytest.approx(0) and tau[-1] == pytest.approx(1)
    assert [x.name for x in tmp_path.iterdir()] == [p.name]  # no temp file left


def test_npz_is_numpys_zip_with_the_same_bytes_for_the_same_steps(artifact) -> None:
    """np.load reads every field back exactly; float arrays are stored (zlib gains little
    on them for most of the write's time), the rest deflated; no timestamp in the bytes."""
    import zipfile

    data = steps_bytes("s.npz", artifact)
    assert steps_bytes("other.npz", artifact) == data
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        for f in ("q", "time", "pitch_source", "step_domain", "joint_well_posed"):
            want = np.asarray(getattr(artifact, f))
            np.testing.assert_array_equal(z[f], want)
            assert z[f].dtype == want.dtype
    kinds = {i.filename: i.compress_type for i in zipfile.ZipFile(io.BytesIO(data)).infolist()}
    assert kinds["q.npy"] == kinds["tau.npy"] == zipfile.ZIP_STORED
    assert kinds["pitch_source.npy"] == kinds["step_domain.npy"] == zipfile.ZIP_DEFLATED


def _write_npz(path, d) -> None:
    buf = io.BytesIO()
    np.savez(buf, **d)
    path.write_bytes(buf.getvalue())


def test_wrong_version_missing_field_bad_values(artifact, tmp_path) -> None:
    base = dict(np.load(io.BytesIO(steps_bytes("x.npz", artifact))))
    p = tmp_path / "bad.npz"
    _write_npz(p, {**base, "schema_version": np.array(2)})
    with pytest.raises(StepsFileError, match=r"bad.npz: field 'schema_version': version 2"):
        load_steps(p)
    _write_npz(p, {k: v for k, v in base.items() if k != "tau"})
    with pytest.raises(StepsFileError, match=r"field 'tau' missing"):
        load_steps(p)
    bad = base["step_domain"].copy()
    bad[0] = "ds"
    _write_npz(p, {**base, "step_domain": bad})
    with pytest.raises(StepsFileError, match=r"field 'step_domain'"):
        load_steps(p)
    _write_npz(p, {**base, "tau_offsets": base["tau_offsets"] + 1})
    with pytest.raises(StepsFileError, match=r"field 'tau_offsets'"):
        load_steps(p)
    j = tmp_path / "bad.json"
    j.write_text(json.dumps({"schema_version": 1}))
    with pytest.raises(StepsFileError, match=r"bad.json: field '\w+' missing"):
        load_steps(j)
    j.write_text("{not json")
    with pytest.raises(StepsFileError, match="not a readable steps file"):
        load_steps(j)
    with pytest.raises(StepsFileError, match="unknown steps file extension"):
        save_steps(tmp_path / "x.txt", replace(artifact))
