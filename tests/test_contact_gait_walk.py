"""The multi-contact gait in closed loop: openOFM's fitted cycle (tests/multicontact_cycle.py),
regressed onto the multi-contact virtual constraints, walks in the one simulator through
all six domains, periodic, at the fitted cycle's stride and speed."""

from __future__ import annotations

import numpy as np

from characterization.gait.contact_gait import contact_gait_of, walk_contact_gait
from hp_model.domains import DomainGraph
from tests.multicontact_cycle import load_cycle


def test_the_fitted_cycle_walks_in_closed_loop() -> None:
    model, traj, durations, stride_length = load_cycle()
    gait = contact_gait_of(model, traj, durations)
    walk = walk_contact_gait(model, gait, traj, steps=6)
    assert walk.walks, walk.line()
    stride = sum(durations.values())
    # the loop tracks curves regressed from the fit (not the fit itself): its stride and
    # speed within 3 % of the fitted cycle's; a limit cycle: the strides agree within 5 ms
    assert np.all(np.abs(walk.strides / stride - 1) < 0.03), walk.strides
    assert np.all(np.abs(walk.speeds / (stride_length / stride) - 1) < 0.03), walk.speeds
    assert np.ptp(walk.strides) < 0.005
    assert "holding that law's torque over each 1 ms period within its motor limits" \
        in walk.line()
    rec = walk.to_json()
    assert rec["walks"] and rec["steps"] == 6


def test_every_domain_is_visited_in_the_graphs_order() -> None:
    from characterization.gait.contact_gait import GAINS, start_state
    from hp_model.closed_loop import ClosedLoop
    from hp_model.simulator import HybridSimulator

    model, traj, durations, _ = load_cycle()
    gait = contact_gait_of(model, traj, durations)
    sim = HybridSimulator(model, ClosedLoop(model, 5), gait.thetas(), np.array(GAINS))
    q0, qd0 = start_state(traj)
    res = sim.run(q0, qd0, DomainGraph.MULTICONTACT.domains[0], steps=2, duration=4.0)
    assert res.fall is None
    codes = res.domain[np.r_[True, np.diff(res.domain) != 0]]
    cycle = [d.code for d in DomainGraph.MULTICONTACT.domains]
    assert list(codes[:6]) == cycle
    # the double supports last about as long as the fitted ones (heel strike to flat foot)
    t = res.t[np.r_[True, np.diff(res.domain) != 0]]
    for k, d in enumerate(DomainGraph.MULTICONTACT.domains[:5]):
        if d.is_double_support:
            assert abs((t[k + 1] - t[k]) - durations[d]) < 0.03, (d, t[k + 1] - t[k])
    # the logged wrenches are the widest domain's (7), NaN past a domain's own
    assert res.lam.shape[1] == 7
    single = res.domain == DomainGraph.MULTICONTACT.domains[0].code
    assert np.isnan(res.lam[single, 6]).all() and np.isfinite(res.lam[~single][:, :5]).all()


def test_the_curves_do_not_read_the_fitted_accelerations() -> None:
    """A fit that holds its contacts at the position level has accelerations that zigzag from
    node to midpoint; the curves come from the positions and rates alone (the hip rate's slopes
    by finite differences), and the hip-rate curve passes within 0.04 m/s RMS (3 % of the
    walking speed) of the fitted rates in every domain (on the accelerations it missed them
    by 0.1 m/s in pns on openOFM's fit)."""
    model, traj, durations, _ = load_cycle()
    gait = contact_gait_of(model, traj, durations)
    rng = np.random.default_rng(0)
    noisy = {d: {**tr, "qdd": tr["qdd"] + 50.0 * rng.standard_normal(tr["qdd"].shape)}
             for d, tr in traj.items()}
    again = contact_gait_of(model, noisy, durations)
    for d, p in gait.params.items():
        assert np.array_equal(again.params[d].alpha, p.alpha), d
        if d.velocity_output:
            assert gait.rms[d][-1] < 0.04, (d, gait.rms[d])
