"""The gait library over walking speed (``characterization/gait/library.py``, ``hpcosim gait
library``): the targets at another speed, the artifact read back, the curves between speeds,
and (slow) the packaged person's gait fitted again at 0.9 and 1.25 m/s from its own take,
walked along a changing speed."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from characterization.gait.library import (
    KIND,
    LibraryGait,
    LibraryOptions,
    fit_library,
    load_gait_library,
    save_gait_library,
    source_gait,
    speed_targets,
    to_document,
)
from characterization.gait.multicontact import (
    GRAPH,
    STANCE,
    TRACKED,
    MultiContactError,
    MultiContactOptions,
    MultiContactTargets,
)
from characterization.gait.multicontact_artifact import (
    load_contact_cycle,
    load_multicontact_gait,
)
from characterization.gait.person_synth import REFERENCE_PERSON_GAIT
from hp_model.artifacts import ArtifactError
from hp_model.speed_profile import SpeedProfile
from tests import person_reference
from tests.cli_support import hpcosim


@pytest.fixture(scope="module")
def cycle():
    return load_contact_cycle(REFERENCE_PERSON_GAIT)


def _quickened(g: LibraryGait, k: float) -> LibraryGait:
    """The same cycle run k times faster (time / k, rates x k, accelerations x k^2): a
    stand-in for another speed's fit (same stride, speed x k)."""
    traj = {d: {**tr, "t": np.asarray(tr["t"]) / k, "qd": np.asarray(tr["qd"]) * k,
                "qdd": np.asarray(tr["qdd"]) * k * k} for d, tr in g.trajectory.items()}
    return LibraryGait(g.speed * k, traj, {d: T / k for d, T in g.durations.items()},
                       g.stride_length, {"status": "scaled"}, None)


@pytest.fixture(scope="module")
def library_file(cycle, tmp_path_factory):
    """A library of the packaged person's gait and the same cycle 20 % faster."""
    base = source_gait(cycle)
    doc = load_multicontact_gait(REFERENCE_PERSON_GAIT)
    path = tmp_path_factory.mktemp("library") / "lib.json"
    save_gait_library(path, to_document([base, _quickened(base, 1.2)], cycle, "person.json",
                                        doc["subject"], doc["device"], MultiContactOptions(),
                                        LibraryOptions()))
    return path


def test_targets_at_another_speed_keep_the_angles_and_share_the_change():
    """Faster by k: durations x k^-0.5, so stride length x k^0.5 too; angles kept, no
    plates."""
    ang = {d: np.zeros((len(TRACKED), 5)) for d in GRAPH.domains}
    t = MultiContactTargets({d: 0.2 for d in GRAPH.domains}, ang, 1.0,
                            stance_fz={next(iter(STANCE)): np.ones(5)})
    f = speed_targets(t, 1.44, 0.5)
    assert f.speed == 1.44 and f.stance_fz == {}
    assert all(f.durations[d] == pytest.approx(0.2 / 1.2) for d in GRAPH.domains)
    assert f.angles is t.angles
    assert f.speed * f.stride_time == pytest.approx(t.speed * t.stride_time * 1.2)


def test_the_source_entry_is_the_gait_files_stride(cycle):
    doc = load_multicontact_gait(REFERENCE_PERSON_GAIT)
    base = source_gait(cycle)
    assert base.source and base.speed == pytest.approx(doc["stride"]["speed"], rel=1e-9)
    assert base.stride_time == pytest.approx(doc["stride"]["time"], rel=1e-12)


def test_the_library_reads_back_and_interpolates_between_speeds(cycle, library_file):
    lib = load_gait_library(library_file)
    v0 = source_gait(cycle).speed
    assert lib.speeds == pytest.approx([v0, 1.2 * v0])
    lo, hi = lib.curves
    for v, want in ((v0, lo), (1.2 * v0, hi), (0.5, lo), (3.0, hi)):  # clamped outside
        got = lib.gait_at(v)
        for d in GRAPH.domains:
            assert np.allclose(got.params[d].alpha, want.params[d].alpha, atol=1e-12)
    mid = lib.gait_at(1.1 * v0)
    for d in GRAPH.domains:
        a, b, m = lo.params[d], hi.params[d], mid.params[d]
        assert np.allclose(m.alpha, (np.asarray(a.alpha) + b.alpha) / 2, atol=1e-12)
        assert m.v_hip == pytest.approx((a.v_hip + b.v_hip) / 2)
        # the same stride's cycle run faster: the hip-rate curve scales, the joints' don't
        assert b.v_hip == pytest.approx(1.2 * a.v_hip, rel=1e-9)


def test_a_library_whose_speeds_do_not_increase_is_refused(library_file, tmp_path):
    doc = json.loads(library_file.read_text())
    doc["gaits"] = doc["gaits"][::-1]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(ArtifactError, match=r"field 'gaits'.*do not increase"):
        load_gait_library(bad)
    doc["kind"] = "hpcosim-gait-multicontact"
    bad.write_text(json.dumps(doc))
    with pytest.raises(ArtifactError, match="kind"):
        load_gait_library(bad)
    assert json.loads(library_file.read_text())["kind"] == KIND


def test_bad_speeds_and_options_are_one_line_errors(cycle, tmp_path):
    r = hpcosim("gait", "library", "steps.npz", "--gait", str(REFERENCE_PERSON_GAIT),
                "--out", str(tmp_path / "l.json"), "--speeds", "0.8,fast")
    assert r.returncode == 2 and "'fast' is not a speed" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    with pytest.raises(MultiContactError, match="cadence_exponent"):
        LibraryOptions(cadence_exponent=2.0)
    t = MultiContactTargets({d: 0.2 for d in GRAPH.domains},
                            {d: np.zeros((len(TRACKED), 5)) for d in GRAPH.domains}, 1.0)
    with pytest.raises(MultiContactError, match=r"speed 5\.0 m/s is outside"):
        fit_library(cycle.model, t, cycle, [5.0])


def test_a_speed_family_needs_the_library_and_draws_only_sensors_beside_it(library_file,
                                                                           tmp_path):
    """A sweep spec's ``human.speed``: refused without ``library``, beside a quantity other
    than ``sensor.*``, outside the speeds a person walks, and on the paper's graph; one line
    naming the field."""
    from orchestrator.sweep.spec import SpecError, load_spec

    base = (f'gait = "{REFERENCE_PERSON_GAIT}"\ncontrollers = ["clfqp"]\ndraws = 2\n'
            f'seed = 1\n')
    lib = f'library = "{library_file}"\n'
    speed = 'human.speed = {dist = "uniform", low = 0.9, high = 1.2}\n'
    data = Path("tests/data/controller").resolve()
    paper = f'gait = "{data / "gait_demo.json"}"\ntube = "{data / "tube_demo.json"}"\n'
    for text, field in (
            (base + "[families.s]\n" + speed, "families.s.human.speed"),
            (base + lib + "[families.s]\n" + speed + "human.stride_cv = 0.01\n",
             "families.s.human.stride_cv"),
            (base + lib + "[families.s]\nhuman.speed = 3.0\n", "families.s.human.speed"),
            (base + lib + "[families.s]\n"
             'human.speed = {dist = "normal", mean = 1.0, std = 0.1}\n',
             "families.s.human.speed"),
            (paper + lib + 'controllers = ["pd"]\ndraws = 2\nseed = 1\n[families.n]\n',
             "library")):
        p = tmp_path / "spec.toml"
        p.write_text(text)
        with pytest.raises(SpecError) as e:
            load_spec(p)
        assert f"field '{field}'" in str(e.value) and "\n" not in str(e.value), text
    p.write_text(base + lib + "[families.s]\n" + speed + "sensor.angle_noise = 0.001\n")
    assert load_spec(p).library == library_file.resolve()


@pytest.fixture(scope="module")
def fitted(private_cache):
    """`gait library` at 0.9 and 1.25 m/s from the packaged person (1.07 m/s) and its take:
    the command's result and the library file.  Made in a folder of this process's own and
    published to the run's cache (``HPCOSIM_CACHE``) by an atomic rename: ``make test``'s
    serial phase (the co-simulation below) takes the parallel phase's (the result then: the
    library file made, exit 0), and two workers making it at once each keep their own."""
    shared = private_cache / "test-person-library.json"
    if shared.is_file():  # published only by a `gait library` that exited 0
        return SimpleNamespace(returncode=0, stderr="", stdout=""), shared
    d = Path(tempfile.mkdtemp(prefix="fitted-library-", dir=private_cache))
    steps = d / "steps.npz"
    assert person_reference.make_steps(steps, d) == 0
    out = d / "lib.json"
    r = hpcosim("gait", "library", str(steps), "--gait", str(REFERENCE_PERSON_GAIT),
                "--out", str(out), "--speeds", "0.9,1.25")
    if r.returncode == 0:
        part = d / "published.part"
        shutil.copyfile(out, part)
        os.replace(part, shared)
    return r, out


@pytest.mark.slow  # the take made and processed, two fits (about 25 s each), the walks
def test_the_person_fitted_again_at_other_speeds_walks_and_changes_speed(fitted):
    """`gait library` at 0.9 and 1.25 m/s from the packaged person (1.07 m/s) and its take:
    exit 0, three gaits, each within 2 % of its speed, its stride time the person's times
    (1.07 / v)^0.5 within 5 % (the durations' targets; the fit trades them against the
    speed), each walking 10 steps with the held oracle.  On it, the person walks 30 steps
    while the command goes 0.9 -> 1.25 -> 0.9 m/s, each stride within 0.05 m/s RMS of the
    command (a stride's lag: 0.04 m/s per stride on the ramps), and `clfqp` following its
    speed walks it at 1.0 m/s, between the library's gaits, reading that speed from its
    flat stances (the hip's rate over the flat foot), and follows the person slowing from
    1.2 to 0.95 m/s over 5 s (20 steps; before its stance read what it senses it fell at
    step 10, the prosthesis heel pulling as its double support ended: docs/gait-design.md):
    the strides after the ramp each within 0.03 m/s of the command and 0.02 on average (at
    a constant 0.95 they measured 0.926-0.956 over 26 steps since `clfqp` senses the
    person's heel strike, 0.953-0.968 before), the estimate within 0.04 of them on average
    (read from one flat stance, it alternates by about 0.03 from stride to stride on this
    library, and reads 0.03 high at its slow end)."""
    from orchestrator.experiments.speed_walk import speed_walk

    r, out = fitted
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    slow, base, fast = doc["gaits"]
    assert base["source"] and not slow["source"] and not fast["source"]
    for g, v in ((slow, 0.9), (fast, 1.25)):
        assert g["speed"] == pytest.approx(v, rel=0.02)
        ratio = (base["speed"] / g["speed"]) ** 0.5
        assert g["stride"]["time"] == pytest.approx(base["stride"]["time"] * ratio, rel=0.05)
    assert all(g["closed_loop"]["walks"] for g in doc["gaits"])
    lib = load_gait_library(out)
    w = speed_walk(lib, SpeedProfile.parse("0:0.9,8:1.25,12:1.25,20:0.9"), 30)
    assert w.walks, w.line()
    assert w.lag_rms() < 0.05 and w.speed.min() < 0.95 and w.speed.max() > 1.2
    c = speed_walk(lib, SpeedProfile.constant(1.0), 10, "clfqp")
    assert c.walks, c.line()
    assert c.speed[-1] == pytest.approx(1.0, abs=0.03)
    assert c.estimate[-1] == pytest.approx(c.speed[-1], abs=0.03)
    slowing = speed_walk(lib, SpeedProfile.parse("0:1.2,1:1.2,6:0.95"), 20, "clfqp")
    assert slowing.walks, slowing.line()
    settled = slowing.t > 7.2  # the strides that end a stride (1.2 s) or more after the ramp
    assert settled.sum() >= 3
    assert np.all(np.abs(slowing.speed[settled] - 0.95) < 0.03), slowing.speed
    assert np.mean(slowing.speed[settled]) == pytest.approx(0.95, abs=0.02)
    assert np.mean(slowing.estimate[settled]) == pytest.approx(
        np.mean(slowing.speed[settled]), abs=0.04)


@pytest.mark.slow  # the library of the test above, a worker's controllers over it, 9 runs
def test_a_sweep_changes_the_persons_speed_over_the_library(fitted, tmp_path):
    """A sweep family ``human.speed`` on the fitted library (``orchestrator/sweep/contact.py``):
    each draw's two speeds within the family's range, the same for every controller; the
    oracle (the person's own curves of the moment, held) walks every draw; the rows carry
    the draws and a replay equals its stored row."""
    from orchestrator.sweep.contact import speed_change
    from orchestrator.sweep.store import read_results

    r, lib = fitted
    assert r.returncode == 0, r.stderr
    spec = tmp_path / "speed.toml"
    spec.write_text(f'gait = "{REFERENCE_PERSON_GAIT}"\nlibrary = "{lib}"\n'
                    'controllers = ["clfqp", "phase-pd"]\ndraws = 3\nseed = 3\nsteps = 8\n'
                    '[families.speed]\n'
                    'human.speed = {dist = "uniform", low = 0.95, high = 1.2}\n')
    out = tmp_path / "out"
    s = hpcosim("sweep", "run", str(spec), "--out", str(out), "--workers", "1")
    assert s.returncode == 0, s.stderr
    rows = {row["key"]: row for row in read_results(out).to_pylist()}
    assert len(rows) == 9
    for i in range(3):
        draws = {(rows[f"{c}/speed/{i}"]["draw_speed_start"],
                  rows[f"{c}/speed/{i}"]["draw_speed_end"])
                 for c in ("oracle", "clfqp", "phase-pd")}
        assert len(draws) == 1
        (v0, v1), = draws
        assert 0.95 <= v0 <= 1.2 and 0.95 <= v1 <= 1.2 and v0 != v1
        assert rows[f"oracle/speed/{i}"]["success"], rows[f"oracle/speed/{i}"]["reason"]
    profile = speed_change(1.0, 1.2)
    assert profile.at(0.5) == 1.0 and profile.at(1.0 + 0.1 / 0.06) == pytest.approx(1.1)
    rep = hpcosim("sweep", "replay", str(out), "clfqp/speed/0")
    assert rep.returncode == 0, rep.stderr
    assert "identical to the stored result" in rep.stdout


@pytest.mark.slow  # the library above, the speed-following controller's file (about 15 s)
@pytest.mark.serial  # a lockstep co-simulation: wall-clock reply limits (tests/test_cosim.py)
def test_the_cosimulation_changes_the_persons_speed_and_clfqp_follows(fitted, tmp_path):
    """``hpcosim run --library --speed-profile``: the human FMU walks the fitted library at
    the commanded speed (1.0 m/s, up to 1.1 from 0 to 4 s) while ``clfqp`` follows it over
    the library in its own process; 12 steps, no reply missed.  The strides speed up with
    the command (the first within 0.02 m/s of 1.0, the last, past the ramp, of 1.1); the
    recording carries the library and the command and replays with no difference, and its
    export the controller's speed estimate, which reads the last stride's speed; the same
    run in process (the simulator under the same schedule, measurements and torques
    quantized as on the bus) is the same walk, to rounding.  A library of another person
    is refused."""
    from bus_schemas.recording.reader import read_messages
    from characterization.gait.contact_gait import GAINS
    from characterization.gait.library import speed_schedule, start_at
    from orchestrator.cosim.config import CosimConfig
    from orchestrator.cosim.contact_controllers import loop_simulator
    from orchestrator.cosim.export import run_table
    from orchestrator.cosim.following import ensure_following_file
    from orchestrator.cosim.master import run_cosim
    from orchestrator.cosim.recording import read_recording, replay
    from orchestrator.loop import ControllerLink, SimulatorPlant, run_loop
    from prosthesis_controller.gait_tables import load_controller_file
    from tests.multicontact_cycle import write_gait_file

    r, lib = fitted
    assert r.returncode == 0, r.stderr
    rec, steps, command = tmp_path / "run.mcap", 12, "0:1.0,4:1.1"
    res = run_cosim(CosimConfig(controller="clfqp", gait=REFERENCE_PERSON_GAIT, tube=None,
                                library=lib, speed_profile=command, steps=steps, record=rec))
    assert not res.fell and not res.faulted, res
    assert res.steps == steps and res.missed == 0 and res.torque_clamped == 0
    truth = [o for _, _, o in read_messages(rec, ["/ground_truth"])]
    t = np.array([o["t"] for o in truth])
    x = np.array([o["q"][0] for o in truth])
    strikes = [i for i in range(1, len(truth))
               if truth[i]["domain"] == "ds_h" and truth[i - 1]["domain"] != "ds_h"]
    speeds = np.diff(x[strikes]) / np.diff(t[strikes])
    assert len(speeds) >= 4 and t[strikes[-2]] > 4.0
    assert speeds[0] == pytest.approx(1.0, abs=0.02)
    assert speeds[-1] == pytest.approx(1.1, abs=0.02)
    recording = read_recording(rec, messages=False)
    assert "library.json" in recording.attachments
    assert recording.metadata["speed"] == {"profile": "0:1,4:1.1", "start": "1.0"}
    assert replay(rec).max_torque_diff == 0.0
    # what the controller made of it (its measurements replayed through its file): its
    # estimate reads the strides' speeds, one stance late; the export carries it
    table = run_table(rec)
    assert table.speed is not None
    est = table.speed.estimate
    assert est[0] == 1.0 and est[-1] == pytest.approx(speeds[-1], abs=0.02)
    assert np.nanmax(table.speed.command) == pytest.approx(1.1)
    library, profile = load_gait_library(lib), SpeedProfile.parse(command)
    ctl = load_controller_file(ensure_following_file(lib, library), 1.0)
    plant = SimulatorPlant(loop_simulator(library.model, library.gait_at(1.0), GAINS),
                           *start_at(library, 1.0), gaits=speed_schedule(library, profile))
    log = run_loop(plant, ControllerLink(ctl, quantize=True), steps=steps)
    assert log.fall is None and log.steps == steps
    gt, q = np.array([o["q"] for o in truth]), np.array(log.q)
    n = min(len(gt), len(q))
    assert n >= res.ticks - 1
    assert np.abs(gt[:n] - q[:n]).max() <= 1e-6  # the same generated C, the same schedule
    other = tmp_path / "openofm.json"
    write_gait_file(other)
    bad = hpcosim("run", "--controller", "clfqp", "--gait", str(other), "--library",
                  str(lib), "--steps", "1")
    assert bad.returncode == 2 and "subject and device" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
