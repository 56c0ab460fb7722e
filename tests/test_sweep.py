"""Robustness sweeps: spec validation, pure draws, the run function on both backends, the
results store, the report's statistics, and the Dask engine (1 vs 2 workers, a worker
killed mid-sweep, an interrupted sweep resumed).

The Dask tests run real LocalClusters (worker processes, loopback) on a small sweep of the
stored synthetic-subject gait (every run falls in the first stance today; the sweep records
that as it is)."""

from __future__ import annotations

import json
import math
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binomtest

from hp_model import bezier
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.falls import Fall, FallReason
from hp_model.force_tube import save_tube
from orchestrator.sweep.draws import SEED_LIMIT, Draw, RunKey, make_draw, run_keys
from orchestrator.sweep.replay import TAU_COLUMNS, compare_rows
from orchestrator.sweep.report import (
    UNLABELLED,
    fall_label,
    mcnemar_exact,
    summarize,
    wilson_interval,
)
from orchestrator.sweep.runs import (
    Artifacts,
    Resources,
    erroneous_model,
    human_thetas,
    run_draw,
    scaled_tube,
)
from orchestrator.sweep.spec import SpecError, load_spec
from orchestrator.sweep.store import (
    KIND,
    SCHEMA_VERSION,
    VOLATILE,
    ResultStore,
    done_keys,
    read_results,
)
from tests.controller_support import tube_about_nominal

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT / "tests" / "data" / "playback" / "gait_synthetic.json"

SPEC = """
name = "test"
gait = "{gait}"
tube = "{tube}"
controllers = ["clfqp", "passive", "pd"]
draws = {draws}
seed = 7
steps = 1
batch = 4
label_walkable = false  # the oracle has its own tests (test_sweep_families.py)

[families.nominal]

[families.mixed]
human.bezier_amplitude = {{ dist = "uniform", low = 0.0, high = 0.02 }}
human.output_offset = {{ dist = "normal", mean = 0.0, std = 0.01 }}
socket.tube_scale = {{ dist = "uniform", low = 1.0, high = 3.0 }}
initial.knee = {{ dist = "uniform", low = -0.03, high = 0.03 }}

[families.wild]   # an unbounded amplitude: negative draws are run errors
human.bezier_amplitude = {{ dist = "normal", mean = 0.0, std = 0.01 }}
"""


@pytest.fixture(scope="module")
def gait(playback_gait):
    return playback_gait


@pytest.fixture(scope="module")
def files(tmp_path_factory, gait):
    d = tmp_path_factory.mktemp("sweep")
    tube = d / "tube.json"
    save_tube(tube, tube_about_nominal(gait, (40.0, 60.0, 8.0)))
    return d, tube


def write_spec(path: Path, tube: Path, draws: int = 3, extra: str = "") -> Path:
    path.write_text(SPEC.format(gait=GAIT, tube=tube, draws=draws) + extra)
    return path


@pytest.fixture(scope="module")
def spec_path(files):
    d, tube = files
    return write_spec(d / "spec.toml", tube)


# ------------------------------------------------------------------ spec

@pytest.mark.parametrize("body, field", [
    ('controllers = ["clfqp", "bogus"]', "controllers"),
    ("draws = 0", "draws"),
    ('families.x.human.bezier_amplitude = { dist = "uniform", low = -0.1, high = 0.1 }',
     "families.x.human.bezier_amplitude"),
    ('families.x.model.mass_scale = { dist = "uniform", low = 0.9, high = 1.1 }',
     "families.x.model.mass_scale"),
    ("families.x.socket.tube_scale = 0", "families.x.socket.tube_scale"),
    ('families.x.initial.knee = { dist = "uniform", low = 1.0, high = 0.0 }',
     "families.x.initial.knee"),
    ("families.x.human.amplitude = 0.1", "families.x.human.amplitude"),
    ('families."a/b" = {}', "families"),
    ('backend = "gpu"', "backend"),
    ('tube = "missing.json"', "tube"),
    ("families.x.human.stride_cv = 0.03", "families.x.human.stride_cv"),  # a person's only
    ("families.x.human.stride_cv = -0.01", "families.x.human.stride_cv"),
    ("families.x.plant.armature = 1.5", "families.x.plant.armature"),  # a person's only
])
def test_bad_spec_is_one_line_naming_the_field(tmp_path, files, body, field):
    _, tube = files
    keys = {b.split("=")[0].strip().split(".")[0] for b in [body]}
    base = {"gait": f'"{GAIT}"', "tube": f'"{tube}"', "controllers": '["pd"]', "draws": "2",
            "seed": "1"}
    lines = [f"{k} = {v}" for k, v in base.items() if k not in keys] + [body]
    if not body.startswith("families"):
        lines.append("families.n = {}")
    p = tmp_path / "bad.toml"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(SpecError) as e:
        load_spec(p)
    msg = str(e.value)
    assert "\n" not in msg and f"field '{field}'" in msg, msg


def test_a_paper_gait_without_its_tube_is_refused(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(f'gait = "{GAIT}"\ncontrollers = ["pd"]\ndraws = 2\nseed = 1\n'
                 'families.n = {}\n')
    with pytest.raises(SpecError, match=r"field 'tube': .* force tube") as e:
        load_spec(p)
    assert "\n" not in str(e.value)


def test_cli_bad_spec_exit_2_no_output(tmp_path, files, capsys):
    from orchestrator.cli import main

    _, tube = files
    p = write_spec(tmp_path / "s.toml", tube, extra='\n[families.y]\nmodel.com_scale = -1\n')
    out = tmp_path / "out"
    assert main(["sweep", str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "families.y.model.com_scale" in err, err
    assert not out.exists()


# ------------------------------------------------------------------ draws

def test_draws_are_pure_functions_of_seed_family_index(tmp_path, files):
    _, tube = files
    a = load_spec(write_spec(tmp_path / "a.toml", tube, draws=5))
    b = load_spec(write_spec(tmp_path / "b.toml", tube, draws=500,
                             extra="\n[families.other]\ninitial.ankle = 0.01\n"))
    for i in range(5):  # independent of the number of draws and of other families
        assert make_draw(a, "mixed", i) == make_draw(b, "mixed", i)
    d = [make_draw(b, "mixed", i) for i in range(500)]
    assert len({x.bezier_seed for x in d}) == 500
    assert all(0 <= x.bezier_seed < SEED_LIMIT for x in d)
    amp = np.array([x.bezier_amplitude for x in d])
    assert amp.min() >= 0.0 and amp.max() <= 0.02
    # uniform on [0, 0.02]: mean 0.01, sd of the mean 0.0058/sqrt(500) = 2.6e-4 (5 sigma)
    assert abs(amp.mean() - 0.01) < 1.3e-3
    off = np.array([x.output_offset for x in d])
    assert off.shape == (500, 4) and abs(off.std() - 0.01) < 1e-3
    # quantities draw from their own streams: the amplitude does not move the offsets
    assert abs(np.corrcoef(amp, off[:, 0])[0, 1]) < 0.2
    n = make_draw(b, "nominal", 3)
    assert n == Draw("nominal", 3)
    assert make_draw(b, "other", 9).ankle_offset == 0.01
    keys = list(run_keys(a))
    assert len(keys) == a.n_runs == len(set(keys)) == 45
    assert RunKey.parse("clfqp/mixed/4") == RunKey("clfqp", "mixed", 4)
    with pytest.raises(ValueError):
        RunKey.parse("clfqp/mixed")


# ------------------------------------------------------------------ statistics

@pytest.mark.parametrize("k, n", [(0, 10), (3, 10), (10, 10), (57, 200), (1, 1), (199, 200)])
def test_wilson_interval_equals_scipy(k, n):
    lo, hi = wilson_interval(k, n)
    ref = binomtest(k, n).proportion_ci(0.95, method="wilson")
    assert abs(lo - ref.low) < 1e-12 and abs(hi - ref.high) < 1e-12
    assert lo <= k / n <= hi


@pytest.mark.parametrize("b, c", [(0, 0), (0, 4), (3, 9), (10, 2), (25, 25)])
def test_mcnemar_exact_equals_binomial_test(b, c):
    ref = 1.0 if b + c == 0 else binomtest(b, b + c, 0.5).pvalue
    assert abs(mcnemar_exact(b, c) - ref) < 1e-12


def test_report_counts_fall_reasons_from_the_stored_label(tmp_path):
    """The report's failure reasons are the FallReason labels stored with the runs, never
    parsed from the message (here deliberately misleading); a failed row stored before the
    label existed counts as unlabelled."""
    st = ResultStore(tmp_path)
    st.write_manifest({"kind": KIND, "schema_version": SCHEMA_VERSION, "artifact_hashes": {},
                       "spec": {"controllers": ["pd"], "families": {"f": {}}, "draws": 5},
                       "sessions": []})
    st.results.mkdir()
    cone = Fall(FallReason.FRICTION_CONE, 0.25, Domain.PS, 0.5, {"F_x": 300.0, "F_z": 10.0})
    base = {"controller": "pd", "family": "f", "session": "s", "seq": 0, "success": False,
            "failed": True, "steps_completed": 0, "duration_s": 0.2}
    rows = [{**base, **Draw("f", i).columns(), "key": f"pd/f/{i}", "draw": i,
             "reason": cone.message(), "fall_reason": label}
            for i, label in enumerate(["hip-low", "hip-low", "friction-cone", None])]
    rows.append({**base, **Draw("f", 4).columns(), "key": "pd/f/4", "draw": 4,
                 "success": True, "failed": False, "reason": "", "fall_reason": None})
    st.write_part(rows, "s", 0)
    assert read_results(tmp_path)["fall_reason"].to_pylist()[:3] == \
        ["hip-low", "hip-low", "friction-cone"]
    cell = summarize(tmp_path)["cells"][0]
    assert cell["failure_reasons"] == {"hip-low": 2, "friction-cone": 1, UNLABELLED: 1}
    assert fall_label({"fall_reason": FallReason.DIVERGED.label}) == "diverged"


# ------------------------------------------------------------------ applying a draw

def test_output_offsets_shift_the_human_curves_only(gait):
    d = Draw("x", 0, 0.01, 5, (0.02, -0.03, 0.04, 0.05))
    base = human_thetas(gait, Draw("x", 0, 0.01, 5))
    th = human_thetas(gait, d)
    s = np.linspace(0, 1, 11)
    L = gait.params[Domain.PS].layout
    for dom, rows in ((d, d.y2_coords) for d in PAPER_DOMAINS):
        for r, joint in enumerate(rows):
            a0 = base[dom][L.row(r)][None, :]
            a1 = th[dom][L.row(r)][None, :]
            shift = bezier.evaluate(a1, s) - bezier.evaluate(a0, s)
            want = dict(zip(("th_lh", "th_lk", "th_la", "th_rh"), d.output_offset,
                            strict=True)).get(joint, 0.0)  # prosthesis rows unchanged
            np.testing.assert_allclose(shift, want, atol=1e-15)
        np.testing.assert_array_equal(th[dom][L.progress], gait.theta(dom)[L.progress])


def test_scaled_tube_divides_the_deviation_bounds(gait):
    t = tube_about_nominal(gait, (40.0, 60.0, 8.0))
    s = scaled_tube(t, 2.5)
    tau = np.linspace(0, 1, 7)
    lo, hi = t.delta_bounds(tau)
    lo2, hi2 = s.delta_bounds(tau)
    np.testing.assert_allclose(lo2, lo / 2.5)
    np.testing.assert_allclose(hi2, hi / 2.5)
    np.testing.assert_array_equal(s.nominal_force(tau), t.nominal_force(tau))
    with pytest.raises(ValueError):
        scaled_tube(t, -1.0)


def test_erroneous_model_scales_the_prosthesis_mass(model):
    m = erroneous_model(model, 1.2, 0.7, 1.0)
    assert math.isclose(m.prosthesis_mass, 1.2 * model.prosthesis_mass, rel_tol=1e-12)
    assert math.isclose(m.tree.total_mass - m.prosthesis_mass,
                        model.tree.total_mass - model.prosthesis_mass, rel_tol=1e-12)
    assert erroneous_model(model, 1.0, 1.0, 1.0) is model
    with pytest.raises(ValueError):
        erroneous_model(model, -1.0, 1.0, 1.0)


# ------------------------------------------------------------------ one run

@pytest.fixture(scope="module")
def resources(spec_path):
    spec = load_spec(spec_path)
    res = Resources(Artifacts.from_spec(spec))
    yield spec, res
    res.close()


def test_run_draw_row_is_bounded_and_deterministic(resources):
    spec, res = resources
    key = RunKey("clfqp", "mixed", 1)
    draw = make_draw(spec, "mixed", 1)
    row = run_draw(res, spec, key, draw)
    assert row["error"] is None, row["error"]
    assert row["torque_finite"] is True
    lim = res.context0.limits
    assert row["max_torque_knee"] <= lim[0] + 1e-9 and row["max_torque_ankle"] <= lim[1] + 1e-9
    assert row["success"] == (not row["failed"] and row["steps_completed"] >= 1)
    assert 0 < row["knee_rms_ps_rad"] < 0.5  # rad; a run ends at a fall long before that
    again = run_draw(res, spec, key, draw)
    assert {k: v for k, v in row.items() if k not in VOLATILE} == \
        {k: v for k, v in again.items() if k not in VOLATILE}


def test_run_error_is_a_row_not_an_exception(resources):
    spec, res = resources
    row = run_draw(res, spec, RunKey("pd", "wild", 0), Draw("wild", 0, -0.01, 3))
    assert row["error"].startswith("ValueError: amplitude must be finite and >= 0")
    assert row["error_kind"] == "run" and row["success"] is False
    assert row["steps_completed"] is None


@pytest.mark.slow
def test_fmu_backend_equals_simulator(resources, tmp_path):
    """The same draws on the FMU (fmpy, reset per run) give the simulator's rows: the same
    samples, torques and falls; tau-derived numbers to the last bits of tau."""
    from orchestrator.sweep.engine import prepare_fmu

    spec, res = resources
    fspec = spec.model_copy(update={"backend": "fmu"})
    fres = Resources(Artifacts.from_spec(fspec, prepare_fmu(fspec)), tmp_path)
    try:
        for key in (RunKey("clfqp", "mixed", 0), RunKey("pd", "mixed", 2),
                    RunKey("passive", "nominal", 0)):
            draw = make_draw(spec, key.family, key.draw)
            a = run_draw(res, spec, key, draw)
            b = run_draw(fres, fspec, key, draw)
            assert a["error"] is None and b["error"] is None, (a["error"], b["error"])
            assert compare_rows(a, b, across_backends=True) == {}
            exact = {k for k in a if k not in VOLATILE and a[k] != b[k]}
            assert exact <= {"backend", "run_hash", "reason",
                             *TAU_COLUMNS}, exact
            assert a["fail_t"] == b["fail_t"] and a["steps_completed"] == b["steps_completed"]
    finally:
        fres.close()


# ------------------------------------------------------------------ store

def test_store_parts_are_atomic_and_newest_row_wins(tmp_path):
    st = ResultStore(tmp_path)
    st.results.mkdir()
    base = {"controller": "pd", "family": "f", "draw": 0, "success": False}
    st.write_part([{**base, "key": "pd/f/0", "error": "KilledWorker: x",
                    "error_kind": "infrastructure", "session": "s1", "seq": 0},
                   {**base, "key": "pd/f/1", "session": "s1", "seq": 1}], "s1", 0)
    assert done_keys(tmp_path) == {"pd/f/1"}
    st.write_part([{**base, "key": "pd/f/0", "success": True, "session": "s2", "seq": 0}],
                  "s2", 0)
    t = read_results(tmp_path)
    assert t["key"].to_pylist() == ["pd/f/0", "pd/f/1"]
    assert t["success"].to_pylist() == [True, False]
    assert done_keys(tmp_path) == {"pd/f/0", "pd/f/1"}
    assert not [p for p in st.results.iterdir() if p.name.startswith(".")]


def test_output_folder_refuses_another_sweep(tmp_path, files):
    _, tube = files
    a = load_spec(write_spec(tmp_path / "a.toml", tube))
    art = Artifacts.from_spec(a)
    st = ResultStore(tmp_path / "out")
    assert st.check(a, art.hashes(), art.digest()) is None
    assert not st.root.exists()  # checking writes nothing
    st.open(a, art.hashes(), art.digest(), {"gait": art.gait, "tube": art.tube})
    more = load_spec(write_spec(tmp_path / "b.toml", tube, draws=9,
                                extra="\n[families.extra]\ninitial.knee = 0.01\n"))
    assert st.check(more, art.hashes(), art.digest()) is not None  # more draws, a family: ok
    other_seed = load_spec(tmp_path / "b.toml", {"seed": 8})
    with pytest.raises(SpecError, match="other settings"):
        st.check(other_seed, art.hashes(), art.digest())
    c = write_spec(tmp_path / "c.toml", tube)
    c.write_text(c.read_text().replace("high = 0.02", "high = 0.03"))  # family 'mixed'
    with pytest.raises(SpecError, match="family 'mixed'"):
        st.check(load_spec(c), art.hashes(), art.digest())
    loaded = st.spec()  # the manifest's spec points at the copied artifacts
    assert loaded.gait == (st.root / "artifacts" / "gait.json").resolve()
    assert loaded.families == a.families


# ------------------------------------------------------------------ Dask

def stable(rows: list[dict]) -> dict[str, dict]:
    return {r["key"]: {k: v for k, v in r.items() if k not in VOLATILE} for r in rows}


@pytest.fixture(scope="module")
def reference(tmp_path_factory, spec_path):
    """The sweep on 1 worker, through the CLI (report written); rows by key."""
    from orchestrator.cli import main

    out = tmp_path_factory.mktemp("ref") / "out"
    assert main(["sweep", str(spec_path), "--out", str(out), "--workers", "1"]) == 0
    return out, read_results(out).to_pylist()


@pytest.mark.slow
def test_sweep_on_one_worker_completes_with_report(reference, spec_path):

    out, rows = reference
    spec = load_spec(spec_path)
    assert len(rows) == spec.n_runs == 27
    errors = [r for r in rows if r["error"] is not None]
    wild = [make_draw(spec, "wild", i).bezier_amplitude for i in range(spec.draws)]
    assert any(a < 0 for a in wild) and any(a >= 0 for a in wild)  # the spec's premise
    assert {r["key"] for r in errors} == {f"{c}/wild/{i}" for c in spec.controllers
                                          for i, a in enumerate(wild) if a < 0}
    assert all(r["error_kind"] == "run" for r in errors)
    ok = [r for r in rows if r["error"] is None]
    assert all(r["torque_finite"] and r["knee_rms_ps_rad"] is not None for r in ok)
    # the nominal family repeats one run: identical numbers for every draw
    for c in spec.controllers:
        nom = [stable([r])[r["key"]] for r in ok if r["controller"] == c
               and r["family"] == "nominal"]
        assert len({(n["knee_rms_ps_rad"], n["duration_s"]) for n in nom}) == 1
    rep = json.loads((out / "report.json").read_text())
    assert rep["complete"] and len(rep["cells"]) == 9
    for cell in rep["cells"]:
        lo, hi = cell["wilson95"] or (0, 1)
        if cell["success_rate"] is not None:
            assert lo <= cell["success_rate"] <= hi
        for w in cell["worst"]:
            assert w["replay"] == f"hpcosim sweep replay {out} {w['key']}"
    for f in ("report.md", "fig_success.png", "fig_knee_rms.png", "fig_survival.png"):
        assert (out / f).stat().st_size > 0


@pytest.mark.slow
def test_replay_reproduces_a_stored_run(reference, capsys):
    from orchestrator.cli import main

    out, rows = reference
    key = next(r["key"] for r in rows if r["family"] == "mixed" and r["error"] is None)
    assert main(["sweep", "replay", str(out), key]) == 0
    assert "identical to the stored result" in capsys.readouterr().out


@pytest.mark.slow
def test_two_workers_give_identical_rows(reference, spec_path, tmp_path):
    from orchestrator.sweep.engine import Streaming, run_sweep

    _, ref = reference
    o = run_sweep(load_spec(spec_path), tmp_path / "out", workers=2,
                  streaming=Streaming(window=3))
    assert o.status == "completed" and o.workers == 2 and o.done == len(ref)
    rows = read_results(tmp_path / "out").to_pylist()
    assert len({r["worker"] for r in rows if r["error"] is None}) == 2  # both worked
    assert len({r["setup"] for r in rows if r["error"] is None}) == 2  # set up once each
    assert stable(rows) == stable(ref)


@pytest.mark.slow
def test_fmu_backend_sweep_on_dask(reference, spec_path, tmp_path):
    """The FMU travels to the workers in the plugin (no shared file); the rows match the
    simulator's 1-worker rows run for run."""
    from orchestrator.sweep.engine import run_sweep

    _, ref = reference
    spec = load_spec(spec_path, {"backend": "fmu"})
    o = run_sweep(spec, tmp_path / "out", workers=2)
    assert o.status == "completed"
    rows = {r["key"]: r for r in read_results(tmp_path / "out").to_pylist()}
    assert (tmp_path / "out" / "artifacts" / "human.fmu").is_file()
    assert len(rows) == len(ref)
    for r in ref:
        assert compare_rows(r, rows[r["key"]], across_backends=True) == {}, r["key"]


@pytest.mark.slow
def test_killed_worker_loses_no_result(reference, files, tmp_path):
    """SIGKILL one of two workers after the third result: its runs are redone elsewhere,
    the results recorded before the kill are kept, and the sweep completes with the
    1-worker rows."""
    from distributed import Client, LocalCluster

    from orchestrator.sweep.engine import run_sweep

    _, ref = reference
    spec = load_spec(files[0] / "spec.toml")
    seen: list[dict] = []
    killed: list[int] = []
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None)
    client = Client(cluster)
    try:
        def on_result(row: dict) -> None:
            seen.append(row)
            if len(seen) == 3 and not killed:
                pids = client.run(os.getpid)
                busy = [pids[w] for w in pids]
                killed.append(busy[0])
                os.kill(busy[0], signal.SIGKILL)

        o = run_sweep(spec, tmp_path / "out", scheduler=cluster.scheduler_address,
                      on_result=on_result)
        after = set(client.run(os.getpid).values())
    finally:
        client.close()
        cluster.close()
    assert killed and killed[0] not in after
    assert o.status == "completed"
    rows = read_results(tmp_path / "out").to_pylist()
    assert len(rows) == spec.n_runs
    assert not [r for r in rows if r["error_kind"] == "infrastructure"]
    got = stable(rows)
    assert got == stable(ref)
    for r in seen[:3]:  # recorded before the kill, kept unchanged
        assert got[r["key"]] == stable([r])[r["key"]]


@pytest.mark.slow
def test_ctrl_c_then_resume_without_redoing(reference, files, tmp_path):
    """SIGINT (Ctrl-C) to ``hpcosim sweep`` once the first results are on disk: exit 130,
    every consumed result saved; the same sweep again runs exactly the missing runs and
    gives the 1-worker rows."""
    import subprocess
    import sys
    import time

    from orchestrator.sweep.engine import run_sweep

    _, ref = reference
    spec_path = write_spec(tmp_path / "spec.toml", files[1], draws=8)
    spec = load_spec(spec_path)
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-m", "orchestrator.cli", "sweep", str(spec_path),
                          "--out", str(out), "--workers", "1"], env=env, cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 120
        while not list((out / "results").glob("part-*.parquet")):
            assert p.poll() is None and time.monotonic() < deadline
            time.sleep(0.1)
        p.send_signal(signal.SIGINT)
        text, _ = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, text
    assert "interrupted" in text
    first = read_results(out).to_pylist()
    sessions = json.loads((out / "sweep.json").read_text())["sessions"]
    assert sessions[0]["status"] == "interrupted"
    assert sessions[0]["runs_done"] == len(first) < spec.n_runs  # every consumed run saved
    o = run_sweep(spec, out, workers=2)
    assert o.skipped == len(first) and o.done == spec.n_runs - len(first)
    rows = stable(read_results(out).to_pylist())
    assert len(rows) == spec.n_runs
    assert {k: rows[k] for k in stable(ref)} == stable(ref)  # draws 0-2 as the 3-draw sweep
    sessions = json.loads((out / "sweep.json").read_text())["sessions"]
    assert [s["status"] for s in sessions] == ["interrupted", "completed"]


@pytest.mark.parametrize("spec_file", sorted((ROOT / "examples" / "sweep").glob("*.toml")),
                         ids=lambda p: p.name)
def test_example_specs_load_with_a_consistent_gait_and_tube(spec_file, model):
    """The shipped example specs work as the README says: their gait is one of this model
    (a paper gait) or a multi-contact gait whose model matches its stored configs, and their
    tube, when they have one, was fitted for that gait (a regenerated gait needs a refitted
    tube)."""
    from characterization.gait.multicontact_artifact import load_contact_cycle
    from hp_model.force_tube import load_tube
    from hp_model.gait_artifact import MULTICONTACT_KIND, load_gait
    from orchestrator.sweep.contact_spec import MULTICONTACT_CONTROLLERS

    spec = load_spec(spec_file)
    if json.loads(Path(spec.gait).read_text()).get("kind") == MULTICONTACT_KIND:
        cycle = load_contact_cycle(spec.gait)  # refuses a gait its model's hash disowns
        assert spec.controllers and set(spec.controllers) <= set(MULTICONTACT_CONTROLLERS)
        if spec.tube is not None:
            load_tube(spec.tube, cycle.hash)
        return
    gait = load_gait(spec.gait, model.parameter_hash())
    load_tube(spec.tube, gait.hash())
