"""Bezier curves continued outside [0, 1] (hp_model.bezier.evaluate_continued): the polynomial
itself inside; outside, its Taylor polynomial at the nearer end, of order 1 (C^1: the
curvature drops to zero at the end) or 2 (C^2: the accelerations a curve asks for stay
continuous, so a double support that lasts past tau = 1 asks for no jump in the forces)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from hp_model import bezier

ALPHA = np.array([[0.1, -0.3, 0.8, 0.2, -0.5, 0.4],
                  [1.0, 1.2, 0.7, 0.9, 1.5, 0.3]])


def _continued(order: int, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    tau = ca.SX.sym("tau")
    f = ca.Function("f", [tau], list(bezier.evaluate_continued(ca.DM(ALPHA), tau, order)))
    return tuple(np.asarray(v).ravel() for v in f(s))  # type: ignore[return-value]


def _poly(s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d1 = bezier.derivative(ALPHA)
    return (bezier.evaluate(ALPHA, s), bezier.evaluate(d1, s),
            bezier.evaluate(bezier.derivative(d1), s))


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("s", [0.0, 0.3, 0.77, 1.0])
def test_inside_it_is_the_polynomial(order, s):
    for got, want in zip(_continued(order, s), _poly(s), strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("end", [0.0, 1.0])
def test_second_order_is_continuous_to_the_curvature_at_each_end(end):
    """Value, slope and curvature just outside equal the polynomial's at the end (to the
    step's first order); the first-order continuation's curvature drops to zero there."""
    h = 1e-7 * (1 if end == 1.0 else -1)
    B, dB, ddB = _poly(end)
    B2, dB2, ddB2 = _continued(2, end + h)
    np.testing.assert_allclose(B2, B + dB * h, atol=1e-12)
    np.testing.assert_allclose(dB2, dB + ddB * h, atol=1e-9)
    np.testing.assert_allclose(ddB2, ddB, atol=1e-12)
    assert np.all(np.abs(ddB) > 0.1)  # a curve with curvature at its ends
    np.testing.assert_allclose(_continued(1, end + h)[2], 0.0, atol=0)


def test_second_order_is_the_taylor_quadratic_far_out():
    s, end = 1.2, 1.0
    B, dB, ddB = _poly(end)
    B2, dB2, ddB2 = _continued(2, s)
    np.testing.assert_allclose(B2, B + dB * 0.2 + ddB * 0.02, atol=1e-12)
    np.testing.assert_allclose(dB2, dB + ddB * 0.2, atol=1e-12)
    np.testing.assert_allclose(ddB2, ddB, atol=1e-12)


def test_an_order_other_than_one_or_two_is_refused():
    with pytest.raises(ValueError, match="order must be 1 or 2"):
        bezier.evaluate_continued(ca.DM(ALPHA), ca.SX.sym("t"), 3)
