"""Force-tube fit (paper Sec. IV-B): the two LPs, their certificate, the credibility numbers
(REFERENCE.md section 2), the single-support rule, the figure and the artifact round trip."""

from __future__ import annotations

import itertools
from fractions import Fraction
from math import comb
from types import SimpleNamespace

import numpy as np
import pytest

from characterization.gait.bezier_fit import FitError
from characterization.tube import fit as ftf
from hp_model import bezier
from hp_model.force_tube import COMPONENTS, load_tube, save_tube

TAU_LO, TAU_HI = 0.15, 0.85
SCALE = np.array([30.0, 80.0, 5.0])  # N, N, N m


def synthetic_profiles(n_steps=20, n=150, degree=5, seed=7, lo=TAU_LO, hi=TAU_HI):
    """Random degree-5 Bezier deviations (a common shape + per-step variation) plus noise,
    sampled at irregular phases covering [lo, hi]."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(3, degree + 1)) * SCALE[:, None]
    out = []
    for _ in range(n_steps):
        tau = np.sort(rng.uniform(lo, hi, n))
        tau[0], tau[-1] = lo, hi
        a = base + 0.15 * rng.normal(size=base.shape) * SCALE[:, None]
        y = bezier.evaluate(a, (tau - lo) / (hi - lo))
        out.append((tau, y + 0.02 * rng.normal(size=y.shape) * SCALE))
    return out


@pytest.fixture(scope="module")
def profiles():
    return synthetic_profiles()


@pytest.fixture(scope="module")
def nominal():
    return np.random.default_rng(1).normal(size=(3, 7)) * SCALE[:, None]


@pytest.fixture(scope="module")
def tube(profiles, nominal):
    return ftf.fit_tube(profiles, nominal, TAU_LO, TAU_HI, degree=3, gait_hash="g123",
                        source={"take": "synthetic"})


def _pooled(profiles):
    s = np.concatenate([(t - TAU_LO) / (TAU_HI - TAU_LO) for t, _ in profiles])
    y = np.concatenate([d for _, d in profiles])
    return s, y


# ------------------------------------------------------------------ fit and certificate

def test_every_profile_inside(tube, profiles):
    assert tube.n_steps == 20 and tube.degree == 3 and tube.gait_hash == "g123"
    for tau, dF in profiles:
        lo, hi = tube.delta_bounds(tau)
        tol = 1e-9 * SCALE.max()
        assert np.all(dF >= lo - tol) and np.all(dF <= hi + tol)
        assert tube.contains(tau, dF, tol=1e-9 * np.abs(dF).max()).all()
    assert tube.credibility["certificate"] == {**tube.credibility["certificate"],
                                               "inside": True, "tight": True, "optimal": True}
    assert tube.credibility["certificate"]["max_rel_excess"] <= 1e-9
    assert tube.credibility["certificate"]["not_tight"] == []


def test_tightness_literally(tube, profiles):
    """Each coefficient moved inward (upper down, lower up) by 1e-6 x scale excludes a
    sample; a generic LP vertex has exactly degree + 1 active samples per bound."""
    s, y = _pooled(profiles)
    B = bezier.basis(3, s)
    for c in range(3):
        sc = np.abs(y[:, c]).max()
        for coeffs, sign in ((tube.upper[c], 1.0), (tube.lower[c], -1.0)):
            slack = sign * (B @ coeffs - y[:, c])
            assert slack.min() >= -1e-9 * sc
            assert np.sum(slack <= 1e-8 * sc) == 4
            for i in range(4):
                moved = coeffs.copy()
                moved[i] -= sign * 1e-6 * sc
                assert (sign * (B @ moved - y[:, c])).min() < -1e-9 * sc, (c, sign, i)


def test_certify_detects_loose_and_violating_bounds(tube, profiles):
    cert = ftf.certify(profiles, tube.lower, tube.upper, TAU_LO, TAU_HI)
    assert cert["inside"] and cert["tight"] and cert["optimal"]
    for name in COMPONENTS:
        for side in ("lower", "upper"):
            v = cert["components"][name][side]
            assert v["n_active"] == 4 and v["kkt_residual"] < 1e-8
            assert all(m is not None and m <= 1e-8 * cert["components"][name]["scale"]
                       for m in v["inward_margin"])
    loose = tube.upper.copy()
    loose[1, 2] += 1.0  # one coefficient of the F_z upper bound pushed out by 1 N
    c2 = ftf.certify(profiles, tube.lower, loose, TAU_LO, TAU_HI)
    zu = c2["components"]["F_z"]["upper"]
    assert c2["inside"] and not c2["tight"] and not c2["optimal"]
    # the formerly active samples are now B_2(s_j) x 1 N away: no small inward move of any
    # coefficient re-touches; coefficient 2 must move back exactly 1 N
    assert zu["coefficient_tight"] == [False] * 4 and zu["n_active"] == 0
    assert zu["inward_margin"][2] == pytest.approx(1.0, rel=1e-6)
    assert min(zu["inward_margin"]) > 1e-3
    inner = tube.lower.copy()
    inner[2] += 0.01  # M_y lower bound raised by 0.01 N m everywhere
    c3 = ftf.certify(profiles, inner, tube.upper, TAU_LO, TAU_HI)
    assert not c3["inside"]
    assert c3["components"]["M_y"]["lower"]["max_excess"] == pytest.approx(0.01, rel=1e-6)


def test_lp_agrees_with_full_interior_point_lp(profiles):
    lo, hi = ftf.fit_bounds(profiles, TAU_LO, TAU_HI, 3)
    lo2, hi2 = ftf.fit_bounds(profiles, TAU_LO, TAU_HI, 3, method="highs-ipm", reduce=False)
    np.testing.assert_allclose(lo, lo2, atol=1e-7 * SCALE.max())
    np.testing.assert_allclose(hi, hi2, atol=1e-7 * SCALE.max())


def test_lp_agrees_with_vertex_enumeration():
    """Small instance (4 steps x 8 samples, degree 3): every basic solution (4 samples on the
    curve) is enumerated; the best feasible one is the LP optimum."""
    profs = synthetic_profiles(n_steps=4, n=8, seed=3)
    lo, hi = ftf.fit_bounds(profs, TAU_LO, TAU_HI, 3)
    s, y = _pooled(profs)
    B = bezier.basis(3, s)
    w = bezier.integral_weights(3)
    subsets = np.array(list(itertools.combinations(range(len(s)), 4)))
    Bs = B[subsets]
    ok = np.abs(np.linalg.det(Bs)) > 1e-12
    for c in range(3):
        alphas = np.linalg.solve(Bs[ok], y[subsets[ok], c][..., None])[..., 0]
        curves = alphas @ B.T  # (n_vertices, n_samples)
        tol = 1e-9 * np.abs(y[:, c]).max()
        for coeffs, sign in ((hi[c], 1.0), (lo[c], -1.0)):
            feas = np.all(sign * (curves - y[:, c]) >= -tol, axis=1)
            vals = sign * alphas[feas] @ w
            best = alphas[feas][np.argmin(vals)]
            assert sign * coeffs @ w == pytest.approx(vals.min(), abs=1e-9 * SCALE.max())
            np.testing.assert_allclose(coeffs, best, atol=1e-6 * SCALE.max())


# -------------------------------------------------------------------------- credibility

def _tail(eps, d, N):
    return sum(comb(N, i) * eps**i * (1 - eps) ** (N - i) for i in range(d))


def test_scenario_epsilon():
    assert ftf.scenario_epsilon(4, 20, 0.05) == pytest.approx(0.344, abs=0.001)
    assert ftf.scenario_epsilon(1, 20, 0.05) == pytest.approx(0.139, abs=0.001)
    for d in (1, 2, 4, 7):
        assert _tail(ftf.scenario_epsilon(d, 20, 0.05), d, 20) == pytest.approx(0.05, rel=1e-9)
    assert ftf.scenario_epsilon(24, 20) == 1.0
    assert ftf.scenario_epsilon(4, 200) < ftf.scenario_epsilon(4, 20)


def test_aposteriori_epsilon_reference_values():
    eps = [ftf.aposteriori_epsilon(k, 20, 0.05) for k in range(21)]
    assert eps[:3] == pytest.approx([0.20, 0.29, 0.37], abs=0.01)
    assert eps[:3] == pytest.approx([0.1966, 0.2907, 0.3674], abs=1e-4)
    assert eps[20] == 1.0 and all(a < b for a, b in itertools.pairwise(eps))
    for k in (0, 1, 2, 5, 19):  # the defining polynomial, in exact rational arithmetic
        t = Fraction(1 - eps[k])
        lhs = comb(20, k) * t ** (20 - k)
        rhs = Fraction(5, 100) / 20 * sum(comb(i, k) * t ** (i - k) for i in range(k, 20))
        assert float(lhs - rhs) == pytest.approx(0.0, abs=1e-12 * float(lhs))
    assert ftf.aposteriori_epsilon(4, 1000, 0.05) < 0.02  # large N: numerically stable


def test_credibility_numbers(tube, profiles):
    cr = tube.credibility
    assert cr["N"] == 20 and cr["degree"] == 3 and cr["beta"] == 0.05
    ap = cr["a_priori"]
    assert ap["epsilon_per_curve"] == pytest.approx(0.344, abs=0.001)
    assert ap["fixed_shape_scale_epsilon"] == pytest.approx(0.139, abs=0.001)
    assert ap["union"]["vacuous"] and ap["union"]["d_joint"] == 24
    assert ap["union"]["epsilon_bonferroni_raw"] > 1 and ap["union"]["epsilon_joint"] == 1.0
    assert "vacuous" in ap["union"]["statement"]
    post = cr["a_posteriori"]
    s, y = _pooled(profiles)
    step = np.concatenate([np.full(len(t), i) for i, (t, _) in enumerate(profiles)])
    B = bezier.basis(3, s)
    touch = set()
    for c in range(3):
        sc = np.abs(y[:, c]).max()
        for name, coeffs, sign in (("upper", tube.upper[c], 1.0), ("lower", tube.lower[c], -1)):
            act = sign * (B @ coeffs - y[:, c]) <= 1e-8 * sc
            steps_c = sorted(set(step[act].tolist()))
            pc = post["per_curve"][f"{COMPONENTS[c]}.{name}"]
            assert pc["steps"] == steps_c and pc["k"] == len(steps_c)
            assert pc["epsilon_aposteriori"] == ftf.aposteriori_epsilon(len(steps_c), 20)
            touch |= set(steps_c)
    assert post["touching_steps"] == sorted(touch) and post["k_tube"] == len(touch)
    assert post["epsilon_tube"] == ftf.aposteriori_epsilon(len(touch), 20)
    assert post["compression_verified"] and post["compression_max_rel_error"] < 1e-6
    assert "not independent" in cr["independence_note"]
    again = ftf.credibility(profiles, tube.lower, tube.upper, TAU_LO, TAU_HI)
    assert again == {k: v for k, v in cr.items() if k != "certificate"}


def test_leave_one_out_equals_direct_count(tube, profiles):
    loo = tube.credibility["leave_one_out"]
    direct = []
    for i in range(len(profiles)):
        rest = profiles[:i] + profiles[i + 1:]
        lo, hi = ftf.fit_bounds(rest, TAU_LO, TAU_HI, 3)  # every step refitted, no shortcut
        s = (profiles[i][0] - TAU_LO) / (TAU_HI - TAU_LO)
        tol = 1e-9 * np.abs(np.concatenate([d for _, d in profiles])).max(axis=0)
        dF = profiles[i][1]
        direct.append(bool(np.all(dF >= bezier.evaluate(lo, s) - tol)
                           and np.all(dF <= bezier.evaluate(hi, s) + tol)))
    assert 0.0 <= loo["coverage"] <= 1.0
    assert loo["coverage"] == pytest.approx(np.mean(direct))
    assert loo["inside"] == sum(direct)
    assert loo["outside_steps"] == [i for i, d in enumerate(direct) if not d]
    # a step that touches no bound stays inside its leave-one-out tube
    assert set(loo["outside_steps"]) <= set(tube.credibility["a_posteriori"]["touching_steps"])


def test_markdown_report(tube):
    md = ftf.credibility_markdown(tube.credibility)
    assert "| a priori, per bound curve (d = 4) | - | 0.344 |" in md
    assert "(vacuous)" in md and "0.139" in md and "not independent" in md
    k = tube.credibility["a_posteriori"]["k_tube"]
    eps = tube.credibility["a_posteriori"]["epsilon_tube"]
    assert f"| {k} | {eps:.3f} |" in md


# ---------------------------------------------------------------------------- bad input

@pytest.mark.parametrize(("mutate", "message"), [
    (lambda p: [], "no profiles"),
    (lambda p: p[:3], "3 profiles cannot support a degree-3 bound"),
    (lambda p: [p[0], p[1], (p[2][0], np.where(np.arange(150)[:, None] == 5, np.nan,
                                               p[2][1])), *p[3:]], "profile 2: non-finite dF"),
    (lambda p: [(np.r_[p[0][0][:-1], np.inf], p[0][1]), *p[1:]], "profile 0: non-finite tau"),
    (lambda p: [*p[:4], (p[4][0] + 0.01, p[4][1]), *p[5:]], "profile 4: tau in"),
    (lambda p: [*p[:1], (p[1][0], p[1][1][:, :2]), *p[2:]], "profile 1: dF has shape"),
    (lambda p: [(np.full(3, 0.5), np.zeros((3, 3)))] * 5, "distinct sample phases"),
    (lambda p: [(t[t < 0.5], d[t < 0.5]) for t, d in p], "unbounded"),
])
def test_bad_inputs(profiles, nominal, mutate, message):
    with pytest.raises(ftf.TubeFitError, match=message) as e:
        ftf.fit_tube(mutate(list(profiles)), nominal, TAU_LO, TAU_HI, degree=3)
    assert isinstance(e.value, FitError) and "\n" not in str(e.value)


def test_bad_arguments(profiles, nominal):
    with pytest.raises(ftf.TubeFitError, match="degree must be"):
        ftf.fit_tube(profiles, nominal, TAU_LO, TAU_HI, degree=-1)
    with pytest.raises(ftf.TubeFitError, match="tau_lo < tau_hi"):
        ftf.fit_tube(profiles, nominal, TAU_HI, TAU_LO)
    with pytest.raises(ftf.TubeFitError, match="nominal coefficients must have shape"):
        ftf.fit_tube(profiles, nominal[:2], TAU_LO, TAU_HI)
    with pytest.raises(ftf.TubeFitError, match="beta"):
        ftf.fit_tube(profiles, nominal, TAU_LO, TAU_HI, beta=1.5)


# ------------------------------------------------- nominal, profiles, single support

def test_nominal_coefficients_refit_exactly():
    coeffs = np.random.default_rng(2).normal(size=(3, 6)) * SCALE[:, None]
    gait = SimpleNamespace(socket_nominal=coeffs,
                           socket_force=lambda t: bezier.evaluate(coeffs, np.clip(t, 0, 1)))
    for src in (gait, coeffs):
        sub = ftf.nominal_coefficients(src, 0.2, 0.7)
        assert sub.shape == (3, 6)
        tau = np.linspace(0.2, 0.7, 57)
        np.testing.assert_allclose(bezier.evaluate(sub, (tau - 0.2) / 0.5),
                                   bezier.evaluate(coeffs, tau), atol=1e-9 * SCALE.max())
    with pytest.raises(ftf.TubeFitError, match="not inside"):
        ftf.nominal_coefficients(coeffs, 0.2, 1.2)


def test_deviation_profiles_restrict_and_subtract():
    nom = np.array([[1.0, 2.0], [10.0, 10.0], [0.0, -1.0]])  # over s in [0, 1]
    tau = np.linspace(0, 1, 11)
    F = np.tile([5.0, 20.0, 1.0], (11, 1))
    (t, d), = ftf.deviation_profiles([(tau, F)], nom, 0.2, 0.6)
    np.testing.assert_allclose(t, [0.2, 0.3, 0.4, 0.5, 0.6])
    s = (t - 0.2) / 0.4
    np.testing.assert_allclose(d, np.c_[4 - s, np.full(5, 10.0), 1 + s])
    with pytest.raises(ftf.TubeFitError, match="step 0: no sample"):
        ftf.deviation_profiles([(tau[:2], F[:2])], nom, 0.2, 0.6)


def _step_signals(lift, touch, n=121, rate=120.0):
    """tau in [0, 1] over a step; the human foot lifts at tau = lift, lands at tau = touch."""
    tau = np.linspace(0, 1, n)
    swing = (tau >= lift) & (tau <= touch)
    speed = np.where(swing, 1.5, 0.0)  # m/s forward while swinging
    x = np.cumsum(speed) / rate
    height = np.where(swing, 0.05 * np.sin(np.pi * (tau - lift) / (touch - lift)) + 0.03, 0.0)
    return tau, x, height, ~swing, rate


def test_single_support_interval_rules():
    tau, x, h, contact, rate = _step_signals(0.2, 0.8)
    a, b = ftf.single_support_interval(tau, contact=contact)
    assert (a, b) == pytest.approx((0.2, 0.8), abs=1e-12)
    assert ftf.single_support_interval(tau, foot_height=h, height_threshold=0.01) == \
        pytest.approx((0.2, 0.8), abs=1e-12)
    a, b = ftf.single_support_interval(tau, foot_x=x, rate=rate)  # the paper's x rule
    assert a == pytest.approx(0.2, abs=0.01) and b == pytest.approx(0.8, abs=0.01)
    with pytest.raises(ftf.TubeFitError, match="exactly one"):
        ftf.single_support_interval(tau, contact=contact, foot_x=x)
    with pytest.raises(ftf.TubeFitError, match="never leaves the ground"):
        ftf.single_support_interval(tau, contact=np.ones_like(tau, bool))
    with pytest.raises(ftf.TubeFitError, match="frame rate"):
        ftf.single_support_interval(tau, foot_x=x)


def test_tube_interval_aggregates_latest_lift_off_and_earliest_touch_down():
    per = [ftf.single_support_interval(t, contact=c) for t, _, _, c, _ in
           (_step_signals(0.2, 0.8), _step_signals(0.25, 0.85), _step_signals(0.15, 0.75))]
    assert ftf.tube_interval(per) == pytest.approx((0.25, 0.75))
    with pytest.raises(ftf.TubeFitError, match="share no single-support"):
        ftf.tube_interval([(0.1, 0.3), (0.4, 0.9)])
    with pytest.raises(ftf.TubeFitError, match="no single-support intervals"):
        ftf.tube_interval([])


def test_tube_interval_from_steps_artifact():
    taus = [np.linspace(0, 1, 11), np.linspace(0, 1, 21), np.linspace(0, 1, 11)]
    steps = SimpleNamespace(
        n_steps=3, step_domain=np.array(["ps", "pns", "ps"]),
        step_start=np.array([0, 10, 30]), step_end=np.array([10, 30, 40]),
        step_ss_start=np.array([2, 12, 33]), step_ss_end=np.array([8, 28, 39]),
        tau=np.concatenate(taus), tau_offsets=np.array([0, 11, 32, 43]))
    steps.step_tau = lambda i: steps.tau[steps.tau_offsets[i]:steps.tau_offsets[i + 1]]
    lo, hi, per = ftf.tube_interval_from_steps(steps)
    assert per == [pytest.approx((0.2, 0.8)), pytest.approx((0.3, 0.9))]
    assert (lo, hi) == pytest.approx((0.3, 0.8))


# ------------------------------------------------------------------ artifact and figure

def test_save_load_round_trip(tube, tmp_path):
    p = tmp_path / "tube.json"
    save_tube(p, tube)
    t2 = load_tube(p, gait_hash="g123")
    for name in ("nominal", "lower", "upper"):
        np.testing.assert_array_equal(getattr(t2, name), getattr(tube, name))
    assert (t2.tau_lo, t2.tau_hi, t2.n_steps) == (TAU_LO, TAU_HI, 20)
    assert t2.credibility == tube.credibility
    assert t2.source["take"] == "synthetic" and t2.source["n_samples"] == 3000
    with pytest.raises(ValueError, match="refit the tube"):
        load_tube(p, gait_hash="other")


def test_allowance_widens_every_bound_in_use_and_round_trips(profiles, nominal, tmp_path):
    allow = np.array([2.0, 3.0, 0.5])
    bare = ftf.fit_tube(profiles, nominal, TAU_LO, TAU_HI, degree=3, gait_hash="g")
    wide = ftf.with_allowance(ftf.fit_tube(profiles, nominal, TAU_LO, TAU_HI, degree=3,
                                           gait_hash="g"), allow)
    # the certified LP bounds are the same; the bounds in use are shifted by the allowance
    np.testing.assert_array_equal(wide.lower, bare.lower)
    tau = np.linspace(TAU_LO, TAU_HI, 7)
    (lo_w, hi_w), (lo_b, hi_b) = wide.delta_bounds(tau), bare.delta_bounds(tau)
    np.testing.assert_allclose(lo_w, lo_b - allow, atol=1e-9)
    np.testing.assert_allclose(hi_w, hi_b + allow, atol=1e-9)
    c_w, r_w = wide.box(0.5)
    c_b, r_b = bare.box(0.5)
    np.testing.assert_allclose(c_w, c_b, atol=1e-9)
    np.testing.assert_allclose(r_w, r_b + allow, atol=1e-9)
    p = tmp_path / "tube.json"
    save_tube(p, wide)
    np.testing.assert_array_equal(load_tube(p).allowance, allow)
    with pytest.raises(ftf.TubeFitError, match="allowance"):
        ftf.with_allowance(ftf.fit_tube(profiles, nominal, TAU_LO, TAU_HI, degree=3),
                           (1.0, -1.0, 0))


def test_figure_written_atomically(tube, profiles, tmp_path):
    p = tmp_path / "fig5.png"
    ftf.save_tube_figure(p, tube, profiles)
    data = p.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    assert [f.name for f in tmp_path.iterdir()] == ["fig5.png"]
    with pytest.raises(ValueError, match="png, pdf or svg"):
        ftf.save_tube_figure(tmp_path / "fig5.jpg", tube, profiles)
