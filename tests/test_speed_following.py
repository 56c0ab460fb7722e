"""Following the person's speed over a gait library (``prosthesis_controller/
speed_following.py``): the estimate from the foot switch's strides, the switch at a heel
strike with the outgoing controller's state handed over, the speeds between the library's;
and the references and stance-QP data blended between two gaits' controllers
(``blend_tables``, ``blend_stance``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hp_model.domains import Domain
from prosthesis_controller.contact_clf_qp import blend_stance
from prosthesis_controller.contact_phase_pd import blend_tables
from prosthesis_controller.interface import ControllerMode, ControlOutput
from prosthesis_controller.measurement import ProsthesisMeasurement
from prosthesis_controller.speed_following import GAIN, SpeedFollowing, filled


class Stub:
    """A controller that records its ticks and what it took over from."""

    name = "stub"

    def __init__(self, speed: float) -> None:
        self.speed, self.ticks, self.took = speed, 0, []
        self.phase = 0.0

    def reset(self, torque=None) -> None:
        self.ticks, self.took = 0, []

    def tick(self, m: ProsthesisMeasurement) -> ControlOutput:
        from prosthesis_controller.contact_phase_pd import control_output

        self.ticks += 1
        return control_output((self.speed, 0.0), 0.0, Domain.PS, ControllerMode.STANCE, 0)

    def take_over(self, other: Stub) -> None:
        self.took.append(other.speed)

    def blended(self, other: Stub, w: float) -> Stub:
        return Stub((1 - w) * self.speed + w * other.speed)


def _m(t: float, contact: bool) -> ProsthesisMeasurement:
    return ProsthesisMeasurement(t=t, knee_angle=0.1, ankle_angle=0.0, knee_vel=0.0,
                                 ankle_vel=0.0, foot_load=500.0 if contact else 0.0,
                                 contact=contact, socket_pitch=0.0)


SPEEDS, STRIDES = (0.6, 0.8, 1.0, 1.2), (1.5, 1.3, 1.1, 1.05)


def _walk(ctl: SpeedFollowing, strikes: list[float], dt: float = 0.01) -> list[float]:
    """Tick through heel strikes at ``strikes`` (s; the foot down for 60 % of each stride):
    the torque (its controller's speed) of each tick."""
    out, t = [], 0.0
    ends = [*strikes, strikes[-1] + 0.5]
    for k in range(len(ends) - 1):
        while t < ends[k + 1]:
            on = t >= ends[k] and t < ends[k] + 0.6 * (ends[k + 1] - ends[k])
            out.append(float(ctl.tick(_m(t, on)).torque[0]))
            t += dt
    return out


def test_the_speed_is_read_from_the_strides_and_switched_at_a_heel_strike():
    ctls = [Stub(v) for v in SPEEDS]
    sf = SpeedFollowing(ctls, SPEEDS, STRIDES, 0.8)
    assert sf.controller is ctls[1] and sf.speed == 0.8
    assert sf.speed_of(1.2) == pytest.approx(0.9) and sf.speed_of(3.0) == 0.6  # clamped
    # strides of 1.1 s (1.0 m/s): the estimate moves GAIN of the way each stride (the walk
    # starts on the foot: the first heel strike it sees is at 1.1 s, three strides follow;
    # each measured to a tick of 10 ms, 0.01 m/s of speed here)
    torque = _walk(sf, [0.0, 1.1, 2.2, 3.3, 4.4])
    v = 0.8
    for _ in range(3):
        v += GAIN * (1.0 - v)
    assert sf.speed == pytest.approx(v, abs=0.01)
    assert sf.controller is ctls[2]  # 0.975 m/s: nearest 1.0
    assert ctls[2].took == [0.8] and not ctls[0].took  # handed over once, at that strike
    # torques change only at heel strikes: each run of one controller's ticks is whole
    changes = np.flatnonzero(np.diff(torque) != 0) + 1
    assert all(abs((k * 0.01) % 1.1) < 0.011 or abs((k * 0.01) % 1.1 - 1.1) < 0.011
               for k in changes)


def test_strides_that_are_not_walking_leave_the_estimate():
    sf = SpeedFollowing([Stub(v) for v in SPEEDS], SPEEDS, STRIDES, 0.8)
    _walk(sf, [0.0, 3.0, 3.3])  # a stop (3 s), then a stumble (0.3 s)
    assert sf.speed == 0.8
    sf.reset()
    assert sf.speed == 0.8 and sf.active == 1


def test_the_speeds_between_the_librarys_are_blends():
    ctls, v = filled([Stub(s) for s in SPEEDS], SPEEDS, 0.05)
    assert v == pytest.approx(np.arange(0.6, 1.2001, 0.05))
    assert [c.speed for c in ctls] == pytest.approx(v)  # each a blend of its neighbours
    assert ctls[4].speed == 0.8 and isinstance(ctls[4], Stub)


def test_a_library_that_does_not_shorten_its_strides_is_refused():
    with pytest.raises(ValueError, match="strides shorten"):
        SpeedFollowing([Stub(v) for v in SPEEDS], SPEEDS, (1.5, 1.6, 1.1, 1.0), 0.8)
    with pytest.raises(ValueError, match="one controller per"):
        SpeedFollowing([Stub(0.6)], SPEEDS, STRIDES, 0.8)
    with pytest.raises(ValueError, match="resolution"):
        filled([Stub(v) for v in SPEEDS], SPEEDS, 0.0)


@pytest.fixture(scope="module")
def two_gaits():
    """clfqp of the packaged person's gait and of the same gait walked 4 % faster."""
    from characterization.gait.contact_gait import contact_gait_of
    from characterization.gait.multicontact_artifact import load_contact_cycle
    from characterization.gait.person_synth import REFERENCE_PERSON_GAIT
    from orchestrator.cosim.contact_controllers import contact_clfqp
    from orchestrator.experiments.contact_perturbations import paced

    c = load_contact_cycle(REFERENCE_PERSON_GAIT)
    gait = contact_gait_of(c.model, c.trajectory, c.durations)
    return (contact_clfqp(c.model, gait, c.trajectory),
            contact_clfqp(c.model, paced(gait, 1.04), c.trajectory))


def test_blended_references_lie_between_the_two_gaits(two_gaits):
    a, b = (c.law.tables for c in two_gaits)
    assert a.swing_time != b.swing_time
    for w in (0.0, 0.3, 1.0):
        m = blend_tables(a, b, w)
        assert m.swing_time == pytest.approx((1 - w) * a.swing_time + w * b.swing_time)
        for s in (0.1, 0.5, 0.9):
            ra, rb, rm = (np.array(t.stance.at(s)) for t in (a, b, m))
            # on a's grid, b's values interpolated: within a sample's change of the blend
            step = np.abs(np.diff(b.stance.values, axis=0)).max(axis=0)
            assert np.all(np.abs(rm - ((1 - w) * ra + w * rb)) <= step + 1e-12)
    assert np.array_equal(blend_tables(a, b, 0.0).stance.values, a.stance.values)


def test_the_stance_qp_blends_within_a_domain_and_keeps_the_nearer_across(two_gaits):
    a, b = (c.stance for c in two_gaits)
    m = blend_stance(a, b, 0.25)
    assert m.phase is not a.phase and np.array_equal(m.phase, a.phase)
    j = np.array([b.index(s) for s in a.phase])
    same = np.array([da is b.domain[k] for da, k in zip(a.domain, j, strict=True)])
    assert same.mean() > 0.9  # the domains' boundaries move a little with the pace
    assert np.allclose(m.u_ref[same], 0.75 * a.u_ref[same] + 0.25 * b.u_ref[j][same])
    assert np.array_equal(m.u_ref[~same], a.u_ref[~same])
    far = blend_stance(a, b, 0.75)  # on b's grid now
    assert np.array_equal(far.phase, b.phase)
    # a blended controller ticks like one: a finite torque within the motors
    mixed = two_gaits[0].blended(two_gaits[1], 0.5)
    out = mixed.tick(replace(_m(0.0, True), socket_pitch=-0.2, knee_angle=0.05))
    assert np.all(np.isfinite(out.torque)) and np.all(np.abs(out.torque) <= mixed.law.limits)
