"""A sweep of a multi-contact gait (orchestrator/sweep/contact.py): the committed openOFM
cycle's file with the tube of its take, on a real Dask worker through the CLI; its rows,
report and replays; what a multi-contact spec refuses; a draw's curves."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from characterization.gait.contact_gait import contact_gait_of
from characterization.gait.multicontact_artifact import load_contact_cycle
from characterization.mocap.session import process_session
from characterization.mocap.steps_artifact import load_steps
from characterization.tube.contact_playback import fit_contact_tube
from hp_model.force_tube import save_tube
from orchestrator.cli import main as hpcosim
from orchestrator.sweep.contact import draw_gait
from orchestrator.sweep.draws import HUMAN_JOINTS, Draw
from orchestrator.sweep.spec import SpecError, load_spec
from orchestrator.sweep.store import read_results
from tests.multicontact_cycle import TAKE, write_gait_file

SPEC = """
name = "person"
gait = "{gait}"
{tube}
controllers = ["clfqp", "phase-pd", "pd", "passive"]
draws = 2
seed = 5
steps = 3

[families.nominal]

[families.sensors]
sensor.imu_bias = {{ dist = "normal", mean = 0.0, std = 0.003 }}
sensor.angle_noise = 0.001

[families.stride]
human.stride_cv = 0.03
"""


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("contact-sweep")
    gait = d / "person.json"
    write_gait_file(gait)
    steps = d / "steps.npz"
    process_session([TAKE / "dynamic.c3d"], steps, mapping=TAKE / "mapping.toml",
                    with_figures=False)
    tube = d / "tube.json"
    save_tube(tube, fit_contact_tube(load_contact_cycle(gait), load_steps(steps)).tube)
    return d, gait, tube


def spec_file(d, gait, tube=None, extra: str = ""):
    p = d / "spec.toml"
    p.write_text(SPEC.format(gait=gait, tube=f'tube = "{tube}"' if tube else "") + extra)
    return p


@pytest.fixture(scope="module")
def swept(files):
    d, gait, tube = files
    out = d / "out"
    assert hpcosim(["sweep", str(spec_file(d, gait, tube)), "--out", str(out),
                    "--workers", "1"]) == 0
    return out, {r["key"]: r for r in read_results(out).to_pylist()}


def test_a_multicontact_sweep_runs_its_controllers_on_the_same_draws(swept):
    out, rows = swept
    assert len(rows) == 5 * 3 * 2  # oracle, clfqp, phase-pd, pd, passive x 3 families x 2
    assert all(r["error"] is None for r in rows.values()), [
        r["error"] for r in rows.values() if r["error"]]
    for c in ("pd", "passive"):  # the paper's baselines on this graph: run, bounded
        for r in (rows[f"{c}/{f}/{i}"] for f in ("nominal", "sensors", "stride")
                  for i in range(2)):
            assert r["torque_finite"] and r["steps_completed"] >= 1, r["reason"]
            assert abs(r["max_torque_knee"]) <= 2.4 + 1e-9
    for c in ("oracle", "clfqp", "phase-pd"):
        for i in range(2):
            r = rows[f"{c}/nominal/{i}"]
            assert r["success"] and r["steps_completed"] == 3, r["reason"]
            assert r["torque_finite"] and abs(r["max_torque_knee"]) <= 2.4 + 1e-9
    # the person's pace from stride to stride: the same draw for every controller, its own
    # seed per draw
    stride = [rows[f"{c}/stride/{i}"] for c in ("oracle", "clfqp") for i in range(2)]
    assert all(r["draw_stride_cv"] == 0.03 for r in stride)
    assert stride[0]["draw_stride_seed"] == stride[2]["draw_stride_seed"] != \
        stride[1]["draw_stride_seed"]
    nominal = [rows[f"clfqp/nominal/{i}"] for i in range(2)]
    assert nominal[0]["knee_rms_ps_rad"] == nominal[1]["knee_rms_ps_rad"]  # one run, twice
    # the tube of the take's steps: the share of the flat single support inside it
    assert all(r["socket_force_in_tube"] is not None and 0 <= r["socket_force_in_tube"] <= 1
               for r in rows.values() if r["steps_completed"] >= 2)
    rep = json.loads((out / "report.json").read_text())
    assert rep["complete"]
    runs = [line for line in (out / "report.md").read_text().splitlines()
            if "hpcosim run " in line]  # a worst run's co-simulation (no tube here)
    assert runs and all("--tube" not in line for line in runs)
    assert {line.split("--controller ")[1].split()[0] for line in runs} <= {
        "clfqp", "phase-pd", "pd", "passive"}


@pytest.mark.parametrize("key", ["clfqp/sensors/1", "phase-pd/nominal/0", "oracle/sensors/0",
                                 "clfqp/stride/1", "passive/sensors/0", "pd/stride/1"])
def test_a_replay_equals_the_stored_run(swept, key, capsys):
    """A run is a pure function of its key: replayed alone in this process (fresh
    controllers) it gives the row the worker wrote after other runs (controllers reset)."""
    out, _ = swept
    assert hpcosim(["sweep", "replay", str(out), key]) == 0
    assert "identical to the stored result" in capsys.readouterr().out


@pytest.mark.parametrize(("extra", "field"), [
    ('\n[families.t]\nsocket.tube_scale = 2.0\n', "families.t.socket.tube_scale"),
    ('\n[families.p]\nplant.segment_mass = 1.1\n', "families.p.plant.segment_mass"),
    ('\n[families.d]\nhuman.delay = 0.01\n', "families.d.human.delay"),
    ('\n[families.a]\nplant.armature = {dist = "uniform", low = 0.5, high = 1.5}\n',
     "families.a.plant.armature"),
    # the committed cycle's device has no rotor inertia: no armature to scale
    ('\n[families.a]\nplant.armature = 1.5\n', "families.a.plant.armature"),
])
def test_quantities_a_multicontact_sweep_does_not_draw_are_refused(files, tmp_path, extra,
                                                                   field):
    _, gait, _ = files
    with pytest.raises(SpecError) as e:
        load_spec(spec_file(tmp_path, gait, extra=extra))
    assert f"field '{field}'" in str(e.value) and "\n" not in str(e.value)


def test_paper_controllers_backend_and_tube_are_refused(files, tmp_path):
    _, gait, _ = files
    p = spec_file(tmp_path, gait)
    base = p.read_text()
    paper_tube = Path("tests/data/controller/tube_demo_v2.json").resolve()
    for text, field in ((base.replace('"phase-pd"', '"clfqp-paper"'), "controllers"),
                        (base.replace("steps = 3", 'steps = 3\nbackend = "fmu"'), "backend"),
                        (SPEC.format(gait=gait, tube=f'tube = "{paper_tube}"'), "tube")):
        p.write_text(text)
        with pytest.raises(SpecError, match=f"field '{field}'") as e:
            load_spec(p)
        assert "\n" not in str(e.value)


def test_a_draw_moves_only_the_human_joints_curves(files):
    _, gait, _ = files
    cycle = load_contact_cycle(gait)
    cg = contact_gait_of(cycle.model, cycle.trajectory, cycle.durations)
    nominal = {d.value: th for d, th in cg.thetas().items()}
    assert all(np.array_equal(draw_gait(cg, Draw("n", 0))[d], th) for d, th in nominal.items())
    off = (0.01, -0.02, 0.03, 0.04)
    moved = draw_gait(cg, Draw("o", 0, output_offset=off))
    for d, p in cg.params.items():
        layout = p.alpha.shape
        got = moved[d][:p.alpha.size].reshape(layout) - p.alpha
        for row, coord in enumerate(d.y2_coords):
            want = dict(zip(HUMAN_JOINTS, off, strict=True)).get(coord, 0.0)
            np.testing.assert_allclose(got[row], want, atol=1e-12)
        np.testing.assert_array_equal(got[len(d.y2_coords):], 0.0)  # hip rate, squeeze


PERSON_SPEC = """
name = "person"
gait = "{gait}"
controllers = ["clfqp", "phase-pd"]
draws = 1
seed = 5
steps = 3
{families}"""


def person_sweep(tmp_path, families: str) -> tuple[Path, dict]:
    """One draw of each of ``families`` (TOML) on the packaged person, its output folder and
    its rows by key."""
    from characterization.gait.person_synth import REFERENCE_PERSON_GAIT

    spec = tmp_path / "spec.toml"
    spec.write_text(PERSON_SPEC.format(gait=REFERENCE_PERSON_GAIT, families=families))
    out = tmp_path / "out"
    assert hpcosim(["sweep", str(spec), "--out", str(out), "--workers", "1"]) in (0, 1)
    return out, {r["key"]: r for r in read_results(out).to_pylist()}


def test_the_walkers_armature_is_the_draws(tmp_path):
    """The packaged person (its device with the drives' rotor inertia): with half the
    armature the walker is another (its own model, compiled once), the controllers keep the
    device's.  The oracle (the plant's own feedback linearization) and contact-pd walk it;
    `clfqp`'s run is not the nominal's (its stance QP's model is the device's: on 200 such
    draws it falls in `ds_p`, docs/sweeps.md)."""
    _, rows = person_sweep(tmp_path, "[families.nominal]\n[families.light]\n"
                                     "plant.armature = 0.5\n")
    assert all(r["error"] is None for r in rows.values())
    assert rows["oracle/light/0"]["draw_armature"] == 0.5
    assert rows["oracle/light/0"]["success"] and rows["phase-pd/light/0"]["success"]
    nominal, light = rows["clfqp/nominal/0"], rows["clfqp/light/0"]
    assert nominal["success"]
    assert (light["success"], light["duration_s"], light["max_torque_ankle"]) != \
        (nominal["success"], nominal["duration_s"], nominal["max_torque_ankle"])


def test_a_start_with_the_prosthesis_moved_is_the_draws(tmp_path, capsys):
    """``initial.knee`` / ``initial.ankle`` on the person's graph: every controller starts
    from the cycle's start with the prosthesis's knee and ankle moved (``prosthesis_start``),
    recorded in the row, and a run is a pure function of its key.  The oracle (yielding its
    feedback at the motors' limits) walks this draw, where clamped it fell in 0.14 s."""
    out, rows = person_sweep(tmp_path, "[families.initial]\ninitial.knee = 0.037\n"
                                       "initial.ankle = -0.007\n")
    assert set(rows) == {f"{c}/initial/0" for c in ("oracle", "clfqp", "phase-pd")}
    for r in rows.values():
        assert r["error"] is None
        assert (r["draw_knee_offset"], r["draw_ankle_offset"]) == (0.037, -0.007)
    assert rows["oracle/initial/0"]["success"], rows["oracle/initial/0"]["reason"]
    capsys.readouterr()
    assert hpcosim(["sweep", "replay", str(out), "clfqp/initial/0"]) == 0
    assert "identical to the stored result" in capsys.readouterr().out


EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "sweep"


@pytest.mark.parametrize("name", sorted(p.name for p in EXAMPLES.glob("*.toml")))
def test_every_example_spec_is_a_valid_sweep(name: str) -> None:
    """The specs the README and docs run (`hpcosim sweep run examples/sweep/NAME`) load and
    pass the sweep's checks (their gait and tube files found, every quantity one their graph
    draws)."""
    spec = load_spec(EXAMPLES / name)
    assert spec.draws >= 1 and spec.families and spec.controllers
