"""Sweeps against a human that is not the controller's model: the plant's body, the human's
tracking stiffness and delay, encoder noise and quantization, and the oracle that labels a
draw walkable (issue: the interaction-aware robust CLF-QP)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hp_model.closed_loop import ClosedLoop
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.falls import FallReason
from hp_model.force_tube import save_tube
from hp_model.human_prosthesis import BodyVariation, HumanProsthesisModel
from hp_model.simulator import HybridSimulator
from orchestrator.experiments.scenarios import (
    ORACLE,
    Scenario,
    initial_state,
    oracle_thetas,
    run_scenario,
)
from orchestrator.loop import Encoder
from orchestrator.sweep.draws import SEGMENTS, Draw, make_draw
from orchestrator.sweep.runs import Artifacts, Resources, human_gains, run_draw
from orchestrator.sweep.spec import SpecError, load_spec
from orchestrator.sweep.store import read_results
from tests.controller_support import tube_about_nominal

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT / "tests" / "data" / "playback" / "gait_synthetic.json"

SPEC = """
name = "families"
gait = "{gait}"
tube = "{tube}"
controllers = ["clfqp", "pd"]
draws = {draws}
seed = 11
steps = 1
batch = 4

[families.body]
plant.segment_mass = {{ dist = "uniform", low = 0.8, high = 1.2 }}
plant.hat_com = {{ dist = "uniform", low = 0.8, high = 1.2 }}
plant.iwalk_mass = {{ dist = "uniform", low = 0.8, high = 1.2 }}

[families.tracking]
human.stiffness = {{ dist = "uniform", low = 0.5, high = 1.0 }}
human.delay = {{ dist = "uniform", low = 0.0, high = 0.03 }}

[families.sensor]
sensor.angle_noise = {{ dist = "uniform", low = 0.0, high = 5e-4 }}
sensor.velocity_noise = 0.05
sensor.angle_resolution = {{ dist = "choice", values = [3.835e-4, 9.59e-5] }}
sensor.velocity_resolution = 0.01
sensor.imu_bias = {{ dist = "uniform", low = -0.035, high = 0.035 }}
"""


@pytest.fixture(scope="module")
def spec_file(tmp_path_factory, playback_gait):
    d = tmp_path_factory.mktemp("families")
    tube = d / "tube.json"
    save_tube(tube, tube_about_nominal(playback_gait, (40.0, 60.0, 8.0)))
    p = d / "spec.toml"
    p.write_text(SPEC.format(gait=GAIT, tube=tube, draws=2))
    return p


# ------------------------------------------------------------------ the plant's body

def test_body_variation_scales_the_human_segments_only(model):
    b = BodyVariation(hat_mass=1.1, thigh_mass=0.9, shank_mass=1.2, foot_mass=0.8,
                      hat_com=1.15, iwalk_mass=0.85)
    v = HumanProsthesisModel(model.subject, model.device, b)
    t0, t1 = model.tree, v.tree
    for body, k in (("hat", 1.1), ("l_thigh", 0.9), ("l_shank", 1.2), ("l_foot", 0.8)):
        assert math.isclose(t1.body(body).mass, k * t0.body(body).mass, rel_tol=1e-12)
        # same radius of gyration: the inertia about the COM scales with the mass
        assert math.isclose(t1.body(body).inertia, k * t0.body(body).inertia, rel_tol=1e-12)
    assert math.isclose(t1.body("hat").com[1], 1.15 * t0.body("hat").com[1], rel_tol=1e-12)
    # the lumped right thigh: thigh, folded shank and foot, iWalk
    iw = model.device.iwalk.mass.value
    expect = (0.9 * t0.body("l_thigh").mass + 1.2 * t0.body("l_shank").mass
              + 0.8 * t0.body("l_foot").mass + 0.85 * iw)
    assert math.isclose(t1.body("r_thigh").mass, expect, rel_tol=1e-12)
    for body in ("p_top", "p_shin", "p_foot"):  # the prosthesis is untouched
        assert t1.body(body) == t0.body(body)
    assert v.parameter_hash() != model.parameter_hash()
    nominal = HumanProsthesisModel(model.subject, model.device, BodyVariation())
    assert nominal.parameter_hash() == model.parameter_hash()  # files made before stay valid
    with pytest.raises(ValueError, match="hat_com"):
        BodyVariation(hat_com=0.0)


# ------------------------------------------------------------------ the delayed human

@pytest.fixture(scope="module")
def loop(model, playback_gait):
    cl = ClosedLoop(model, playback_gait.degree)
    th = {d: playback_gait.theta(d) for d in PAPER_DOMAINS}
    return cl, th, initial_state(model, playback_gait)


def test_a_human_without_delay_is_the_continuous_human_sampled(model, playback_gait, loop):
    """Delay 0: the feedback term held over 1 ms instead of continuous. The tracking error
    it adds is O(dt) relative: the joint trajectories agree to well under a milliradian
    over a whole step, and both walk."""
    cl, th, (q0, qd0) = loop
    g = playback_gait.gains_array
    a = HybridSimulator(model, cl, th, g).run(q0, qd0, Domain.PS, steps=2)
    b = HybridSimulator(model, cl, th, g, human_delay=0.0).run(q0, qd0, Domain.PS, steps=2)
    assert not a.failed and not b.failed and a.steps == b.steps == 2
    n = min(a.t.size, b.t.size) - 5
    assert np.max(np.abs(a.q[:n, 3:] - b.q[:n, 3:])) < 1e-3
    assert abs(a.impacts[0].t - b.impacts[0].t) < 2e-3


def test_a_late_stiff_human_falls_where_a_soft_one_walks(model, playback_gait, loop):
    """A 30 ms feedback delay on the stiff human (40 rad/s bandwidth: 69 deg of phase lag)
    makes it fall; at half the bandwidth (34 deg) the same delay walks. Neither happens with
    the continuous human, which walks both."""
    cl, th, (q0, qd0) = loop
    g = playback_gait.gains_array
    soft = g * np.array([0.5, 0.25, 0.5])
    late_stiff = HybridSimulator(model, cl, th, g, human_delay=0.03).run(q0, qd0, Domain.PS,
                                                                         steps=3)
    late_soft = HybridSimulator(model, cl, th, soft, human_delay=0.03).run(q0, qd0, Domain.PS,
                                                                           steps=3)
    assert late_stiff.fall is not None and late_stiff.fall.reason is FallReason.FRICTION_CONE
    assert not late_soft.failed and late_soft.steps == 3
    with pytest.raises(ValueError, match="human_delay"):
        HybridSimulator(model, cl, th, g, human_delay=-0.01)


def test_human_stiffness_scales_the_bandwidth_at_the_same_damping(playback_gait):
    eps, kp, kd = playback_gait.gains_array
    g = human_gains(playback_gait, Draw("x", 0, human_stiffness=0.5))
    assert np.allclose(g, [0.5 * eps, 0.25 * kp, 0.5 * kd])
    # damping ratio kd / (2 sqrt(kp)) unchanged
    assert math.isclose(g[2] / (2 * math.sqrt(g[1])), kd / (2 * math.sqrt(kp)))


# ------------------------------------------------------------------ encoders

def test_encoder_quantizes_and_adds_noise_of_the_given_spread():
    rng = np.random.default_rng(0)
    q = Encoder(angle_resolution=1e-3, velocity_resolution=0.01)
    a, v = q.read(rng, np.array([0.12345, -0.5004]), np.array([1.234, -0.005]))
    assert np.allclose(a, [0.123, -0.500]) and np.allclose(v, [1.23, -0.0])
    n = Encoder(angle_noise=2e-4, velocity_noise=0.05)
    samples = np.array([np.r_[n.read(rng, np.zeros(2), np.zeros(2))] for _ in range(4000)])
    # standard deviation of a sample std of 4000 draws: 1.1 % (5 sigma: 6 %)
    assert np.allclose(samples[:, :2].std(axis=0), 2e-4, rtol=0.06)
    assert np.allclose(samples[:, 2:].std(axis=0), 0.05, rtol=0.06)
    assert Encoder().ideal and not n.ideal
    with pytest.raises(ValueError, match="angle_noise"):
        Encoder(angle_noise=-1.0)


def test_imu_bias_and_noise_on_the_socket_pitch_leave_the_encoder_noise_alone():
    imu = Encoder(imu_bias=0.02, imu_noise=3e-3)
    rng = np.random.default_rng(1)
    p = np.array([imu.pitch(rng, 0.3) for _ in range(4000)])
    # the sample mean of 4000 draws: 3e-3 / sqrt(4000) = 4.7e-5 (5 sigma: 2.4e-4)
    assert abs(p.mean() - 0.32) < 2.4e-4 and p.std() == pytest.approx(3e-3, rel=0.06)
    assert not imu.ideal and not Encoder(imu_bias=-0.01).ideal
    assert Encoder(imu_bias=0.01).pitch(np.random.default_rng(0), 0.3) == 0.31  # no draw
    # a noiseless IMU draws nothing: the encoders' noise sequence is that of no IMU
    enc = dict(angle_noise=2e-4, velocity_noise=0.05)
    a = Encoder(**enc, imu_bias=0.05)
    r1, r2 = np.random.default_rng(5), np.random.default_rng(5)
    for _ in range(3):
        a.pitch(r1, 0.0)
        assert np.array_equal(np.r_[a.read(r1, np.zeros(2), np.zeros(2))],
                              np.r_[Encoder(**enc).read(r2, np.zeros(2), np.zeros(2))])
    with pytest.raises(ValueError, match="imu_noise"):
        Encoder(imu_noise=-1.0)
    with pytest.raises(ValueError, match="imu_bias"):
        Encoder(imu_bias=math.inf)


# ------------------------------------------------------------------ draws and spec

def test_plant_and_sensor_draws_stay_in_their_ranges(spec_file):
    spec = load_spec(spec_file.parent / spec_file.name, {"draws": 200})
    body = [make_draw(spec, "body", i) for i in range(200)]
    seg = np.array([d.segment_mass for d in body])
    assert seg.shape == (200, len(SEGMENTS)) and seg.min() >= 0.8 and seg.max() <= 1.2
    # each segment draws its own number
    assert abs(np.corrcoef(seg[:, 0], seg[:, 1])[0, 1]) < 0.25
    assert all(d.human_delay is None and d.sensor_seed == 0 for d in body)
    tr = [make_draw(spec, "tracking", i) for i in range(200)]
    assert all(0.5 <= d.human_stiffness <= 1.0 and 0.0 <= d.human_delay <= 0.03 for d in tr)
    se = [make_draw(spec, "sensor", i) for i in range(200)]
    assert {d.angle_resolution for d in se} == {3.835e-4, 9.59e-5}
    assert len({d.sensor_seed for d in se}) == 200
    bias = np.array([d.imu_bias for d in se])
    assert -0.035 <= bias.min() < -0.03 and 0.03 < bias.max() <= 0.035
    assert all(d.imu_noise == 0.0 for d in se)
    row = se[3].columns()
    assert Draw.from_columns("sensor", 3, row) == se[3]
    # a row of an older sweep (no IMU columns, or nulls) reads as an ideal IMU
    old = {k: v for k, v in row.items() if k != "draw_imu_bias"} | {"draw_imu_noise": None}
    assert Draw.from_columns("sensor", 3, old) == replace(se[3], imu_bias=0.0)


def test_the_fmu_backend_refuses_what_it_does_not_model(tmp_path, spec_file):
    p = tmp_path / "fmu.toml"
    p.write_text('backend = "fmu"\n' + spec_file.read_text())
    with pytest.raises(SpecError) as e:
        load_spec(p)
    msg = str(e.value)
    assert "\n" not in msg and "family 'body'" in msg and "plant.segment_mass" in msg


# ------------------------------------------------------------------ the oracle

def test_oracle_tracks_the_humans_rows_and_the_nominal_prosthesis(playback_gait):
    from human_fmu.perturbation import perturbed_thetas

    nominal = {d: playback_gait.theta(d) for d in PAPER_DOMAINS}
    pert = perturbed_thetas(nominal, 0.02, 5)
    th = oracle_thetas(playback_gait, pert)
    L = playback_gait.params[Domain.PS].layout
    for d in PAPER_DOMAINS:
        for r, name in enumerate(Domain(d).y2_coords):
            rows = L.row(r)
            src = pert if r + 1 in Domain(d).human_outputs else nominal
            assert np.array_equal(th[d][rows], src[d][rows]), (d, name)
            assert name.startswith("th_p") == (src is nominal)


def test_the_oracle_walks_the_nominal_gait_on_it(model, playback_gait, loop):
    cl, _, _ = loop
    r = run_scenario(model, playback_gait, tube_about_nominal(playback_gait, (40., 60., 8.)),
                     Scenario(ORACLE, steps=3), closed_loop=cl)
    assert r.success and r.steps == 3
    # feedback linearization from a state on the orbit: the knee stays on B_pk(tau)
    assert r.knee_rms(Domain.PS) < 1e-4
    assert np.all(np.isfinite(r.torque))


@pytest.mark.slow
def test_a_sweep_labels_draws_walkable_and_reports_among_them(tmp_path, spec_file):
    from orchestrator.cli import main

    out = tmp_path / "out"
    assert main(["sweep", str(spec_file), "--out", str(out), "--workers", "1"]) == 0
    spec = load_spec(spec_file)
    rows = read_results(out).to_pylist()
    assert len(rows) == spec.n_runs == 3 * 3 * 2  # oracle + 2 controllers, 3 families
    assert all(r["error"] is None for r in rows), [r["error"] for r in rows if r["error"]]
    oracle = {(r["family"], r["draw"]): r["success"] for r in rows
              if r["controller"] == ORACLE}
    assert len(oracle) == 6
    rep = json.loads((out / "report.json").read_text())
    assert rep["walkability_labelled"] and rep["complete"]
    for c in rep["cells"]:
        walkable = sum(oracle[(c["family"], i)] for i in range(spec.draws))
        assert c["walkable_runs"] == walkable
        ok = [r for r in rows if r["controller"] == c["controller"]
              and r["family"] == c["family"] and oracle[(r["family"], r["draw"])]]
        assert c["walkable_successes"] == sum(r["success"] for r in ok)
    assert all("walkable_pairs" in p for p in rep["paired"])
    # the body draws really simulated another walker: a run of the body family replayed
    # on the nominal plant differs
    res = Resources(Artifacts.from_spec(spec))
    try:
        key = next(r for r in rows if r["family"] == "body" and r["controller"] == "pd")
        d = make_draw(spec, "body", key["draw"])
        from orchestrator.sweep.draws import RunKey

        again = run_draw(res, spec, RunKey("pd", "body", d.index), d)
        assert again["duration_s"] == key["duration_s"]
        nominal = run_draw(res, spec, RunKey("pd", "body", d.index),
                           Draw("body", d.index))
        assert nominal["duration_s"] != key["duration_s"] or \
            nominal["knee_rms_ps_rad"] != key["knee_rms_ps_rad"]
    finally:
        res.close()
