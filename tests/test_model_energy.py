"""Energy conservation and constraint preservation: physics fixes the answers.

Unactuated motion conserves T + V exactly (ideal constraints do no work), so any drift is
integration or modelling error.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from hp_model.domains import PAPER_DOMAINS
from tests.conftest import random_state


def _energy(fs, q, qd):
    T, V = fs["energy"](q, qd)
    return float(T[0]) + float(V[0]), float(T[0])


def test_unconstrained_unactuated_motion_conserves_energy(model, rng):
    fs = model.numeric()
    terms = fs["terms_ps"]
    n = model.nq

    def rhs(_t, x):
        D, H, _, _ = terms(x[:n], x[n:])
        return np.r_[x[n:], np.linalg.solve(D, -H)]

    q0, qd0 = random_state(model, rng, on_socket=False, scale=0.5)
    sol = solve_ivp(rhs, (0.0, 2.0), np.r_[q0, qd0], method="DOP853", rtol=1e-12, atol=1e-12,
                    dense_output=False, t_eval=np.linspace(0, 2.0, 201))
    assert sol.success
    E = np.array([_energy(fs, x[:n], x[n:])[0] for x in sol.y.T])
    Tmax = max(_energy(fs, x[:n], x[n:])[1] for x in sol.y.T)
    drift = np.abs(E - E[0]).max() / Tmax  # relative to the largest kinetic energy reached
    assert drift < 1e-6, f"relative energy drift {drift:.2e}"


def _constrained_run(model, rng, dom):
    fs = model.numeric()
    dyn = fs[f"dyn_{dom}"]
    n = model.nq
    q0, _ = random_state(model, rng, scale=0.15)
    q0 = model.place_stance_foot(q0, dom)
    _, _, J, _ = fs[f"terms_{dom}"](q0, np.zeros(n))
    qd0 = rng.normal(scale=0.3, size=n)
    qd0 -= np.linalg.pinv(J) @ (J @ qd0)  # onto J qd = 0
    u0 = np.zeros(model.nu)

    def rhs(_t, x):
        qdd, _ = dyn(x[:n], x[n:], u0)
        return np.r_[x[n:], qdd]

    sol = solve_ivp(rhs, (0.0, 0.5), np.r_[q0, qd0], method="DOP853", rtol=1e-11, atol=1e-11,
                    t_eval=np.linspace(0, 0.5, 101))
    assert sol.success
    return fs, sol


def test_constrained_motion_keeps_constraints_and_energy(model, rng, record_property):
    for dom in PAPER_DOMAINS:
        fs, sol = _constrained_run(model, rng, dom)
        n = model.nq
        h0 = None
        drift_h = drift_v = 0.0
        for x in sol.y.T:
            pose, _ = fs["frames"](x[:n], x[n:])
            frame = model.domains[dom].constraints[0].target
            h = np.r_[pose[:, model.frame_index(frame)], x[7:10]]
            h0 = h.copy() if h0 is None else h0
            _, _, J, _ = fs[f"terms_{dom}"](x[:n], x[n:])
            drift_h = max(drift_h, np.abs(h - h0).max())
            drift_v = max(drift_v, np.abs(J @ x[n:]).max())
        E = np.array([_energy(fs, x[:n], x[n:])[0] for x in sol.y.T])
        Tmax = max(_energy(fs, x[:n], x[n:])[1] for x in sol.y.T)
        # plain floats: a parallel worker sends the properties to pytest-xdist's controller,
        # which cannot serialize numpy scalars
        record_property(f"{dom}_constraint_drift_m_rad", float(drift_h))
        record_property(f"{dom}_constraint_velocity_drift", float(drift_v))
        print(f"{dom}: over 0.5 s, max |h - h0| = {drift_h:.2e}, max |J qd| = {drift_v:.2e}")
        assert drift_h < 1e-7, f"{dom}: constraint drift {drift_h:.2e}"
        assert drift_v < 1e-7, f"{dom}: constraint velocity drift {drift_v:.2e}"
        assert np.abs(E - E[0]).max() / Tmax < 1e-6
