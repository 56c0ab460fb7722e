"""The CLF-QP on the multi-contact graph (prosthesis_controller.contact_clf_qp, with
hp_model.contact_interaction): its model against the simulator, its QP against a second
solver, its behaviour on bad input, and the committed cycle walked with it in the in-process
plant (the simulated human on its feedback linearization)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import quadprog
from scipy.optimize import minimize

from characterization.gait.contact_gait import GAINS, contact_gait_of, start_state
from characterization.gait.multicontact import GRAPH
from hp_model.contact_interaction import STANCE_DOMAINS, ContactInteraction
from hp_model.domains import PROSTHESIS, Domain
from orchestrator.cosim.contact_controllers import contact_clfqp, loop_simulator
from orchestrator.experiments.contact_walk import CLFQP, walk_controller
from orchestrator.loop.link import Encoder, measurement
from orchestrator.loop.plant import SimulatorPlant
from prosthesis_controller.interface import ControllerMode, ControlOutput
from prosthesis_controller.measurement import ProsthesisMeasurement
from tests.multicontact_cycle import load_cycle

pytestmark = pytest.mark.slow  # about a minute: the committed cycle's model, compiled once

DT = 1e-3  # s, the plant's period


@pytest.fixture(scope="module")
def cycle():
    model, traj, durations, _ = load_cycle()
    return model, traj, durations, contact_gait_of(model, traj, durations)


class Recorded:
    """A controller that keeps what each stance tick of :class:`ContactClfQp` decided."""

    def __init__(self, ctl) -> None:
        self.ctl, self.ticks = ctl, []
        ctl.keep_qp = True

    def reset(self, torque=None) -> None:
        self.ctl.reset(torque)

    def tick(self, m: ProsthesisMeasurement) -> ControlOutput:
        out = self.ctl.tick(m)
        u = tuple(out.torque)
        c = self.ctl
        self.ticks.append((m.contact, u, c.domain, c.solved, c.sigma, c.qp, c.rho, m))
        c.qp = None
        return out


@pytest.fixture(scope="module")
def walk(cycle):
    model, traj, _, gait = cycle
    rec = Recorded(contact_clfqp(model, gait, traj))
    return rec, walk_controller(loop_simulator(model, gait, GAINS), traj, rec, 20, CLFQP)


def test_the_interaction_model_predicts_the_simulators_joint_accelerations(cycle) -> None:
    """At the walker's true state, under the torque the held oracle applies, f + g u equals
    the prosthesis joint accelerations the simulator produces over the next period (their
    mean over it from the rates, against the trapezoid of the model at the period's ends),
    in every prosthesis-stance domain away from the impacts and where the simulated person
    applies the whole of its feedback (the model's human; it yields a share of it where its
    contacts could not take it, ``hp_model.contact_outputs.feedback_share``: in at most 5 %
    of these periods)."""
    model, traj, _, gait = cycle
    sim = loop_simulator(model, gait, GAINS)
    fns = ContactInteraction(model, gait.params[GRAPH.domains[0]].degree).numeric()
    thetas = gait.thetas()
    pk, pa = (model.coord_names.index(c) for c in PROSTHESIS)
    fl = {d: sim.cl.vcs[d].numeric()[f"fl_{d}"] for d in GRAPH.domains}
    share = {d: sim.cl.vcs[d].numeric()[f"hfeedback_{d}"] for d in GRAPH.domains}
    q0, qd0 = start_state(traj)
    plant = SimulatorPlant(sim, q0, qd0, GRAPH.domains[0])
    rows, yielded = [], 0
    while plant.observe().t < 1.2:
        st = plant.run.observe()
        u = np.asarray(fl[st.domain](st.q, st.qd, thetas[st.domain], np.array(GAINS))[0])
        u = np.asarray(plant.actuate(u.ravel()[4:6]).torque)  # within the motors' limits
        plant.advance()
        after = plant.run.observe()
        if st.domain not in STANCE_DOMAINS or after.domain != st.domain:
            continue
        if min(float(np.asarray(share[st.domain](x.q, x.qd, thetas[st.domain], np.array(GAINS),
                                                 u)[2]).item())
               for x in (st, after)) < 1.0:
            yielded += 1
            continue
        fn = fns[f"interaction_{st.domain}"]

        def predicted(x, fn=fn, d=st.domain, u=u):
            f, g, _, _ = (np.asarray(a) for a in fn(x.q, x.qd, thetas[d], np.array(GAINS)))
            return f.ravel() + g @ u

        want = (after.qd[[pk, pa]] - st.qd[[pk, pa]]) / DT
        got = 0.5 * (predicted(st) + predicted(after))  # the period's mean (trapezoid)
        rows.append((st.t, st.domain, want, got))
    assert yielded <= 0.05 * (len(rows) + yielded), (yielded, len(rows))
    impacts = np.array([i.t for i in plant.run.result().impacts])
    seen = set()
    for t, d, want, got in rows:
        if np.min(np.abs(impacts - t)) < 3 * DT:  # an impact within the period or next to it
            continue
        assert got == pytest.approx(want, rel=0.01, abs=0.5), (d, t)
        seen.add(d)
    assert seen == set(STANCE_DOMAINS), seen


def test_in_ds_p_the_prosthesis_moves_one_joint_direction(cycle) -> None:
    """After the prosthesis's heel strike the human holds y1, both hips and the prosthesis
    sole's pitch: the prosthesis's two torques move one combination of its joint
    accelerations (g of rank 1); the other presses the feet along the ground (W of rank 2).
    In the other stance domains g has full rank."""
    model, traj, _, gait = cycle
    fns = ContactInteraction(model, gait.params[GRAPH.domains[0]].degree).numeric()
    thetas = gait.thetas()
    for d in STANCE_DOMAINS:
        tr = traj[d]
        k = np.asarray(tr["q"]).shape[1] // 2
        _, g, _, W = (np.asarray(a) for a in fns[f"interaction_{d}"](
            np.asarray(tr["q"])[:, k], np.asarray(tr["qd"])[:, k], thetas[d], np.array(GAINS)))
        sv = np.linalg.svd(g, compute_uv=False)
        if d == Domain.DS_P:
            assert sv[1] < 1e-6 * sv[0], sv
            assert np.linalg.matrix_rank(W, tol=1e-6 * np.abs(W).max()) == 2
        else:
            assert sv[1] > 1e-3 * sv[0], (d, sv)


def test_it_walks_the_committed_cycle(cycle, walk) -> None:
    """20 steps; each stride within 1 % of the fitted cycle's time and speed (the CLF tracks
    the gait); every torque within the motors; every stance QP solved, its contact rows
    held (slack below 1e-3 body weights) on at least 99 % of the stance ticks."""
    model, _, durations, _ = cycle
    rec, w = walk
    assert w.walks, w.fall
    stride = sum(durations.values())
    assert np.all(np.abs(w.strides / stride - 1) < 0.01), w.strides
    p = model.device.prosthesis
    lim = np.array([p.knee.torque_limit.value, p.ankle.torque_limit.value])
    u = np.array([t[1] for t in rec.ticks])
    assert np.all(np.abs(u) <= lim + 1e-12)
    stance = [t for t in rec.ticks if t[0]]
    assert stance and all(t[3] for t in stance)
    assert {t[2] for t in stance} == set(STANCE_DOMAINS)
    held = sum(t[4] < 1e-3 for t in stance) / len(stance)
    assert held >= 0.99, held


def test_on_gait_holds_a_domains_last_sample_before_its_touchdown() -> None:
    """A sample past its domain's designed touchdown (tau > 1) reads the last one of the
    same domain that is not; a domain's first sample reads itself whatever its tau."""
    from orchestrator.cosim.contact_controllers import on_gait

    domain = np.array([1, 1, 1, 1, 2, 2, 2, 3])
    tau = np.array([0.5, 0.99, 1.01, 1.2, 0.0, 1.05, 0.3, 1.4])
    np.testing.assert_array_equal(on_gait(domain, tau), [0, 1, 1, 1, 4, 4, 6, 7])


def test_the_stance_qp_is_read_on_the_gait_not_on_the_persons_resting_tail(cycle) -> None:
    """The held walk the stance QP's data come from passes the person's designed touchdown
    of a domain before its foot lands; there its law's resting tail changes the torques at
    once.  Those samples hold the last one on the gait: the QP's reference torque does not
    follow the walk's step there."""
    from orchestrator.cosim.contact_controllers import LoopSetup, held_walk
    from prosthesis_controller.contact_phase_pd import first_stride

    model, traj, _, gait = cycle
    sim = loop_simulator(model, gait, GAINS)
    w = held_walk(sim, traj)
    i0, i1, _ = first_stride(w.contact)
    tail = np.flatnonzero(w.tau[i0:i1] > 1.0)
    assert tail.size and tail[0] > 0
    st = contact_clfqp(model, gait, traj, setup=LoopSetup(sim, w)).stance
    for k in tail:
        assert w.domain[i0 + k] == w.domain[i0 + k - 1]
        np.testing.assert_array_equal(st.u_ref[k], st.u_ref[k - 1])
    first = tail[0] - 1  # the last sample on the gait before the tail
    step = np.abs(w.torque[i0 + tail] - w.torque[i0 + first]).max()
    assert step > np.abs(np.diff(w.torque[i0 + first - 5:i0 + first + 1], axis=0)).max(), step


def _hips_apart(gait, deg: float):
    """``gait`` with the person's hip curves offset: th_lh by +deg, th_rh by -deg (its swing
    heel lower at the end of the step: an early heel strike)."""
    from orchestrator.experiments.contact_perturbations import offset_outputs

    return offset_outputs(gait, {"th_lh": math.radians(deg), "th_rh": -math.radians(deg)})


def _strike_run(model, traj, gait, plant_gait, config, steps, encoder=None):
    """``clfqp`` (``config``) on the plant of ``plant_gait`` for ``steps`` steps: the
    plant's log and per tick (t, the QP's domain, the sensed strike, the QP's cost P)."""
    from orchestrator.experiments.contact_perturbations import IDEAL_ENCODER, controller_run

    ctl = contact_clfqp(model, gait, traj, config=config)
    ctl.keep_qp = True
    ticks = []

    class Logged:
        def reset(self, torque=None) -> None:
            ctl.reset(torque)

        def tick(self, m: ProsthesisMeasurement) -> ControlOutput:
            out = ctl.tick(m)
            ticks.append((m.t, ctl.domain, ctl._strike.struck_at,
                          None if ctl.qp is None else ctl.qp[0]))
            ctl.qp = None
            return out

    log = controller_run(loop_simulator(model, plant_gait, GAINS), traj, Logged(), steps,
                         encoder or IDEAL_ENCODER)
    return ctl, log, ticks


def test_the_persons_early_heel_strike_is_sensed_and_ds_h_read_from_it(cycle) -> None:
    """The committed cycle's person with its hips 2 deg apart strikes its heel about 37 ms
    before the gait's phase reaches ds_h.  clfqp senses the strike at the joints within 2 ms
    and dates it within 1 ms; from then its QP is ds_h's, read at the time since the strike
    (its cost is that sample's).  With the sensor off (threshold inf) the QP stays in
    ps_toe's until the phase reaches ds_h: it met the person's heel with its push-off."""
    from prosthesis_controller.contact_clf_qp import DEFAULT_CONFIG, SAMPLE_PERIOD

    model, traj, _, gait = cycle
    person = _hips_apart(gait, 2.0)
    ctl, log, ticks = _strike_run(model, traj, gait, person, DEFAULT_CONFIG, 2)
    strike = next(i.t for i in log.impacts if i.into is Domain.DS_H)
    sensed = next(t for t in ticks if t[2] is not None)
    assert strike <= sensed[0] <= strike + 2e-3 + 1e-9
    assert abs(sensed[2] - strike) <= 1e-3 + 1e-9
    first_ds_h = next(t for t in ticks if t[1] is Domain.DS_H)
    assert first_ds_h[0] == sensed[0]
    st, (first, _) = ctl.stance, ctl.stance.strike_span
    for t, d, struck, P in ticks:
        if struck is not None and d is Domain.DS_H and t > sensed[0]:
            np.testing.assert_array_equal(P, st.P[first + round((t - struck) / SAMPLE_PERIOD)])
            break
    else:
        raise AssertionError("no ds_h tick after the strike")
    _, log_off, ticks_off = _strike_run(model, traj, gait, person,
                                        replace(DEFAULT_CONFIG, strike_threshold=math.inf), 2)
    assert next(i.t for i in log_off.impacts if i.into is Domain.DS_H) == pytest.approx(strike)
    assert all(t[2] is None for t in ticks_off)
    assert next(t[0] for t in ticks_off if t[1] is Domain.DS_H) > strike + 0.03


def test_no_heel_strike_is_sensed_before_the_person_strikes(cycle) -> None:
    """The committed cycle, 6 steps, the sweeps' encoder noise (0.2 deg and 0.02 rad/s):
    no strike is sensed before the person's; the person walks (its strikes 2-3 ms before
    the phase: the sensor, its windows 3 ms each, mostly comes after the phase); a strike
    sensed is dated within 2 ms of the person's (the noise: 30 rad/s^2 on one period's
    residual)."""
    from orchestrator.loop.link import Encoder
    from prosthesis_controller.contact_clf_qp import DEFAULT_CONFIG

    model, traj, _, gait = cycle
    noisy = Encoder(angle_noise=0.0035, velocity_noise=0.02, angle_resolution=0.001, seed=5)
    _, log, ticks = _strike_run(model, traj, gait, gait, DEFAULT_CONFIG, 6, noisy)
    assert log.fall is None and log.steps >= 6
    strikes = [i.t for i in log.impacts if i.into is Domain.DS_H]
    for t, _, struck, _ in ticks:
        if struck is not None:
            assert any(s - 2e-3 - 1e-9 <= struck <= t for s in strikes), (t, struck)


def _quadprog(P, c, G, h, xl, xu):
    """min 1/2 z^T P z + c^T z, G z <= h, xl <= z <= xu (finite bounds) with quadprog."""
    n = len(c)
    lo, hi = np.isfinite(xl), np.isfinite(xu)
    C = np.vstack([-G, np.eye(n)[lo], -np.eye(n)[hi]]).T
    b = np.concatenate([-h, xl[lo], -xu[hi]])
    Pq = P + 1e-9 * np.eye(n)
    return quadprog.solve_qp(Pq, -c, C, b, 0)[0]


def _slsqp(P, c, G, h, xl, xu, z0):
    """The same QP with scipy's SLSQP from z0."""
    res = minimize(lambda v: 0.5 * v @ P @ v + c @ v, z0, jac=lambda v: P @ v + c,
                   method="SLSQP", bounds=list(zip(xl, xu, strict=True)),
                   constraints={"type": "ineq", "fun": lambda v: h - G @ v,
                                "jac": lambda v: -G},
                   options={"ftol": 1e-14, "maxiter": 200})
    return res.x


def _on_active_set(P, c, G, h, xl, xu, z, tol=1e-6):
    """The exact minimizer of the QP on the constraints active at z (rows of G z <= h and
    bounds within ``tol``): its KKT system solved by least squares (P is singular along the
    slacks, which the active rows fix).  z itself when that point is not feasible or a
    multiplier comes out negative (z's active set is not the optimum's)."""
    n = len(c)
    rows = [(G[i], h[i]) for i in np.flatnonzero(G @ z - h > -tol)]
    rows += [(-np.eye(n)[j], -xl[j]) for j in np.flatnonzero(z - xl < tol)]
    rows += [(np.eye(n)[j], xu[j]) for j in np.flatnonzero(xu - z < tol)]
    if not rows:
        return z
    A, b = np.array([r[0] for r in rows]), np.array([r[1] for r in rows])
    K = np.block([[P, A.T], [A, np.zeros((len(b), len(b)))]])
    sol = np.linalg.lstsq(K, np.concatenate([-c, b]), rcond=None)[0]
    zs, lam = sol[:n], sol[n:]
    feasible = np.all(G @ zs - h <= 1e-9) and np.all(zs >= xl - 1e-9) and np.all(zs <= xu + 1e-9)
    return zs if feasible and np.all(lam >= -1e-9) else z


def test_a_second_solver_agrees_on_its_qps(walk) -> None:
    """quadprog and scipy's SLSQP on 200 of the walk's stance QPs, their point finished on
    its active set (an exact solve of the KKT system there: SLSQP stops short where the cost
    is flat along the CLF's relaxation, 7e-3 N m and 3e-5 of the cost away at c_rho 10): the
    controller's cost as low as theirs (1e-6 of its scale), its torques within 1e-3 motor
    N m (0.04 % of the limits): piqp stops at a duality gap of 1e-8 of costs up to ~1e4, and
    the torque block's curvature turns that gap into ~2e-4 N m."""
    rec, _ = walk
    ticks = [t for t in rec.ticks if t[0] and t[5] is not None]
    for t in ticks[:: max(len(ticks) // 200, 1)]:
        P, c, G, h, xl, xu = t[5]
        # quadprog needs P > 0: with the slacks' 1e-9 curvature against their linear costs
        # its slack came out 2^-17 off (~1e-3 of cost); it solves with 1e-4 there, then
        # scipy's SLSQP polishes its point on the controller's own QP
        reg = np.diag([0.0, 0.0, 1e-4, 1e-4])
        z0 = np.clip(_quadprog(P + reg, c, G, h, xl, xu), xl, xu)
        z = _on_active_set(P, c, G, h, xl, xu, _slsqp(P, c, G, h, xl, xu, z0))
        assert np.all(G @ z - h <= 1e-6)
        zp = np.array([*t[1], t[6], t[4]])  # the controller's torques, rho and sigma
        assert zp[:2] == pytest.approx(z[:2], abs=1e-3)
        cost_p, cost_q = (0.5 * v @ P @ v + c @ v for v in (zp, z))
        assert cost_p <= cost_q + 1e-6 * (1 + abs(cost_q))  # piqp's as low as the reference's


def test_the_walked_stance_reads_each_wrench_under_the_torque_applied(cycle) -> None:
    """The stance the QP's data come from pairs each sample's torque with the wrench under
    it: from one period to the next (1 ms), within a domain and under a torque that changes
    by less than 0.05 N m, every contact's normal force changes by less than 10 % of the
    body's weight, the heel strike's sample included.  Read before the torque was applied
    (under the swing's), the heel strike's prosthesis heel pulled: -14 N against the next
    sample's 158 N on this cycle, up to -535 N on gaitalytics' library, and the QP's first
    rows asked the gait itself for 0.4 body weights of slack."""
    from orchestrator.cosim.contact_controllers import held_walk
    from prosthesis_controller.contact_phase_pd import first_stride

    model, traj, _, gait = cycle
    w = held_walk(loop_simulator(model, gait, GAINS), traj)
    i0, i1, _ = first_stride(w.contact)
    weight = float(model.tree.total_mass) * 9.81
    assert Domain.from_code(int(w.domain[i0])) is Domain.DS_P
    normal = {}  # (sample, contact) -> N
    for k in range(i0, i1):
        j = 0
        for c in Domain.from_code(int(w.domain[k])).contacts:
            normal[k, (c.side, c.part)] = w.wrench[k, j + 1]
            j += c.size
    heel = next(c for c in Domain.DS_P.contacts if c.side == "p")
    assert normal[i0, ("p", heel.part)] > 0.1 * weight
    steady = np.abs(np.diff(w.torque, axis=0)).max(axis=1) < 0.05  # motor N m per period
    steps = [abs(normal[k + 1, c] - f) for (k, c), f in normal.items()
             if (k + 1, c) in normal and w.domain[k + 1] == w.domain[k] and steady[k]]
    assert max(steps) < 0.1 * weight, max(steps)


def test_the_load_cell_moves_the_contact_rows(cycle, walk) -> None:
    """In ``ds_p`` a load cell reading 100 N above the model's prediction (under the last
    torque) tells the QP the prosthesis heel carries 100 N more and the person's trailing toe
    100 N less: the two normal-force rows' room moves by that much, and a reading equal to
    the prediction leaves the rows as the gait has them."""
    model = cycle[0]
    rec, _ = walk
    ctl, st = rec.ctl, rec.ctl.stance
    ds_p = [t[7] for t in rec.ticks[:1500] if t[2] is Domain.DS_P]
    m = ds_p[len(ds_p) // 2]  # the middle of the first double support
    ctl.reset()
    ctl.tick(replace(m, foot_load=0.0))  # no reading: no correction
    i = st.index(ctl.phase)
    assert st.domain[i] is Domain.DS_P
    rows = {}
    for extra in (0.0, 100.0):
        ctl.reset(torque=tuple(st.u_ref[i]))  # the prediction under the last torque: load_ref
        ctl.tick(replace(m, foot_load=float(st.load_ref[i]) + extra))
        assert st.index(ctl.phase) == i
        rows[extra] = np.array(ctl.qp[3])
    assert rows[0.0][1:7] == pytest.approx(st.h[i, :6], abs=1e-12)
    moved = (rows[100.0] - rows[0.0]) * float(model.tree.total_mass) * 9.81  # N, per row
    for k, contact in enumerate(Domain.DS_P.contacts):  # rows F_x <=, -F_x <=, F_z >=
        assert moved[1 + 3 * k + 2] == pytest.approx(100.0 if contact.side == "p" else -100.0)


def test_a_foot_sensed_on_its_heel_keeps_the_double_supports_qp(walk) -> None:
    """Past the gait's landing of the foot (its ``ps``), a foot the leg's sensors still put on
    its heel (more than HEEL_DOWN below its toe: a person slower than the gait), or a flat
    one whose load cell reads less than FLAT_LOAD of the flat foot's load (the person's
    other foot still on the ground) runs ``ds_p``'s last QP; the first flat reading of the
    stance ends that until the next heel strike, whatever the sensors read after it."""
    from prosthesis_controller.contact_clf_qp import HEEL_DOWN

    rec, _ = walk
    ctl, st = rec.ctl, rec.ctl.stance
    flat = [t[7] for t in rec.ticks[:1500] if t[2] is Domain.PS][5]
    law = ctl.law

    def rise(m: ProsthesisMeasurement) -> float:
        return law.leg.sense(m.socket_pitch, m.knee_angle, m.ankle_angle)[1]

    assert abs(rise(flat)) < HEEL_DOWN
    heel = next(h for h in (replace(flat, ankle_angle=flat.ankle_angle + d)
                            for d in (0.03, -0.03)) if rise(h) < -2 * HEEL_DOWN)
    ctl.reset()
    ctl.tick(heel)
    assert ctl.domain is Domain.DS_P and st.domain[st.index(ctl.phase)] is Domain.PS
    ctl.tick(replace(flat, t=heel.t + 0.001))
    assert ctl.domain is Domain.PS and ctl.landed
    ctl.tick(replace(heel, t=heel.t + 0.002))
    assert ctl.domain is Domain.PS
    ctl.tick(replace(heel, t=heel.t + 0.003, contact=False))  # a toe-off ...
    ctl.tick(replace(heel, t=heel.t + 0.004))  # ... and a heel strike
    assert ctl.domain is Domain.DS_P and not ctl.landed
    # flat, but carrying half the flat foot's load: the person's other foot still loaded
    ctl.tick(replace(flat, t=heel.t + 0.005, foot_load=0.5 * flat.foot_load))
    assert ctl.domain is Domain.DS_P and not ctl.landed
    ctl.tick(replace(flat, t=heel.t + 0.006))
    assert ctl.domain is Domain.PS and ctl.landed


def test_a_foot_flat_before_the_gaits_runs_the_flat_stances_qp(walk) -> None:
    """Before the gait's landing of the foot (its ``ds_p``), a foot the leg's sensors put
    flat (within EARLY_FLAT_PITCH, EARLY_FLAT_TICKS ticks in a row) and whose load cell
    reads the flat foot's load (the person's other foot off the ground: the plant is in
    ``ps``) runs ``ps``'s first QP and the gait
    there: ``ds_p``'s QP moves one joint direction, and its CLF relaxed while the person's
    weight extended the knee past straight (3-deg posture draws, docs/gait-design.md).  On
    its heel, flat with the load shared, or flat within EARLY_FLAT of the gait's landing, it
    stays in ``ds_p``."""
    from prosthesis_controller.contact_clf_qp import (
        EARLY_FLAT,
        EARLY_FLAT_PITCH,
        EARLY_FLAT_TICKS,
        HEEL_DOWN,
        SAMPLE_PERIOD,
    )

    rec, _ = walk
    ctl, st = rec.ctl, rec.ctl.stance
    law = ctl.law
    ps = [t[7] for t in rec.ticks[:1500] if t[2] is Domain.PS][5]
    first = st.heel_end + 1

    def rise(m: ProsthesisMeasurement) -> float:
        return law.leg.sense(m.socket_pitch, m.knee_angle, m.ankle_angle)[1]

    # a flat foot at a phase of the gait's ds_p: the hip behind the flat foot's by moving
    # the thigh back and the ankle with it (rise = 0 kept)
    early = None
    for back in np.linspace(0.02, 0.3, 57):
        m = replace(ps, socket_pitch=ps.socket_pitch - back, ankle_angle=ps.ankle_angle + back)
        ctl.reset()
        ctl.tick(replace(m, foot_load=0.5 * ps.foot_load))
        i = st.index(law.phase)
        if (st.domain[i] is Domain.DS_P and (first - i) * SAMPLE_PERIOD > EARLY_FLAT
                and abs(rise(m)) < EARLY_FLAT_PITCH):
            early = m
            break
    assert early is not None
    assert ctl.domain is Domain.DS_P and not ctl.landed  # flat, the load shared
    for k in range(1, EARLY_FLAT_TICKS):  # flat and loaded: confirmed over ticks in a row
        ctl.tick(replace(early, t=early.t + 0.001 * k))
        assert ctl.domain is Domain.DS_P and not ctl.landed
    ctl.tick(replace(early, t=early.t + 0.001 * EARLY_FLAT_TICKS))
    assert ctl.domain is Domain.PS and ctl.landed
    assert st.domain[st.index(law.phase)] is Domain.DS_P  # the gait is still on its heel
    k, a, vk, va = law.tables.stance.at(float(st.phase[first]))[:4]
    ctl.keep_qp = True
    ctl.tick(replace(early, t=early.t + 0.001 * (EARLY_FLAT_TICKS + 1)))
    np.testing.assert_array_equal(ctl.qp[0], st.P[first])  # ps's first sample's cost
    v_want = (ctl._clf.terms(early.knee_angle - k, early.knee_vel - vk)[0]
              + ctl._clf.terms(early.ankle_angle - a, early.ankle_vel - va)[0])
    v_got = ctl.V
    assert v_got == pytest.approx(v_want, rel=1e-12)  # about the gait there
    ctl.keep_qp = False
    heel = next(h for h in (replace(early, ankle_angle=early.ankle_angle + d)
                            for d in (0.03, -0.03)) if rise(h) < -2 * HEEL_DOWN)
    ctl.reset()
    ctl.tick(heel)
    if st.domain[st.index(law.phase)] is Domain.DS_P:
        assert ctl.domain is Domain.DS_P and not ctl.landed  # on its heel


def test_bad_measurements_give_zero_torque_and_torques_stay_bounded(cycle) -> None:
    model, traj, _, gait = cycle
    ctl = contact_clfqp(model, gait, traj)
    ok = ProsthesisMeasurement(t=0.0, knee_angle=0.05, ankle_angle=0.0, knee_vel=0.0,
                               ankle_vel=0.0, foot_load=500.0, contact=True,
                               socket_pitch=0.0)
    for bad in (replace(ok, knee_vel=math.nan), replace(ok, socket_pitch=math.nan),
                replace(ok, t=math.inf)):
        out = ctl.tick(bad)
        assert tuple(out.torque) == (0.0, 0.0)
        assert out.diagnostics.mode == ControllerMode.FAULT
    p = model.device.prosthesis
    lim = (p.knee.torque_limit.value, p.ankle.torque_limit.value)
    for k in range(50):  # far from the gait: bounded, finite
        u = ctl.tick(replace(ok, t=0.001 * (k + 1), knee_angle=1.2, knee_vel=-8.0,
                             ankle_vel=6.0)).torque
        assert all(math.isfinite(v) and abs(v) <= lim_ for v, lim_ in zip(u, lim, strict=True))


def test_an_imu_bias_is_estimated_while_the_foot_is_flat(cycle) -> None:
    """The socket IMU reads 1 deg off: the controller's estimate of the bias (from the heel's
    sensed rise over the toe while the gait's foot is flat) is within 0.02 deg of it after
    the first flat stance, and the walk takes its 10 steps at the fitted stride (1 %).
    Without the estimate, 0.25 deg (standard deviation over 20 draws) made half of the walks
    fall (docs/gait-design.md)."""
    model, traj, durations, gait = cycle
    bias = math.radians(1.0)
    ctl = contact_clfqp(model, gait, traj)
    encoder = Encoder(imu_bias=bias)
    q0, qd0 = start_state(traj)
    plant = SimulatorPlant(loop_simulator(model, gait, GAINS), q0, qd0, GRAPH.domains[0])
    rng = np.random.default_rng(0)
    estimates = []
    while plant.fall is None and plant.run.steps < 10:
        obs = plant.observe()
        plant.actuate(ctl.tick(measurement(obs, encoder, rng)).torque)
        estimates.append((obs.t, ctl.law.imu_bias))
        plant.advance()
    assert plant.fall is None, plant.fall.message()
    est = np.array(estimates)
    late = est[est[:, 0] > sum(durations.values()), 1]  # after the first stride
    assert np.all(np.abs(late - bias) < math.radians(0.02)), np.degrees(late).min()
    strikes = [i.t for i in plant.run.result().impacts if i.into == Domain.DS_H]
    assert np.all(np.abs(np.diff(strikes) / sum(durations.values()) - 1) < 0.01)


def test_a_perturbation_family_is_walked_by_every_controller_on_the_same_draws(cycle) -> None:
    """orchestrator.experiments.contact_perturbations (what docs/gait-design.md's table
    runs): two draws of the IMU bias (0.5 deg sd) and of the human's gains, 6 steps: clfqp
    walks all four (the table: 20 of 20 and 18 of 20); the oracle's sensor row is the draws;
    the human's posture offsets of 0 deg change nothing."""
    from orchestrator.experiments.contact_perturbations import (
        draw,
        family_walks,
        perturbed_controllers,
    )

    model, traj, durations, gait = cycle
    ctls = perturbed_controllers(model, gait, traj)  # made once for both families
    w = family_walks(model, traj, durations, "bias", 1.0, draws=2, steps=6, controllers=ctls)
    assert w["clfqp"] == 2 and w["oracle"] == 2, w
    w = family_walks(model, traj, durations, "gains", 1.0, draws=2, steps=6,
                     controllers=ctls)
    assert w["clfqp"] == 2, w
    same = draw(gait, "posture", 0.0, 0).gait
    for d in gait.params:
        np.testing.assert_array_equal(same.params[d].alpha, gait.params[d].alpha)
    with pytest.raises(ValueError, match="unknown family"):
        draw(gait, "wind", 1.0, 0)


def test_the_pace_family_scales_the_hips_rate_only(cycle) -> None:
    """``pace``: in each domain with a velocity output the hip's rate curve (the row after
    the joints') and v_hip times the draw's factor, every other row and the toe domains
    unchanged; amplitude 0 is the gait."""
    from orchestrator.experiments.contact_perturbations import draw, paced

    _, _, _, gait = cycle
    fast = paced(gait, 1.1)
    for d, p in gait.params.items():
        a, b = np.asarray(p.alpha), np.asarray(fast.params[d].alpha)
        n = len(d.y2_coords)
        np.testing.assert_array_equal(b[:n], a[:n])
        if d.velocity_output:
            np.testing.assert_allclose(b[n], 1.1 * a[n])
            assert fast.params[d].v_hip == pytest.approx(1.1 * p.v_hip)
        else:
            np.testing.assert_array_equal(b, a)
        np.testing.assert_array_equal(b[n + d.velocity_output:], a[n + d.velocity_output:])
    same = draw(gait, "pace", 0.0, 3).gait
    for d in gait.params:
        np.testing.assert_array_equal(same.params[d].alpha, gait.params[d].alpha)


def test_the_perturbation_script_refuses_a_missing_gait_in_one_line(capsys) -> None:
    from orchestrator.experiments.contact_perturbations import main

    assert main(["/nonexistent/gait.json", "--family", "bias"]) == 2
    err = capsys.readouterr().err.strip()
    assert "/nonexistent/gait.json" in err and "\n" not in err


def test_the_robust_term_enters_the_clf_row_where_its_bound_holds(cycle) -> None:
    """The tube's model-error bound (``StanceQp.with_margin``): its box at the flat single
    support's samples inside its phase range, zero elsewhere; in the CLF row it lowers the
    right-hand side by the box's worst case, dV/dnu . c + |dV/dnu| . r (rad/s^2 against
    the CLF's rate per joint acceleration), and nowhere else; a paper-graph bound is
    refused."""
    from hp_model.force_tube import ModelErrorBound

    model, traj, _, gait = cycle
    plain = contact_clfqp(model, gait, traj)
    st = plain.stance
    ps = np.array([d is Domain.PS for d in st.domain])
    lo_t, hi_t = float(np.quantile(st.phase[ps], 0.2)), float(np.quantile(st.phase[ps], 0.8))
    center, radius = np.array([4.0, -6.0]), np.array([10.0, 3.0])
    bound = ModelErrorBound(lo_t, hi_t, np.tile((center - radius)[:, None], (1, 2)),
                            np.tile((center + radius)[:, None], (1, 2)),
                            components=("qdd_pk", "qdd_pa"))
    robust = contact_clfqp(model, gait, traj, model_error=bound)
    on = ps & (st.phase >= lo_t) & (st.phase <= hi_t)
    assert on.sum() > 50
    assert np.allclose(robust.stance.d_center[on], center)
    assert np.allclose(robust.stance.d_radius[on], radius)
    assert not robust.stance.d_center[~on].any() and not robust.stance.d_radius[~on].any()
    with pytest.raises(ValueError, match="multi-contact controller"):
        st.with_margin(replace(bound, components=("dy1", "d2y2")))
    # the same measurements ticked by both (the plain one's torque applied): the CLF rows
    # differ by the margin where it holds; dV/dnu = w from the row's LgV = g^T w
    plain.keep_qp = robust.keep_qp = True
    plain.reset()
    robust.reset()
    q0, qd0 = start_state(traj)
    plant = SimulatorPlant(loop_simulator(model, gait, GAINS), q0, qd0, GRAPH.domains[0])
    seen = 0
    while plant.observe().t < 1.2:
        m = measurement(plant.observe())
        out = plain.tick(m)
        robust.tick(m)
        if plain.domain is not None:
            i = st.index(plain.phase)
            G0, h0 = plain.qp[2][0], plain.qp[3][0]
            scale = -1.0 / G0[2]  # the row: (LgV / scale, -1 / scale, 0) . z <= h / scale
            assert np.array_equal(robust.qp[2][0], G0)
            if on[i]:
                w = np.linalg.solve(st.g[i].T, G0[:2] * scale)
                margin = w @ center + np.abs(w) @ radius
                assert robust.qp[3][0] == pytest.approx(h0 - margin / scale, rel=1e-6,
                                                        abs=1e-9)
                seen += 1
            else:
                assert robust.qp[3][0] == h0
        plant.actuate(out.torque)
        assert plant.fall is None
        plant.advance()
    assert seen > 50
