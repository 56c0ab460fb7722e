"""Exit status 1 for a result that is negative (``orchestrator.cli.outcome``): the decision of
each verb on its own, on real results where they are cheap, and end to end through the
command line (a co-simulation that falls, experiments whose claims are not reproduced, a
sweep folder with runs missing, a replay by another controller).  Exit 2 (bad input) is
``tests/test_cli_errors.py``'s."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hp_model.falls import FallReason
from hp_model.force_tube import load_tube
from orchestrator.cli.model_check import CheckRow
from orchestrator.cli.outcome import (
    EXPECTED_NOT_REPRODUCED,
    NEGATIVE_WHEN,
    claims_verdict,
    combine,
    cosim_verdict,
    coverage_verdict,
    gait_verdict,
    model_check_verdict,
    replay_verdict,
    sweep_verdict,
    uncounted_claims,
)
from orchestrator.cosim.result import CosimResult
from tests.cli_support import GAIT, TUBE, cosim_files, hpcosim, negative_line

__all__ = ["cosim_files"]  # a fixture of tests/cli_support.py

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ decisions


def test_every_verb_states_when_it_exits_1():
    from orchestrator.cli.synopsis import verbs

    assert set(NEGATIVE_WHEN) == {p for p, _ in verbs()}
    assert all(w.strip() for w in NEGATIVE_WHEN.values())


def test_model_check_fails_on_any_failed_row():
    rows = [CheckRow("a", "1", "1", True), CheckRow("impact ps: |E qd+|", "3e-3", "< 1e-9",
                                                     False)]
    v = model_check_verdict(rows)
    assert not v.holds and v.reason == "1 of 2 model checks failed: impact ps: |E qd+|"
    assert model_check_verdict(rows[:1]).holds


def test_a_fall_or_a_fault_is_negative_a_time_limit_is_not():
    fell = CosimResult(sim_time=0.5123, steps=1, fell=True,
                       fall_code=int(FallReason.FRICTION_CONE))
    v = cosim_verdict(fell, 4)
    assert v.reason == ("the walker fell at t = 0.512 s (friction-cone, code "
                        f"{int(FallReason.FRICTION_CONE)}) after 1 of 4 steps")
    v = cosim_verdict(CosimResult(sim_time=0.1, faulted=True, fault_reason="5 replies missed"),
                      4)
    assert v.reason == "the run faulted at t = 0.100 s: 5 replies missed"
    assert cosim_verdict(CosimResult(sim_time=60.0, steps=3), 20).holds  # --max-time


def test_a_gait_that_does_not_walk_is_negative():
    v = gait_verdict({"walks": False, "steps_simulated": 3, "steps_required": 20,
                      "simulation_failed": True, "failure": "hip-low at t = 1.2 s",
                      "spectral_radius": 1.7})
    assert v.reason == ("the gait does not walk: fell after 3 of 20 steps (hip-low at t = "
                        "1.2 s); return-map spectral radius 1.7 >= 1; written by "
                        "--allow-unstable, marked walks: false")
    assert gait_verdict({"walks": True, "spectral_radius": 0.4}).holds
    assert gait_verdict({}).holds  # --no-verify: nothing to judge


def test_tube_coverage_against_its_guarantee_and_a_target():
    """The demo subject's tube (committed): leave-one-out coverage 0.50, a posteriori eps
    0.788 (k = 10 of N = 20), so the default target 1 - eps = 0.21 holds; a stricter
    --min-coverage, a coverage of 0 and the model-error bound are judged the same way."""
    t = load_tube(TUBE)
    cred = t.credibility
    assert cred["leave_one_out"]["coverage"] == 0.5
    assert coverage_verdict("force tube", cred).holds
    v = coverage_verdict("force tube", cred, 0.6)
    assert v.reason == ("force tube: leave-one-out coverage 0.50 below --min-coverage 0.60; "
                        "written all the same")
    strict = {**cred, "a_posteriori": {**cred["a_posteriori"], "epsilon_tube": 0.4}}
    assert coverage_verdict("force tube", strict).reason == (
        "force tube: leave-one-out coverage 0.50 below the a posteriori guarantee 1 - eps = "
        "0.60; written all the same")
    zero = {**cred, "leave_one_out": {"coverage": 0.0, "inside": 0}}
    assert "coverage 0 " in coverage_verdict("force tube", zero, 0.0).reason
    assert t.model_error is not None
    me = t.model_error.credibility
    assert coverage_verdict("model-error bound", me).holds  # 0.50 against 1 - 0.788
    assert not coverage_verdict("model-error bound", me, 0.75).holds
    few = {"leave_one_out": {"step_coverage": None}, "a_posteriori": {"epsilon": 1.0}}
    assert coverage_verdict("model-error bound", few).holds  # too few steps: not judged
    assert combine(coverage_verdict("a", zero), coverage_verdict("b", me, 0.75)).reason.count(
        "leave-one-out") == 2


def _claims(**reproduced: bool) -> list[dict]:
    return [{"id": k, "reproduced": v} for k, v in reproduced.items()]


def test_claims_not_reproduced_are_negative_but_the_documented_one():
    ok = {"nominal": {"run": {"success": True}, "stability": {"computed": True}},
          "claims": _claims(nominal_stable=True, relaxed_smooth=True, robust_order=True,
                            robust_success=True, paper_literal=False)}
    assert frozenset({"paper_literal"}) == EXPECTED_NOT_REPRODUCED
    assert claims_verdict(ok).holds  # the demo's documented result
    assert uncounted_claims(ok) == {"paper_literal": "expected"}
    bad = {**ok, "claims": _claims(nominal_stable=True, relaxed_smooth=False,
                                   robust_order=False, robust_success=True,
                                   paper_literal=False)}
    assert claims_verdict(bad).reason == ("2 claims NOT reproduced: relaxed_smooth, "
                                          "robust_order (report.md says why)")
    assert claims_verdict(bad, judged=False).holds  # demo --quick
    # --no-eigen: a nominal run that completed has no stability evidence: not judged ...
    no_eigen = {"nominal": {"run": {"success": True}, "stability": {"computed": False}},
                "claims": _claims(nominal_stable=False, paper_literal=False)}
    assert claims_verdict(no_eigen).holds
    assert uncounted_claims(no_eigen)["nominal_stable"] == "not judged: no eigenvalues"
    # ... but a nominal run that fell is negative whatever the eigenvalues
    fell = {**no_eigen, "nominal": {"run": {"success": False},
                                    "stability": {"computed": False}}}
    assert claims_verdict(fell).reason.startswith("1 claim NOT reproduced: nominal_stable")


def test_replay_and_sweep_decisions():
    assert replay_verdict(0.0, 1e-6).holds and replay_verdict(1e-6, 1e-6).holds
    assert replay_verdict(0.031, 1e-6).reason == (
        "largest torque difference 0.031 N m (motor) is above --tolerance 1e-06 N m")
    assert sweep_verdict(24, 24).holds
    assert sweep_verdict(24, 21).reason.startswith("3 of 24 runs have no result")


# ------------------------------------------------------------------ end to end


def test_experiments_with_claims_not_reproduced_exit_1(tmp_path):
    """One step per run (7 s): the relaxed law's tracking cannot settle in one step and the
    ordering against the baselines is not shown, so two claims are NOT reproduced: exit 1 with
    their ids, the outputs written; nominal_stable is not judged (--no-eigen) and
    paper_literal is the documented negative."""
    out = tmp_path / "exp"
    r = hpcosim("experiments", "--gait", str(GAIT), "--tube", str(TUBE), "--out", str(out),
                "--steps", "1", "--no-eigen")
    m = json.loads((out / "metrics.json").read_text())
    bad = [c["id"] for c in m["claims"] if not c["reproduced"]
           and c["id"] not in uncounted_claims(m)]
    assert bad, m["claims"]  # the premise: a negative result
    negative_line(r, f"{len(bad)} claim", *bad)
    assert (out / "report.md").is_file()
    assert "nominal_stable  (not judged: no eigenvalues)" in r.stdout


def _sweep_folder(root: Path, infrastructure: int) -> tuple[Path, int]:
    """A folder of the quick example sweep (examples/sweep/quick.toml) with a result for
    every run, a fall among them, and the first ``infrastructure`` runs lost by Dask
    (error_kind "infrastructure"); with the number of runs the spec has."""
    from orchestrator.sweep.draws import make_draw, run_keys
    from orchestrator.sweep.spec import load_spec
    from orchestrator.sweep.store import KIND, SCHEMA_VERSION, ResultStore

    spec = load_spec(ROOT / "examples" / "sweep" / "quick.toml")
    root.mkdir()
    st = ResultStore(root)
    st.write_manifest({"kind": KIND, "schema_version": SCHEMA_VERSION, "artifact_hashes": {},
                       "spec": spec.model_dump(mode="json"), "sessions": []})
    st.results.mkdir()
    base = {"session": "s", "seq": 0, "success": True, "failed": False,
            "steps_completed": 1, "duration_s": 0.5, "reason": ""}
    rows = [{**base, **make_draw(spec, k.family, k.draw).columns(), "key": k.text,
             "controller": k.controller, "family": k.family, "draw": k.draw}
            for k in run_keys(spec)]
    for row in rows[:infrastructure]:
        row.update(success=False, error="KilledWorker: lost", error_kind="infrastructure")
    rows[-1].update(success=False, failed=True, reason="fell", fall_reason="hip-low")
    st.write_part(rows, "s", 0)
    return root, len(rows)


def test_sweep_report_exits_1_while_runs_are_missing(tmp_path):
    """A stored sweep whose every run has a result (one of them a fall: a measurement)
    holds; with 2 of its 24 runs lost to the infrastructure (a resume retries them) it is
    negative, the report written all the same."""
    ok, n = _sweep_folder(tmp_path / "ok", 0)
    r = hpcosim("sweep", "report", str(ok))
    assert r.returncode == 0, r.stderr
    lost, _ = _sweep_folder(tmp_path / "lost", 2)
    negative_line(hpcosim("sweep", "report", str(lost)), f"2 of {n} runs have no result",
                  "resume")
    assert (lost / "report.md").is_file()


@pytest.mark.serial  # lockstep co-simulations (tests/test_cosim.py: reply deadlines)
def test_run_that_falls_exits_1_and_replay_by_another_controller_too(cosim_files, tmp_path):
    """``hpcosim run`` with the human's gait perturbed by 0.1 rad falls: exit 1 naming the
    fall, its recording complete; replaying that recording with the recorded controller
    gives 0 N m (exit 0), with ``pd`` a difference above --tolerance (exit 1)."""
    f = cosim_files
    rec = tmp_path / "fell.mcap"
    r = hpcosim("run", "--controller", "clfqp", "--gait", str(f["gait"]), "--tube",
                str(f["tube"]), "--fmu", str(f["fmu"]), "--steps", "4", "--perturb",
                "human:0.1", "--record", str(rec))
    negative_line(r, "the walker fell at t = ", "of 4 steps")
    assert "fell (" in r.stdout
    from orchestrator.cosim.recording import read_recording

    summary = read_recording(rec, messages=False).metadata["summary"]
    assert summary["fell"] == "true"
    r = hpcosim("replay", str(rec))
    assert r.returncode == 0 and "largest torque difference 0 N m" in r.stdout, r.stderr
    negative_line(hpcosim("replay", str(rec), "--controller", "pd"),
                  "largest torque difference", "above --tolerance 1e-06 N m")


def _stand_in(monkeypatch, path: tuple[str, ...], exc: BaseException) -> None:
    """The verb ``path`` raises ``exc`` (through the path wrapper's call-time lookup)."""
    import functools

    from orchestrator.cli import app

    group, *rest = path
    t = next(g.typer_instance for g in app.registered_groups if g.name == group)
    cb = next(c.callback for c in t.registered_commands if c.name == rest[0])
    verb = cb.__wrapped__

    @functools.wraps(verb)
    def raising(*a, **kw):
        raise exc

    monkeypatch.setattr(cb, "__wrapped__", raising)


def test_a_bug_is_exit_3_in_one_line_never_1(monkeypatch, capsys):
    """An exception no verb expects (a bug) is not a negative result: exit 3, one line
    naming it, the traceback only with HPCOSIM_DEBUG=1; Ctrl-C is 130."""
    from orchestrator.cli import main

    _stand_in(monkeypatch, ("mocap", "synth"), KeyError("frame"))
    monkeypatch.delenv("HPCOSIM_DEBUG", raising=False)
    assert main(["mocap", "synth", "--out", "x"]) == 3
    err = capsys.readouterr().err
    assert err.strip().splitlines() == ["hpcosim: internal error: KeyError: 'frame' (a bug; "
                                        "HPCOSIM_DEBUG=1 prints the traceback)"]
    monkeypatch.setenv("HPCOSIM_DEBUG", "1")
    assert main(["mocap", "synth", "--out", "x"]) == 3
    err = capsys.readouterr().err
    assert "Traceback" in err and err.strip().splitlines()[-1].startswith(
        "hpcosim: internal error: KeyError")
    _stand_in(monkeypatch, ("mocap", "synth"), KeyboardInterrupt())
    assert main(["mocap", "synth", "--out", "x"]) == 130
    assert "Traceback" not in capsys.readouterr().err


@pytest.mark.parametrize("label_walkable", [False, True])
def test_sweep_report_counts_the_runs_of_the_stored_spec(label_walkable):
    """``sweep report`` reads the runs a sweep has from its stored spec: the keys
    ``draws.run_keys`` makes for it (the walkability oracle's among them when labelled)."""
    from orchestrator.cli.sweep import _manifest_keys
    from orchestrator.sweep.draws import run_keys
    from orchestrator.sweep.spec import load_spec

    spec = load_spec(ROOT / "examples" / "sweep" / "quick.toml").model_copy(
        update={"label_walkable": label_walkable})
    keys = {k.text for k in run_keys(spec)}
    assert len(keys) == spec.n_runs == (4 if label_walkable else 3) * 2 * 4
    assert _manifest_keys(spec.model_dump(mode="json")) == keys
