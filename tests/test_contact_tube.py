"""``tube fit`` of a multi-contact gait (characterization/tube/contact_playback.py): the
playback of a flat prosthesis single support reproduces the gait's own socket force when the
"recording" is the gait as the model walks it; on openOFM's take (two single supports) the
tube is fitted, written and judged; experiments measure the walks against it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from characterization.gait.contact_gait import GAINS, contact_gait_of, start_state
from characterization.gait.multicontact import TakeStrides
from characterization.gait.multicontact_artifact import load_contact_cycle
from characterization.mocap.session import process_session
from characterization.tube import contact_playback as cp
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain
from hp_model.force_tube import load_tube
from hp_model.leg_kinematics import LegKinematics
from hp_model.simulator import HybridSimulator
from orchestrator.cli import main as hpcosim
from tests.multicontact_cycle import TAKE, write_gait_file


@pytest.fixture(scope="module")
def gait_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("ctube") / "openofm_multicontact.json"
    write_gait_file(path)
    return path


@pytest.fixture(scope="module")
def steps_file(gait_file):
    out = gait_file.parent / "steps.npz"  # as `mocap process`: with the take's subject
    process_session([TAKE / "dynamic.c3d"], out, mapping=TAKE / "mapping.toml",
                    with_figures=False)
    return out


def test_playback_of_the_gaits_own_walk_gives_its_socket_force(gait_file):
    """The gait walked by its own curves, sampled at 100 Hz as a take would be, played back:
    F_s against F* at the same stance phase.  What differs is the fit, not the physics: the
    hip rate regressed as a parabola (contact_playback.RATE_DEGREE) where the gait's curve
    is a quintic, from the 10 ms samples' finite differences; the hip's acceleration error
    is the socket's F_x and M_y error: 12 and 18 % of their peaks over the flat support in
    RMS, within 20 % (10 and 13 % of peaks that were the foot's landing transient, before F*
    left out its first two periods, ``contact_playback.LANDING_PERIODS``; a line leaves 43
    and 52 % of those)."""
    gait = load_contact_cycle(gait_file)
    model = gait.model
    cl = ClosedLoop(model, cp.DEGREE)
    thetas = contact_gait_of(model, gait.trajectory, gait.durations).thetas()
    leg = LegKinematics.of(model)
    nominal = cp.nominal_stance(model, cl, thetas, gait, leg)
    sim = HybridSimulator(model, cl, thetas, np.array(GAINS))
    log = sim.run(*start_state(gait.trajectory), Domain.PS, steps=3, duration=6.0)
    assert log.fall is None
    t, q, code = log.t[::10], log.q[::10], log.domain[::10]
    entries = np.flatnonzero((code[1:] == Domain.PS.code) & (code[:-1] != Domain.PS.code)) + 1
    a = int(entries[-1])
    b = a + int(np.argmax(code[a:] != Domain.PS.code)) - 1  # the last ps sample
    strides = TakeStrides(q, {}, [], {}, [(a, b)])
    sp = cp.play_stride(model, cl, thetas, t, strides, 0, leg, nominal.progress)
    assert not sp.failed, sp.reason
    assert sp.cone_periods == 0
    # the walk's own angles refitted: within half a degree (the human's swing ankle, which
    # the walk follows less closely than its curve)
    assert np.degrees(sp.fit_rms[:-1]).max() < 0.5
    ref = np.column_stack([np.interp(sp.phase, nominal.phase, nominal.socket[:, c])
                           for c in range(3)])
    rms = np.sqrt(np.mean((sp.socket - ref) ** 2, axis=0))
    peak = np.abs(nominal.socket).max(axis=0)
    assert np.all(rms < 0.20 * peak), (rms, peak)


def test_tube_fit_on_a_real_take(gait_file, steps_file, capsys):
    """openOFM's take: its two flat prosthesis single supports played back, a degree-1 tube
    around the gait's F*, written with its figure and report, carrying the degree-1 bound of
    clfqp's model error along the same playbacks (its robust term); two steps certify
    nothing, so `tube fit` says so and exits 1 with the files written."""
    out = gait_file.parent / "tube.json"
    rc = hpcosim(["tube", "fit", str(steps_file), "--gait", str(gait_file), "--out", str(out)])
    text = " ".join(capsys.readouterr().out.split())  # rich wraps its lines
    assert rc == 1
    assert "2 flat prosthesis single supports played back" in text
    assert "certify nothing" in text
    tube = load_tube(out, load_contact_cycle(gait_file).hash)
    assert tube.degree == 1 and tube.n_steps == 2
    assert tube.source["domain_graph"] == "multicontact"
    assert 0.0 < tube.tau_lo < tube.tau_hi < 1.0  # inside the stance, its flat single support
    assert (out.with_name("tube_fig5.png")).stat().st_size > 20_000
    assert "multi-contact graph" in out.with_name("tube.md").read_text()
    me = tube.model_error
    assert me is not None and me.components == ("qdd_pk", "qdd_pa")
    assert me.degree == 1 and me.n_steps == 2
    assert tube.tau_lo <= me.tau_lo < me.tau_hi <= tube.tau_hi
    # every sample inside its own bound (the LPs' constraints); a person's joint
    # accelerations differ from the gait's by tens of rad/s^2, not thousands
    assert me.credibility["samples_inside_fraction"] == 1.0
    assert 0.0 < max(me.source["max_abs"]) < 500.0
    assert "model error of clfqp's model" in text
    assert "Model error of the nominal-human model" in out.with_name("tube.md").read_text()


def test_a_real_takes_socket_force_carries_the_body(gait_file, steps_file):
    """The socket holds the body above it: over each flat single support of openOFM's take the
    played-back socket force's mean magnitude is within 25 % of that weight (the body's
    vertical accelerations in single support are within about 0.2 g)."""
    from characterization.mocap.steps_artifact import load_steps

    gait = load_contact_cycle(gait_file)
    out, skipped, _ = cp.play_strides(gait, load_steps(steps_file))
    assert len(out) == 2 and not skipped
    above = (sum(b.mass for b in gait.model.tree.bodies) - gait.model.prosthesis_mass) * 9.81
    for sp in out:
        mean = np.linalg.norm(sp.socket[:, :2], axis=1).mean()
        assert mean == pytest.approx(above, rel=0.25), (sp.stride, mean, above)


def test_experiments_measure_the_walks_against_the_tube(gait_file, steps_file):
    out = gait_file.parent / "tube2.json"
    hpcosim(["tube", "fit", str(steps_file), "--gait", str(gait_file), "--out", str(out)])
    exp = gait_file.parent / "exp"
    assert hpcosim(["experiments", "--gait", str(gait_file), "--tube", str(out), "--out",
                    str(exp), "--steps", "4", "--draws", "0"]) == 0
    m = json.loads((exp / "metrics.json").read_text())
    inside = m["tube"]["inside"]
    assert set(inside) == {"oracle", "clfqp", "contact-pd", "pd", "passive"}
    assert all(v is None or 0.0 <= v <= 1.0 for v in inside.values())
    assert inside["clfqp"] is not None
    report = (exp / "report.md").read_text()
    assert "Socket force inside the force tube" in report
    # clfqp walked with the tube's model-error bound in its CLF row
    assert m["tube"]["robust_term"] and "carries the tube's bound" in report
    assert m["nominal"]["clfqp"]["walk"]["walks"]


@pytest.mark.parametrize("extra", [["--whole-step-fit"], ["--phase", "step"],
                                   ["--subject", "hp_model/configs/subject_example.toml"]])
def test_paper_options_beside_a_multicontact_gait_are_refused(gait_file, steps_file, tmp_path,
                                                              capsys, extra):
    out = tmp_path / "t.json"
    assert hpcosim(["tube", "fit", str(steps_file), "--gait", str(gait_file), "--out",
                    str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert "multi-contact gait" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_steps_of_another_person_are_refused(gait_file, tmp_path, capsys):
    steps = tmp_path / "other.npz"  # the same take processed as the example subject
    process_session([TAKE / "dynamic.c3d"], steps, mapping=TAKE / "mapping.toml",
                    subject="hp_model/configs/subject_example.toml", with_figures=False)
    out = tmp_path / "t.json"
    assert hpcosim(["tube", "fit", str(steps), "--gait", str(gait_file), "--out",
                    str(out)]) == 2
    err = capsys.readouterr().err
    assert "field 'subject'" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_a_paper_tube_beside_a_multicontact_gait_is_refused(gait_file, tmp_path, capsys):
    paper_tube = "tests/data/controller/tube_demo_v2.json"
    assert hpcosim(["experiments", "--gait", str(gait_file), "--tube", paper_tube, "--out",
                    str(tmp_path / "x")]) == 2
    assert "gait" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
