"""A double support's trailing foot leaves the ground when it would pull on it
(hp_model.simulator: the leading foot then lands flat at once, an impact that is not a step).

Before every contact was watched, the committed cycle's closed loop held the trailing toe on
the ground by pulling on it: 0.42-0.44 kN for 1-2 ms at the end of every ``ds_h`` (a flat
landing 1-2 ms late, the curves continued linearly past tau = 1), and a prosthesis holding
the oracle's torque over each 1 ms pulled up to 0.69 kN for 38 ms while it "walked" 8 steps.
"""

from __future__ import annotations

import numpy as np
import pytest

from characterization.gait.contact_gait import GAINS, contact_gait_of, start_state
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain, DomainGraph
from hp_model.simulator import HybridSimulator
from tests.multicontact_cycle import load_cycle

G = 9.81
pytestmark = pytest.mark.slow  # about 50 s: the committed cycle's loop, compiled once


@pytest.fixture(scope="module")
def loop():
    model, traj, durations, _ = load_cycle()
    gait = contact_gait_of(model, traj, durations)
    sim = HybridSimulator(model, ClosedLoop(model, 5), gait.thetas(), np.array(GAINS))
    return model, traj, sim


def test_a_release_lands_the_leading_foot_flat_with_the_flat_foots_impact(loop) -> None:
    model, traj, sim = loop
    nq = model.nq
    for d in (Domain.DS_H, Domain.DS_P):
        x = np.r_[traj[d]["q"][:, -3], traj[d]["qd"][:, -3]]  # near the fitted landing
        released = sim.release_trailing(d, x, 0.25)
        assert released is not None
        xp, impact = released
        into = DomainGraph.MULTICONTACT.next(d)
        assert (impact.into, impact.release, impact.starts_step, impact.t) == (into, True,
                                                                               False, 0.25)
        sole = model.frame_index(d.stance_leg.sole_frame)
        frames = model.numeric()["frames"]
        before = float(frames(x[:nq], np.zeros(nq))[0][2, sole])
        after = float(frames(xp[:nq], np.zeros(nq))[0][2, sole])
        assert impact.foot_pitch == pytest.approx(before, abs=1e-12)
        assert 0 < abs(before) < 0.1 and abs(after) < 1e-9  # rotated flat about its ankle
        # only the leading ankle moved; the velocities obey the flat foot's constraint
        moved = np.flatnonzero(xp[:nq] != x[:nq])
        assert [model.coord_names[i] for i in moved] == [d.stance_leg.ankle]
        J = np.asarray(model.numeric()[f"terms_{into}"](xp[:nq], xp[nq:])[2])
        assert np.abs(J @ xp[nq:]).max() < 1e-9
    assert sim.release_trailing(Domain.PS, x, 0.0) is None  # a single support has none


def test_no_contact_of_a_double_support_pulls_on_the_ground(loop) -> None:
    """Over 6 steps of the closed loop: the trailing foot leaves within the period its force
    crosses zero (a force falling about 14 kN/s at the end of a double support: 1 ms is
    14 N, 0.02 body weights), the leading foot lands within 0.5 deg of flat, and it walks."""
    model, traj, sim = loop
    q0, qd0 = start_state(traj)
    res = sim.run(q0, qd0, DomainGraph.MULTICONTACT.domains[0], steps=6, duration=12.0)
    assert res.fall is None and res.steps == 6
    weight = model.tree.total_mass * G
    for d in (Domain.DS_H, Domain.DS_P):
        rows = res.domain == d.code
        trailing = d.contacts[0].size + 1
        assert res.lam[rows, 1].min() > -0.02 * weight, d  # the leading heel
        assert res.lam[rows, trailing].min() > -0.03 * weight, d
    releases = [i for i in res.impacts if i.release]
    assert releases, "the committed cycle's trailing toes leave a little early"
    assert all(abs(i.foot_pitch) < np.radians(0.5) for i in releases)
    assert all(i.into in (Domain.PS, Domain.PNS) and not i.starts_step for i in releases)


def test_a_trailing_toe_sliding_under_load_is_watched_when_asked(loop) -> None:
    """The trailing contact's slip counts where it carries more than ``trailing_slip_load``
    (off by default, hp_model.simulator): at 0, the toe unloading at the end of the committed
    cycle's first ``ds_h`` slides (|F_x| > mu F_z at 20-30 N) for 5 periods and the run ends
    there, naming that contact's forces; at 0.05 BW this cycle walks."""
    from hp_model.falls import FallReason
    from hp_model.simulator import SimOptions

    model, traj, sim = loop
    strict = HybridSimulator(model, sim.cl, sim.thetas, sim.gains,
                             SimOptions(trailing_slip_load=0.0))
    q0, qd0 = start_state(traj)
    res = strict.run(q0, qd0, DomainGraph.MULTICONTACT.domains[0], steps=6, duration=12.0)
    fall = res.fall
    assert fall is not None and fall.reason == FallReason.FRICTION_CONE
    assert fall.domain == Domain.DS_H and fall.tau > 0.8
    weight = model.tree.total_mass * G
    assert 0 < fall.values["F_z"] < 0.05 * weight
    assert abs(fall.values["F_x"]) > strict.opt.mu * fall.values["F_z"]
    loaded = HybridSimulator(model, sim.cl, sim.thetas, sim.gains,
                             SimOptions(trailing_slip_load=0.05))
    res = loaded.run(q0, qd0, DomainGraph.MULTICONTACT.domains[0], steps=6, duration=12.0)
    assert res.fall is None and res.steps == 6
