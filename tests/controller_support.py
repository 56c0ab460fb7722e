"""Helpers for the controller tests: tubes built directly, QP terms by name, and an RK4 of
the reduced 4-state prosthesis model with the controller in the loop (zero-order hold)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hp_model.force_tube import ForceTube
from hp_model.gait_artifact import Gait
from prosthesis_controller import BaseController, ControllerContext, ProsthesisMeasurement

STANCE_LOAD = 600.0  # N on the foot load cell: clearly stance


def tube_about_nominal(gait: Gait, half: tuple[float, float, float]) -> ForceTube:
    """The gait's nominal socket force (tau in [0, 1]) with constant half-widths."""
    h = np.asarray(half, dtype=float)[:, None] * np.ones((1, 2))
    return ForceTube(gait_hash=gait.hash(), tau_lo=0.0, tau_hi=1.0,
                     nominal=gait.socket_nominal, lower=-h, upper=h)


def constant_tube(gait: Gait, centre: np.ndarray, half: tuple[float, float, float]
                  ) -> ForceTube:
    """A tube whose box is the same at every phase: a constant nominal ``centre``."""
    h = np.asarray(half, dtype=float)[:, None] * np.ones((1, 2))
    return ForceTube(gait_hash=gait.hash(), tau_lo=0.0, tau_hi=1.0,
                     nominal=np.asarray(centre, dtype=float)[:, None], lower=-h, upper=h)


def clf_terms(ctx: ControllerContext, x: np.ndarray) -> dict[str, np.ndarray]:
    """All outputs of the compiled ``clf_qp`` function at x, by name (copies)."""
    f = ctx.terms.numeric["clf_qp"]
    outs = f(np.asarray(x, dtype=float), ctx.clf_params)
    return dict(zip(f.function.name_out(), (np.array(o) for o in outs), strict=True))


#: encoder-like measurement noise of ``stance_ticks``: rad, rad, rad/s, rad/s
TICK_NOISE = (1e-4, 1e-4, 1e-2, 1e-2)


def stance_ticks(model, gait: Gait, n: int, seed: int = 1
                 ) -> tuple[list[ProsthesisMeasurement], np.ndarray]:
    """``n`` consecutive 1 kHz measurements along the gait's ps collocation trajectory of
    (th_pk, th_pa) and their rates (interpolated, repeated with time running on, noise
    ``TICK_NOISE``), and the nominal motor torque at its start (a controller's u0)."""
    tr = gait.trajectory["ps"]
    i = [model.coord_names.index(c) for c in ("th_pk", "th_pa")]
    grid = np.arange(0.0, float(tr["t"][-1]), 1e-3)
    X = np.array([np.interp(grid, tr["t"], tr["q"][j]) for j in i]
                 + [np.interp(grid, tr["t"], tr["qd"][j]) for j in i]).T
    rng = np.random.default_rng(seed)
    noise = np.array(TICK_NOISE)
    meas = [ProsthesisMeasurement(k * 1e-3, *map(float, X[k % len(X)]
                                                 + rng.normal(size=4) * noise),
                                  STANCE_LOAD, True) for k in range(n)]
    return meas, tr["u"][4:, 0]


def stance_meas(t: float, x: np.ndarray) -> ProsthesisMeasurement:
    return ProsthesisMeasurement(t, float(x[0]), float(x[1]), float(x[2]), float(x[3]),
                                 STANCE_LOAD, True)


def rk4_step(f: Callable[[int, np.ndarray], np.ndarray], x: np.ndarray, h: float
             ) -> np.ndarray:
    """One classical RK4 step of x_dot = f(stage, x); ``stage`` (0-3) numbers the four
    evaluations in order."""
    k1 = f(0, x)
    k2 = f(1, x + 0.5 * h * k1)
    k3 = f(2, x + 0.5 * h * k2)
    k4 = f(3, x + h * k3)
    return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def simulate_reduced(ctl: BaseController, ctx: ControllerContext, x0: np.ndarray,
                     force: Callable[[np.ndarray], np.ndarray], duration: float,
                     dt: float = 1e-3, substeps: int = 4,
                     u0: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Closed loop of the reduced model x_dot = f_p + g_m u + g_s F_s(x): the controller
    ticks every ``dt`` on the exact state and its torque is held (ZOH) over ``substeps``
    RK4 steps.  Returns t, x (n, 4), u (n, 2), V, tau, rho, mode."""
    red = ctx.terms.numeric["reduced"]

    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        fp, gm, gs = red(x)
        return fp + gm @ u + gs @ force(x)

    ctl.reset(u0)
    x = np.array(x0, dtype=float)
    rows = []
    h = dt / substeps
    for k in range(round(duration / dt)):
        t = k * dt
        out = ctl.tick(stance_meas(t, x))
        u = out.torque
        d = out.diagnostics
        rows.append((t, *x, *u, d.V, d.tau, d.rho, d.mode, int(d.active)))
        for _ in range(substeps):
            x = rk4_step(lambda _stage, x, u=u: f(x, u), x, h)
        if not np.all(np.isfinite(x)):
            break
    cols = list(zip(*rows, strict=True))
    return {"t": np.array(cols[0]), "x": np.array(cols[1:5]).T, "u": np.array(cols[5:7]).T,
            "V": np.array(cols[7]), "tau": np.array(cols[8]), "rho": np.array(cols[9]),
            "mode": np.array(cols[10]), "active": np.array(cols[11])}


def simulate_reduced_continuous(ctl: BaseController, ctx: ControllerContext,
                                x0: np.ndarray, force: Callable[[np.ndarray], np.ndarray],
                                duration: float, h: float) -> dict[str, np.ndarray]:
    """Closed loop of the reduced model with the controller as a CONTINUOUS feedback law,
    the setting of the paper's guarantee: its torque is recomputed at every RK4 stage (no
    hold), step ``h`` (s).  The controller refuses a time that does not increase, so the four
    stage evaluations of a step carry the stamps t, t + h/4, t + h/2, t + 3h/4; the stance
    laws depend on the state only, never on time.  Returns t, x (n, 4), u (n, 2), V, tau,
    mode, active at the start of every step."""
    red = ctx.terms.numeric["reduced"]

    ctl.reset(None)
    x = np.array(x0, dtype=float)
    rows = []
    for k in range(round(duration / h)):
        t = k * h

        def f(stage: int, x: np.ndarray, t: float = t) -> np.ndarray:
            out = ctl.tick(stance_meas(t + stage * h / 4, x))
            if stage == 0:
                d = out.diagnostics
                rows.append((t, *x, *out.torque, d.V, d.tau, d.mode, int(d.active)))
            fp, gm, gs = red(x)
            return np.ravel(fp + gm @ out.torque + gs @ force(x))

        x = rk4_step(f, x, h)
        if not np.all(np.isfinite(x)):
            break
    cols = list(zip(*rows, strict=True))
    return {"t": np.array(cols[0]), "x": np.array(cols[1:5]).T, "u": np.array(cols[5:7]).T,
            "V": np.array(cols[7]), "tau": np.array(cols[8]), "mode": np.array(cols[9]),
            "active": np.array(cols[10])}
