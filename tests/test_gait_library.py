"""The gait library over walking speed (``characterization/gait/library.py``, ``hpcosim gait
library``): the targets at another speed, the artifact read back, the curves between speeds,
and (slow) the packaged person's gait fitted again at 0.9 and 1.25 m/s from its own take,
walked along a changing speed."""

from __future__ import annotations

import json
from pathlib import Path

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
def fitted(tmp_path_factory):
    """`gait library` at 0.9 and 1.25 m/s from the packaged person (1.07 m/s) and its take:
    the command's result and the library file."""
    d = tmp_path_factory.mktemp("fitted-library")
    steps = d / "steps.npz"
    assert person_reference.make_steps(steps, d) == 0
    out = d / "lib.json"
    r = hpcosim("gait", "library", str(steps), "--gait", str(REFERENCE_PERSON_GAIT),
                "--out", str(out), "--speeds", "0.9,1.25")
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
    flat stances (the hip's rate over the flat foot)."""
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
