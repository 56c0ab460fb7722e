"""Following the person's speed over a gait library (``prosthesis_controller/
speed_following.py``): the estimate from the hip's rate over the flat stance, read at
toe-off, the switch at the next heel strike with the outgoing controller's state handed
over, the speeds between the library's; and the references and stance-QP data blended
between two gaits' controllers (``blend_tables``, ``blend_stance``)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

from hp_model.domains import Domain
from prosthesis_controller.contact_clf_qp import blend_stance
from prosthesis_controller.contact_phase_pd import blend_tables
from prosthesis_controller.interface import ControllerMode, ControlOutput
from prosthesis_controller.measurement import ProsthesisMeasurement
from prosthesis_controller.speed_following import (
    MARGIN,
    SpeedFollowing,
    filled,
    flat_stance_rate,
    rising,
)


@dataclass(frozen=True)
class Tables:
    """What the estimate reads of a controller's tables: the hip's progress (m) at heel
    strike and toe-off, the flat window of the stance phase."""

    progress: tuple[float, float] = (-0.3, 0.4)
    flat: tuple[float, float] = (0.25, 0.55)


class Stub:
    """A controller whose stance phase rises from 0 to 1 over ``STANCE`` s after a heel
    strike; it records what it took over from."""

    name = "stub"
    tables = Tables()

    def __init__(self, speed: float) -> None:
        self.speed, self.took, self.fallbacks = speed, [], 0
        self.phase, self._strike = 0.0, None

    def reset(self, torque=None) -> None:
        self.took, self._strike = [], None

    def tick(self, m: ProsthesisMeasurement) -> ControlOutput:
        from prosthesis_controller.contact_phase_pd import control_output

        if m.contact:
            if self._strike is None:
                self._strike = m.t
            self.phase = (m.t - self._strike) / STANCE
        else:
            self._strike = None
        return control_output((self.speed, 0.0), self.phase, Domain.PS, ControllerMode.STANCE,
                              0)

    def take_over(self, other: Stub) -> None:
        self.took.append(other.speed)
        self._strike = other._strike

    def blended(self, other: Stub, w: float) -> Stub:
        return Stub((1 - w) * self.speed + w * other.speed)


def _m(t: float, contact: bool) -> ProsthesisMeasurement:
    return ProsthesisMeasurement(t=t, knee_angle=0.1, ankle_angle=0.0, knee_vel=0.0,
                                 ankle_vel=0.0, foot_load=500.0 if contact else 0.0,
                                 contact=contact, socket_pitch=0.0)


#: s: the stubs' stance; the hip then moves 0.7 m over it, 1.0 m/s
STANCE = 0.7
SPEEDS, RATES = (0.6, 0.8, 1.0, 1.2), (0.55, 0.75, 1.0, 1.15)


def _walk(ctl: SpeedFollowing, strides: int, stance: float = STANCE, stride: float = 1.1,
          dt: float = 0.001) -> list[float]:
    """Tick through ``strides`` strides starting with a heel strike at 0.1 s, the foot down
    for ``stance`` s of each: each tick's torque (its controller's speed)."""
    out = []
    for k in range(round((0.1 + strides * stride) / dt)):
        t = k * dt
        on = t >= 0.1 and (t - 0.1) % stride < stance
        out.append(float(ctl.tick(_m(t, on)).torque[0]))
    return out


def test_the_speed_is_read_over_the_flat_stance_and_switched_at_the_next_heel_strike():
    ctls = [Stub(v) for v in SPEEDS]
    sf = SpeedFollowing(ctls, SPEEDS, SPEEDS, RATES, 0.83)
    assert sf.controller is ctls[1] and sf.speed == 0.83  # nearest 0.83 - MARGIN, 0.8
    assert 0.83 - MARGIN < 0.9 < 1.0 - MARGIN
    assert sf.speed_of(0.875) == pytest.approx(0.9) and sf.speed_of(2.0) == 1.2  # clamped
    torque = _walk(sf, 2)
    # the hip's rate over the flat window: 0.7 m over 0.7 s, read to a tick: 1.0 m/s
    assert sf.speed == pytest.approx(1.0, abs=0.01)
    assert sf.controller is ctls[2] and ctls[2].took == [0.8]  # handed over once
    # the switch waits for the heel strike after the toe-off that read it (1.2 s)
    changes = (np.flatnonzero(np.diff(torque) != 0) + 1) * 0.001
    assert changes == pytest.approx([1.2], abs=0.0015)


def test_a_stance_that_is_not_walking_leaves_the_estimate():
    sf = SpeedFollowing([Stub(v) for v in SPEEDS], SPEEDS, SPEEDS, RATES, 0.83)
    _walk(sf, 2, stance=0.04 / 0.3)  # a flat window of 0.04 s: a stumble
    assert sf.speed == 0.83 and sf.active == 1
    sf.restart(1.15)
    assert sf.speed == 1.15 and sf.active == 3 and sf.fallbacks == 0


def test_the_flat_stance_rate_of_a_walk():
    t = np.arange(0.0, 2.0, 0.001)
    contact = (t >= 0.2) & (t < 0.9)
    phase = np.where(contact, (t - 0.2) / 0.7, 0.0)
    contact[1500:] = True  # the next heel strike
    assert flat_stance_rate(Tables(), t, phase, contact) == pytest.approx(1.0, rel=1e-3)
    with pytest.raises(ValueError, match="no flat window"):
        flat_stance_rate(Tables(flat=(2.0, 3.0)), t, phase, contact)


def test_the_speeds_between_the_librarys_are_blends():
    ctls, v = filled([Stub(s) for s in SPEEDS], SPEEDS, 0.05)
    assert v == pytest.approx(np.arange(0.6, 1.2001, 0.05))
    assert [c.speed for c in ctls] == pytest.approx(v)  # each a blend of its neighbours
    assert ctls[4].speed == 0.8 and isinstance(ctls[4], Stub)


def test_rates_that_do_not_rise_with_the_speed_are_left_out_or_refused():
    # a calibration walk that read off its neighbours (the first) is left out by the factory
    assert rising([1.014, 0.886, 0.904, 0.922, 0.939]) == [1, 2, 3, 4]
    assert rising([0.5, 0.7, 0.6, 0.8]) == [0, 1, 3] and rising([]) == []
    with pytest.raises(ValueError, match="rise together"):
        SpeedFollowing([Stub(v) for v in SPEEDS], SPEEDS, SPEEDS, (0.5, 0.4, 1.0, 1.1), 0.8)
    with pytest.raises(ValueError, match="two or more"):
        SpeedFollowing([Stub(v) for v in SPEEDS], SPEEDS, (0.6,), (0.5,), 0.8)
    with pytest.raises(ValueError, match="one controller per speed"):
        SpeedFollowing([Stub(0.6)], SPEEDS, SPEEDS, RATES, 0.8)
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


def test_the_stance_qp_blends_each_domain_over_its_span(two_gaits):
    """A blend moves each domain's span of the phase between the two gaits' (their
    boundaries move with the pace), keeps the nearer's samples, and blends each with the
    other's sample at the same share of its domain."""
    from prosthesis_controller.contact_clf_qp import domain_spans

    a, b = (c.stance for c in two_gaits)
    sa, sb = domain_spans(a), domain_spans(b)
    assert [d for d, _, _ in sa] == [d for d, _, _ in sb]
    assert any(a.phase[i1] != b.phase[k1] for (_, _, i1), (_, _, k1) in zip(sa, sb, strict=True))
    for w, near in ((0.25, a), (0.75, b)):
        m = blend_stance(a, b, w)
        assert m.domain == near.domain and len(m.phase) == len(near.phase)
        assert np.all(np.diff(m.phase) >= 0)
        for (_, i0, i1), (_, k0, k1), (_, m0, m1) in zip(sa, sb, domain_spans(m), strict=True):
            for ia, kb, im in ((i0, k0, m0), (i1, k1, m1)):  # the span's ends
                assert m.phase[im] == pytest.approx((1 - w) * a.phase[ia] + w * b.phase[kb])
                assert m.u_ref[im] == pytest.approx((1 - w) * a.u_ref[ia] + w * b.u_ref[kb])
    # a blended controller ticks like one: a finite torque within the motors
    mixed = two_gaits[0].blended(two_gaits[1], 0.5)
    out = mixed.tick(replace(_m(0.0, True), socket_pitch=-0.2, knee_angle=0.05))
    assert np.all(np.isfinite(out.torque)) and np.all(np.abs(out.torque) <= mixed.law.limits)
