"""The person's heel strike sensed at the prosthesis's joints
(prosthesis_controller.heel_strike): a step of the joints' accelerations away from the
model's prediction is a strike, dated at the period it happened in, whatever the joints'
signs; the sweeps' encoder noise, a slow drift of the model's error and a step back to the
prediction are not."""

from __future__ import annotations

import numpy as np
import pytest

from prosthesis_controller.heel_strike import HeelStrikeSensor

DT = 1e-3  # s, the controller's period


def feed(sensor: HeelStrikeSensor, t: np.ndarray, vk: np.ndarray, va: np.ndarray,
         ak: np.ndarray, aa: np.ndarray) -> list[float | None]:
    return [sensor.update(*x) for x in zip(t, vk, va, ak, aa, strict=True)]


def walk(n: int, acc: tuple[float, float] = (12.0, -30.0)) -> tuple[np.ndarray, ...]:
    """n ticks of joints accelerating at ``acc`` (rad/s^2) as the model predicts."""
    t = np.arange(n) * DT
    return t, 0.3 + acc[0] * t, -0.2 + acc[1] * t, np.full(n, acc[0]), np.full(n, acc[1])


def step(t: np.ndarray, at: int, size: float) -> np.ndarray:
    """The speed of a joint whose acceleration steps by ``size`` (rad/s^2) at tick ``at``."""
    return size * np.clip(t - t[at], 0.0, None)


@pytest.mark.parametrize("knee, ankle", [(250.0, 250.0), (-470.0, 480.0), (0.0, -200.0)])
def test_a_step_of_the_joints_accelerations_is_a_strike_dated_at_its_period(
        knee: float, ankle: float) -> None:
    """The residual steps at tick 39 (the packaged person's early strikes: both joints up
    by 170-480 rad/s^2; the committed cycle's: the knee down, the ankle up): sensed within
    the window, dated at the start of the period it stepped in, held until reset."""
    t, vk, va, ak, aa = walk(80)
    s = HeelStrikeSensor(window=3, threshold=100.0)
    out = feed(s, t, vk + step(t, 39, knee), va + step(t, 39, ankle), ak, aa)
    assert all(x is None for x in out[:40])
    first = next(k for k, x in enumerate(out) if x is not None)
    assert first <= 39 + 3
    assert s.struck_at == pytest.approx(t[39])
    assert all(x == s.struck_at for x in out[first:])


def test_the_encoders_noise_and_a_drift_of_the_models_error_are_not_a_strike() -> None:
    """10 s of the sweeps' encoder noise (0.02 rad/s white; 16 rad/s^2 per joint on the
    statistic) and no strike: nothing.  A model error growing by 5 rad/s^2 per period (the
    perturbed persons' drift at the end of ps_toe was 3-20), to 500: nothing."""
    rng = np.random.default_rng(3)
    t, vk, va, ak, aa = walk(10_000)
    s = HeelStrikeSensor()
    assert all(x is None for x in feed(s, t, vk + rng.normal(0, 0.02, t.size),
                                       va + rng.normal(0, 0.02, t.size), ak, aa))
    t, vk, va, ak, aa = walk(100)
    drift = 0.5 * 5.0 / DT * t**2  # its acceleration 5 rad/s^2 more each period
    s.reset()
    assert all(x is None for x in feed(s, t, vk + drift, va - drift, ak, aa))


def test_a_step_back_to_the_prediction_is_not_a_strike() -> None:
    """The model in ps_toe a few periods before the plant's heel leaves the ground (the
    controller's phase ahead of the person): the residual 200 rad/s^2 off, then back to 0
    at the heel-off.  A step toward the prediction is the plant catching up with the model,
    not a strike (gaitalytics' library, a person changing speed: 7 of 200 draws fell on it
    before)."""
    t, vk, va, ak, aa = walk(40)
    lag = np.minimum(t, t[20])  # the residual 200 until tick 20, 0 after
    assert all(x is None for x in feed(HeelStrikeSensor(), t, vk + 200.0 * lag,
                                       va - 150.0 * lag, ak, aa))


def test_the_prediction_is_what_the_speeds_are_compared_with() -> None:
    """The joints' acceleration stepping by 300 rad/s^2: a strike if the model predicts
    none of it, none if it predicts the step too (a domain's own change)."""
    t, vk, va, ak, aa = walk(30)
    vk, va = vk + step(t, 15, 300.0), va + step(t, 15, 300.0)
    assert feed(HeelStrikeSensor(), t, vk, va, ak, aa)[-1] is not None
    predicted = ak + 300.0 * (t > t[15]), aa + 300.0 * (t > t[15])
    assert feed(HeelStrikeSensor(), t, vk, va, *predicted)[-1] is None


def test_restart_keeps_the_strike_and_reset_forgets_it() -> None:
    t, vk, va, ak, aa = walk(20)
    s = HeelStrikeSensor()
    feed(s, t, vk + step(t, 9, 400.0), va, ak, aa)
    assert s.struck_at == pytest.approx(t[9])
    s.restart()
    assert s.struck_at == pytest.approx(t[9])
    s.reset()
    assert s.struck_at is None
    # the windows not yet full sense nothing
    assert all(s.update(1.0 + k * DT, 9.0 * k, 9.0 * k, 0.0, 0.0) is None for k in range(6))


@pytest.mark.parametrize("window, threshold", [(0, 100.0), (3, 0.0), (3, float("nan"))])
def test_a_bad_setting_is_refused(window: int, threshold: float) -> None:
    with pytest.raises(ValueError, match="heel strike"):
        HeelStrikeSensor(window, threshold)
