"""Closed loop of the reduced 4-state prosthesis model alone (RK4, controller ticking with
zero-order hold) with the socket force held at a vertex of the tube: the robust CLF-QP
drives the outputs to the nominal with V decaying exponentially at the promised rate
gamma/eps, i.e. V(t) <= M V(0) exp(-(gamma/eps) t) with a constant M close to 1.

The promise is a continuous-time one; how much of it survives the sample-and-hold depends on
the controller rate against the subsystem's fastest dynamics, so two rates are tested:

- 10 kHz: the full rate, M = 1.15 over 0.15 s (measured worst 1.11, i.e. an effective rate
  >= 14.3 of the promised 15 1/s);
- 1 kHz (the deployed rate): half the rate, M = 1.5 (measured worst decay 9 1/s);

both on the tube +/-(0.1 N, 0.15 N, 0.02 N m) about a constant centre.  Wider boxes (up to
+/-(4 N, 6 N, 0.8 N m) measured) keep the rate at 10 kHz too, but there most runs end on a
torque or per-tick rate bound, where the promise no longer applies.

Why a constant, narrow tube here: in the reduced model the socket force is exogenous and
acts on the prosthesis alone, whose top link (1 kg, 0.0017 kg m^2 about the knee) turns
1 N m of socket moment into ~440 m/s^2 of hip acceleration.  (a) A force that follows
F*(tau(x)) adds a state feedback dF*/dtau dtau/dx that makes the open loop unstable at
~550 1/s, beyond what any 1 kHz hold can track, so the vertex is held constant and the
tube's nominal is that constant.  (b) The worst-case row makes the law act against the
whole box each tick; a vertex other than the worst case then moves the outputs by up to
2 |A_s r| dt per tick, so the continuous-time rate survives the 1 ms hold only while that
is small against eta: r = (0.1 N, 0.15 N, 0.02 N m) gives 2 * 440 * 0.02 * 1e-3 = 0.018
(m/s of y1) per tick.  Wider tubes are a property of the full human-prosthesis loop (the
human's inertia is behind the socket), tested in the co-simulation, not here.

The promise itself is a continuous-time one, and the last test checks it as such on WIDE
tubes about the gait's nominal socket force -- +/-(40 N, 60 N, 8 N m), the tube of the other
controller tests, and +/-(48 N, 100 N, 19 N m), the mean half-widths of the demo subject's
fitted tube -- with the exact law of paper eq. (robust_CLF_QP), which has no torque bound,
recomputed at every RK4 stage: V(t) <= V(0) exp(-(gamma/eps) t) to the integration error (M
= 1.01; measured 1.0002 at h = 50 us and 1.000002 at 20 us on the first, 1.000003 at 10 us
on the second, all 4 starts) at every vertex. The device's torque limits are opened for it
(to 500 motor N m, never reached): the law's peak demand is ~50 motor N m at the ankle on
the first tube and up to ~120 on the second (17x and 40x the estimated AMPRO3 limit),
because its cost |nu|^2 steers nu along grad V, which the ankle moves 500x more weakly than
the knee (Am's singular values ~8e4 and ~150 per motor N m), while cancelling the worst
socket force alone would take < 0.6 motor N m.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import pytest

from prosthesis_controller import ClfConfig, ControllerConfig, ControllerContext, make_controller
from prosthesis_controller.config import SafetyConfig
from prosthesis_controller.interface import Active
from tests.controller_support import (
    clf_terms,
    constant_tube,
    simulate_reduced,
    simulate_reduced_continuous,
    tube_about_nominal,
)

DURATION = 0.15  # s


@dataclass(frozen=True)
class Rate:
    """A controller rate, the constant tube's half-widths (N, N, N m) it is tested on, the
    fraction of the promised decay rate asserted and the constant M of the bound."""

    dt: float
    half: tuple[float, float, float]
    fraction: float
    M: float
    substeps: int


RATES = {
    # the hold of 0.1 ms costs < 0.7 1/s: exp(0.7 * 0.15) = 1.11 measured, 1.15 allowed
    "10kHz": Rate(1e-4, (0.1, 0.15, 0.02), 1.0, 1.15, 2),
    # at 1 kHz over 0.15 s a factor 1.5 on V at half the rate (measured: >= 9 of 15 1/s)
    "1kHz": Rate(1e-3, (0.1, 0.15, 0.02), 0.5, 1.5, 4),
}
PERTURBATIONS = (np.array([0.02, -0.01, 0.1, -0.1]), np.array([-0.03, 0.02, -0.3, 0.2]))
#: start points on the ps collocation trajectory at tau ~ 0.1 and 0.4 (fractions of its points)
NODE_FRACTIONS = (0.1, 0.4)
BOUNDS = (Active.KNEE_LOWER | Active.KNEE_UPPER | Active.ANKLE_LOWER | Active.ANKLE_UPPER
          | Active.OUTPUT_CLAMP)
VERTICES = list(itertools.product((-1.0, 1.0), repeat=3))


def _setup(model, subsystem, gait, clf: ClfConfig, half: tuple[float, float, float]):
    tr = gait.trajectory["ps"]
    centre = tr["lam"][3:6].mean(axis=1)  # the mean nominal socket wrench of the stance
    tube = constant_tube(gait, centre, half)
    ctx = ControllerContext(gait, tube, model, ControllerConfig(clf=clf),
                            subsystem=subsystem)
    return ctx, tube, tr


def _starts(model, tr):
    i = [model.coord_names.index(c) for c in ("th_pk", "th_pa")]
    n = tr["q"].shape[1] - 1
    nodes = [round(f * n) for f in NODE_FRACTIONS]
    for node, p in itertools.product(nodes, PERTURBATIONS):
        yield np.r_[tr["q"][i, node], tr["qd"][i, node]] + p


def _fl_torque(ctx, x):
    """The torque a running controller would hold: nu(u, F*) = 0."""
    T = clf_terms(ctx, x)
    return -np.linalg.solve(T["Am"], T["Lf"] + T["As"] @ T["Fstar"])


@pytest.mark.parametrize("rate", [pytest.param("10kHz", marks=pytest.mark.slow), "1kHz"])
@pytest.mark.parametrize("name", ["clfqp-paper-exact", "clfqp-paper"])
def test_closed_loop_converges_at_the_promised_rate_at_every_vertex(model, subsystem,
                                                                   template_gait, name, rate):
    r = RATES[rate]
    # the relaxed law with a small relaxation cap: it converges into V <= rho_max
    clf = ClfConfig() if name == "clfqp-paper-exact" else ClfConfig(rho_max=0.1)
    ctx, tube, tr = _setup(model, subsystem, template_gait, clf, r.half)
    ctl = make_controller(name, None, None, None, context=ctx)
    c = r.fraction * clf.gamma / clf.eps
    floor = 0.0 if name == "clfqp-paper-exact" else clf.rho_max
    c0, r0 = tube.box(0.5)
    worst = 0.0
    saturated_runs: list = []
    for x0 in _starts(model, tr):
        for s in VERTICES:
            F = c0 + np.array(s) * r0
            run = simulate_reduced(ctl, ctx, x0, lambda x, F=F: F, DURATION, dt=r.dt,
                                   substeps=r.substeps, u0=_fl_torque(ctx, x0))
            assert len(run["t"]) == round(DURATION / r.dt), "state diverged"
            assert set(run["mode"]) == {"stance"}, "fallback in a feasible closed loop"
            V, t = run["V"], run["t"]
            # the rate is promised while the CLF row decides the torque; a torque bound
            # reached overrides it (then only boundedness is asserted, above)
            saturated = np.nonzero(run["active"] & int(BOUNDS))[0]
            if saturated.size:
                V, t = V[: saturated[0]], t[: saturated[0]]
                saturated_runs.append((x0, s))
                if V.size < 2:
                    continue
            bound = V[0] * np.exp(-c * t) + floor
            worst = max(worst, float(np.max(V / bound)))
            assert np.max(V / bound) <= r.M, (x0, s, float(np.max(V / bound)))
            # the phase keeps progressing: |y1| -> 0 means the hip moves at v_hip
            # the walker moves through stance (not a run held still): the phase advances by
            # a third of its nominal progress at least (measured about half)
            assert run["tau"][-1] - run["tau"][0] > DURATION / ctx.durations["ps"] / 3
            assert np.all(np.abs(run["u"]) <= np.array(ctx.limits) + 1e-12)
    print(f"{name}: max V(t) / (V0 exp(-{c:.0f} t) + {floor}) = {worst:.3f}; "
          f"{len(saturated_runs)} runs reached a torque bound")
    assert len(saturated_runs) <= len(VERTICES) * 2, "torque bounds decide most runs"


def _vertex_force(ctx, s):
    """F_s(x) at the vertex of sign pattern s of the tube's box at the phase tau(x)."""
    s = np.asarray(s, dtype=float)

    def force(x):
        T = clf_terms(ctx, x)
        return T["c"].ravel() + s * T["r"].ravel()

    return force


@dataclass(frozen=True)
class Continuous:
    """A continuous-time check from the last perturbed start (tau ~ 0.4, the largest
    perturbation): the tube's half-widths about the nominal (N, N, N m) and the RK4 step (s).
    (All four starts at 20 us on the wide tube: the same ratio, 4x the time.)"""

    half: tuple[float, float, float]
    h: float


CONTINUOUS = {
    # the tube of the other controller tests (conftest ``ctx``); the loop has modes of ~1e4
    # 1/s: on the committed template gait RK4 at h = 50 us gives a ratio of 1.79 (the
    # integration error, not the law), at 20 us the law's rate to 1e-5
    "wide": Continuous((40.0, 60.0, 8.0), 2e-5),
    # the mean half-widths of the demo subject's fitted tube (`make demo`): 1.47 at 50 us
    "demo width": Continuous((48.0, 100.0, 19.0), 1e-5),
}
#: motor N m: opened so that the paper's exact law, which has no torque bound, acts unclamped
OPEN_LIMITS = (500.0, 500.0)


@pytest.mark.parametrize("case", ["wide", pytest.param("demo width", marks=pytest.mark.slow)])
def test_exact_law_keeps_the_promised_rate_in_continuous_time_on_a_wide_tube(
        model, subsystem, template_gait, case):
    """The paper's guarantee as stated: the exact robust CLF-QP as a continuous feedback law,
    the socket force at a vertex of the box at the current phase, F = c(tau) + s r(tau):
    V(t) <= V(0) exp(-(gamma/eps) t) up to the RK4 error, at every vertex."""
    k = CONTINUOUS[case]
    clf = ClfConfig()
    cfg = ControllerConfig(clf=clf, safety=SafetyConfig(torque_limits=OPEN_LIMITS))
    ctx = ControllerContext(template_gait, tube_about_nominal(template_gait, k.half), model,
                            cfg, subsystem=subsystem)
    ctl = make_controller("clfqp-paper-exact", None, None, None, context=ctx)
    c = clf.gamma / clf.eps
    starts = list(_starts(model, template_gait.trajectory["ps"]))[-1:]
    worst, peak = 0.0, np.zeros(2)
    for x0 in starts:
        for s in VERTICES:
            run = simulate_reduced_continuous(ctl, ctx, x0, _vertex_force(ctx, s), DURATION,
                                              k.h)
            assert len(run["t"]) == round(DURATION / k.h), "state diverged"
            assert set(run["mode"]) == {"stance"}, "fallback or fault in the closed loop"
            assert not np.any(run["active"] & int(BOUNDS)), "a torque bound acted"
            ratio = float(np.max(run["V"] / (run["V"][0] * np.exp(-c * run["t"]))))
            worst = max(worst, ratio)
            assert ratio <= 1.01, (x0, s, ratio)
            # the walker moves through stance (not a run held still): the phase advances by
            # a third of its nominal progress at least (measured about half)
            assert run["tau"][-1] - run["tau"][0] > DURATION / ctx.durations["ps"] / 3
            peak = np.maximum(peak, np.abs(run["u"]).max(axis=0))
    print(f"{case}: max V(t) / (V0 exp(-{c:.0f} t)) = {worst:.6f}; peak motor torque "
          f"{peak.round(1)} N m (device limits {np.round(model.torque_limits[4:], 1)})")
