"""contact-pd, the multi-contact graph's prosthesis controller from its own sensors
(prosthesis_controller.contact_phase_pd; orchestrator.experiments.contact_walk): its stance phase
from the socket IMU and the encoders against the model's own frames, its tables, its
behaviour on bad input, and the committed cycle walked with it in the in-process plant."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from characterization.gait.contact_gait import GAINS, contact_gait_of
from hp_model.domains import PROSTHESIS, Domain
from hp_model.leg_kinematics import LegKinematics
from orchestrator.cosim.contact_controllers import controller_tables, loop_simulator
from orchestrator.experiments.contact_walk import walk_with_contact_pd
from prosthesis_controller.contact_phase_pd import (
    ContactPhasePD,
    PhaseTable,
)
from prosthesis_controller.interface import ControllerMode
from prosthesis_controller.measurement import ProsthesisMeasurement
from tests.multicontact_cycle import load_cycle

pytestmark = pytest.mark.slow  # about a minute: the committed cycle's model, compiled once


@pytest.fixture(scope="module")
def cycle():
    model, traj, durations, _ = load_cycle()
    return model, traj, durations, contact_gait_of(model, traj, durations)


@pytest.fixture(scope="module")
def tables(cycle):
    model, traj, _, gait = cycle
    leg = LegKinematics.of(model)
    return leg, controller_tables(loop_simulator(model, gait, GAINS), leg, traj)


def test_the_stance_phase_is_the_hip_over_the_heels_ground_point(cycle) -> None:
    """From (socket pitch, knee, ankle) alone: the hip over the heel while the heel is down,
    over the toe plus the heel-to-toe length once the heel is up, against the full model's
    frames at every node of the fitted stance (hip, heel and toe from all 12 coordinates)."""
    model, traj, _, _ = cycle
    leg = LegKinematics.of(model)
    frames = model.numeric()["frames"]
    ix = model.coord_names.index
    pk, pa = ix(PROSTHESIS[0]), ix(PROSTHESIS[1])
    pitch = model.pitch_row("socket")
    def frame_x(q: np.ndarray, name: str) -> float:
        return float(np.asarray(frames(q, np.zeros(model.nq))[0])[0, model.frame_index(name)])

    # the heel's ground point: where ds_p's heel strike put it (the cycle's last domain:
    # ps of the next stride starts from it; ps of this cycle from its own heel)
    ground = {d: frame_x(np.asarray(traj[Domain.PS if d != Domain.DS_P else d]["q"])[:, 0],
                         "p_heel") for d in (Domain.DS_P, Domain.PS, Domain.PS_TOE, Domain.DS_H)}
    for d, heel_x in ground.items():
        q = np.asarray(traj[d]["q"])
        for k in range(q.shape[1]):
            want = frame_x(q[:, k], "hip") - heel_x
            got = leg.progress(float(pitch @ q[:, k]), q[pk, k], q[pa, k])
            assert got == pytest.approx(want, abs=2e-3), (d, k)  # the fit holds contacts to 1 mm


def test_the_tables_span_one_stance_and_one_swing(cycle, tables) -> None:
    _, _, durations, _ = cycle
    _, tab = tables
    for t in (tab.stance, tab.swing):
        assert t.phase[0] == 0.0 and 0.99 < t.phase[-1] <= 1.0  # the last 1 ms sample
        assert np.all(np.diff(t.phase) >= -1e-9)
    stance = sum(durations[d] for d in (Domain.DS_P, Domain.PS, Domain.PS_TOE, Domain.DS_H))
    swing = durations[Domain.PNS] + durations[Domain.PNS_TOE]
    assert tab.swing_time == pytest.approx(swing, rel=0.03)
    assert tab.stance.phase.size * 1e-3 == pytest.approx(stance, rel=0.03)  # 1 ms samples
    assert tab.progress[1] - tab.progress[0] > 0.5  # m: a stance's hip travel


def test_bad_input_gives_no_torque_and_the_output_is_bounded(tables) -> None:
    leg, tab = tables
    limits = (0.5, 0.6)
    ctl = ContactPhasePD(tab, leg, (50.0, 50.0), limits)
    ok = ProsthesisMeasurement(0.1, 0.3, 0.1, 0.0, 0.0, 300.0, True, 0.2)
    u = ctl.tick(ok).torque
    assert all(math.isfinite(v) for v in u)
    assert abs(u[0]) <= limits[0] and abs(u[1]) <= limits[1]
    for bad in (ProsthesisMeasurement(0.2, math.nan, 0.1, 0.0, 0.0, 300.0, True, 0.2),
                ProsthesisMeasurement(0.3, 0.3, 0.1, 0.0, 0.0, 300.0, True, math.nan),
                ProsthesisMeasurement(0.4, 0.3, 0.1, math.inf, 0.0, 300.0, False, 0.2)):
        out = ctl.tick(bad)
        assert tuple(out.torque) == (0.0, 0.0)
        assert out.diagnostics.mode == ControllerMode.FAULT


def test_a_swing_longer_than_the_gaits_holds_its_landing_posture(tables) -> None:
    """Past the swing table's end (the clock's phase above 1, no heel strike yet: a person
    slower than the gait) the reference is the table's last angles at rest: zero rates and
    no torque of the gait's, so the law is a PD on the landing posture; inside the table it
    is the table's."""
    leg, tab = tables
    kp, kd = 100.0, 3.0  # STANCE_GAINS and SWING_GAINS, joint side
    ctl = ContactPhasePD(tab, leg, (50.0, 50.0), (10.0, 10.0), swing_phase="time")
    k1, a1 = tab.swing.values[-1][:2]
    assert np.abs(tab.swing.values[-1][2:]).max() > 0.1  # the gait lands moving
    ctl.tick(ProsthesisMeasurement(1.0, 0.3, 0.1, 0.0, 0.0, 300.0, True, 0.2))  # stance
    toe_off = ProsthesisMeasurement(1.001, 0.3, 0.1, 0.0, 0.0, 0.0, False, 0.2)
    ctl.tick(toe_off)
    mid = replace(toe_off, t=1.001 + 0.5 * tab.swing_time)
    assert ctl.reference(mid) == pytest.approx(tab.swing.at(0.5))
    late = replace(toe_off, t=1.001 + 1.2 * tab.swing_time, knee_angle=k1 + 0.1,
                   ankle_angle=a1 - 0.05, knee_vel=2.0, ankle_vel=-1.0)
    assert ctl.reference(late) == (k1, a1, 0.0, 0.0, 0.0, 0.0)
    assert ctl.phase == pytest.approx(1.2)
    u = ctl.tick(late).torque
    assert u[0] == pytest.approx((kp * -0.1 + kd * -2.0) / 50.0)
    assert u[1] == pytest.approx((kp * 0.05 + kd * 1.0) / 50.0)


def test_a_thigh_that_stays_flexed_past_its_pace_holds_the_landing_posture(tables) -> None:
    """The residual thigh's swing phase (``swing_phase="thigh"``): a thigh that flexes along
    the gait's pitch at the gait's pace, then stays at its peak flexion with no heel strike,
    takes the phase past 1 at the pace it set; there the reference is the landing posture at
    rest, as for the clock (not the gait's last torque, which would flex the waiting knee)."""
    leg, tab = tables
    ctl = ContactPhasePD(tab, leg, (50.0, 50.0), (10.0, 10.0), swing_phase="thigh")
    k1, a1 = tab.swing.values[-1][:2]
    ctl.tick(ProsthesisMeasurement(1.0, 0.3, 0.1, 0.0, 0.0, 300.0, True, 0.0))  # stance
    peak = int(np.argmin(tab.swing_pitch))
    t = 1.001 + np.arange(0.0, 2.0 * tab.swing_time, 1e-3)
    pitch = np.interp(np.minimum((t - t[0]) / tab.swing_time, tab.swing.phase[peak]),
                      tab.swing.phase, tab.swing_pitch)
    for ti, p in zip(t, pitch, strict=True):
        m = ProsthesisMeasurement(float(ti), k1, a1, 0.0, 0.0, 0.0, False, float(p))
        ref = ctl.reference(m)
    assert ctl.phase > 1.5
    assert ref == (k1, a1, 0.0, 0.0, 0.0, 0.0)


def test_a_reset_forgets_the_thighs_peak(tables) -> None:
    """The peak the thigh's phase learns from a walk's swings is the walk's: a reset (a new
    run, the next sweep draw on the same controller) forgets it."""
    leg, tab = tables
    ctl = ContactPhasePD(tab, leg, (50.0, 50.0), (10.0, 10.0), swing_phase="thigh")
    assert ctl._thigh.peak_offset == 0.0
    ctl._thigh.peak_offset = 0.05
    ctl.reset()
    assert ctl._thigh.peak_offset == 0.0


def test_a_phase_table_clamps_and_interpolates() -> None:
    t = PhaseTable(np.array([0.0, 0.5, 1.0]), np.arange(18.0).reshape(3, 6))
    np.testing.assert_allclose(t.at(0.25), np.arange(6) + 3.0)
    np.testing.assert_allclose(t.at(-1.0), np.arange(6))
    np.testing.assert_allclose(t.at(2.0), np.arange(6) + 12.0)


def test_the_committed_cycle_walks_with_contact_pd(cycle) -> None:
    """10 steps in the in-process plant (AMPRO3's sensors, the torque held each 1 ms within
    the motors' limits), stride and speed within 3 % of the fitted cycle's."""
    model, traj, durations, gait = cycle
    walk = walk_with_contact_pd(model, gait, traj, steps=10)
    assert walk.walks, walk.line()
    stride = sum(durations.values())
    _, _, _, stride_length = load_cycle()
    assert np.all(np.abs(walk.strides / stride - 1) < 0.03), walk.strides
    assert np.all(np.abs(walk.speeds / (stride_length / stride) - 1) < 0.03), walk.speeds
    assert "contact-pd" in walk.line() and walk.to_json()["controller"].endswith("sensors")


def _swing_ends(model, traj, gait, ctl, steps: int, *, oracle: bool = False
                ) -> list[tuple[float, float]]:
    """Each completed swing's (duration (s), phase at its last tick) as ``ctl`` walks the
    plant of ``gait`` (the in-process plant with ideal sensors) for ``steps`` steps; with
    ``oracle`` the plant's own feedback linearization drives the prosthesis while ``ctl``
    ticks on the same measurements (what it reads of a walk a prosthesis walks)."""
    from characterization.gait.contact_gait import start_state
    from characterization.gait.multicontact import GRAPH
    from orchestrator.loop.link import measurement
    from orchestrator.loop.plant import SimulatorPlant

    plant = SimulatorPlant(loop_simulator(model, gait, GAINS), *start_state(traj),
                           GRAPH.domains[0], mode="full" if oracle else "human")
    ctl.reset()
    ends, t_off, last = [], None, (0.0, math.nan)
    while plant.fall is None and plant.run.steps < steps:
        m = measurement(plant.observe())
        out = ctl.tick(m)
        if not m.contact:
            t_off = m.t if t_off is None else t_off
            last = (m.t, out.diagnostics.tau)
        elif t_off is not None:
            ends.append((last[0] - t_off, last[1]))
            t_off = None
        plant.actuate(None if oracle else out.torque)
        if plant.fall is not None:
            break
        plant.advance()
    return ends


def test_the_thigh_phase_follows_a_person_who_swings_faster(cycle) -> None:
    """``swing_phase="thigh"``: with the simulated person's hip 8 % faster than the gait's
    (thigh and all: its joints follow the hip's progress), each prosthesis swing ends with
    the thigh's phase within 0.03 of 1 (measured 0.98), where the time since toe-off over
    the gait's swing time would read the swing's shortening.  This person's thigh starts
    its swing 4.4 deg higher and peaks where the gait's does: read to that peak from its
    own toe-off, the first swing too (read against the gait's range it ended at 1.32); on
    the gait's own pace every swing ends within 0.04 of 1.
    The prosthesis is the plant's own (the oracle) while the controller reads the walk (its
    swings 3 % shorter at this pace: the person's toe domains keep their time): this is the
    phase's reading, not whether `clfqp` walks that person."""
    from orchestrator.cosim.contact_controllers import contact_clfqp
    from orchestrator.experiments.contact_perturbations import paced

    model, traj, _, gait = cycle
    ctl = contact_clfqp(model, gait, traj, swing_phase="thigh")
    T = ctl.law.tables.swing_time
    for pace in (1.0, 1.08):
        ends = _swing_ends(model, traj, paced(gait, pace), ctl, 6, oracle=True)
        assert len(ends) >= 2, pace
        for k, (duration, phase) in enumerate(ends):  # the clock: duration / T, 0.97 at 1.08
            if pace == 1.0:
                assert phase == pytest.approx(1.0, abs=0.04), (pace, phase)
                assert duration / T == pytest.approx(1.0, abs=0.03), (pace, duration)
                continue
            # shorter: the clock would end it early (the toe domains keep their time)
            assert duration / T < 0.98, (pace, duration)
            assert phase == pytest.approx(1.0, abs=0.03), (pace, k, phase)
