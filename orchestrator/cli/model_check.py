"""``hpcosim model check``: build both models, evaluate them, and check physics that fixes
the answer (static balance, impact energy, subsystem consistency) and evaluation speed."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from hp_model import HumanProsthesisModel, ProsthesisSubsystem
from hp_model.compiled import CompileBackend
from hp_model.domains import Domain
from hp_model.statics import standing_posture, static_equilibrium


@dataclass(frozen=True)
class CheckRow:
    name: str
    value: str
    expected: str
    ok: bool


def run_checks(model: HumanProsthesisModel, backend: CompileBackend = CompileBackend.AUTO,
               seed: int = 0) -> tuple[list[CheckRow], dict[str, float]]:
    """Rows of the check table and timing figures (median microseconds per call)."""
    rows: list[CheckRow] = []
    fs = model.numeric(backend)
    sub = ProsthesisSubsystem(model)
    sfs = sub.numeric(backend)
    g = model.tree.gravity
    M, mp = model.tree.total_mass, model.prosthesis_mass

    # 1. static stance on the prosthesis: F_s carries everything above the socket
    q0 = standing_posture(model)
    _, lam = static_equilibrium(model, Domain.PS, q0)
    fz, grf = lam[4], lam[1]
    rows.append(CheckRow("standing on prosthesis: socket F_z [N]", f"{fz:.3f}",
                         f"{-(M - mp) * g:.3f}", abs(fz + (M - mp) * g) < 1e-6 * M * g))
    rows.append(CheckRow("standing on prosthesis: ground F_z [N]", f"{grf:.3f}",
                         f"{M * g:.3f}", abs(grf - M * g) < 1e-6 * M * g))

    rng = np.random.default_rng(seed)
    q = q0 + rng.normal(scale=0.2, size=model.nq)
    q[7:10] = 0.0  # on the socket constraint
    qd = rng.normal(scale=0.5, size=model.nq)
    qd[7:10] = 0.0
    D, *_ = fs["terms_ps"](q, qd)
    eig = np.linalg.eigvalsh(D)
    rows.append(CheckRow("D(q) symmetric positive definite: min eig", f"{eig[0]:.3g}", "> 0",
                         eig[0] > 0 and np.allclose(D, D.T, atol=1e-12)))

    # 2. impact into ps: post-impact constraint velocity zero, kinetic energy not increased
    qd_plus, _ = fs["impact_ps"](q, qd)
    qd_plus = qd_plus.copy()
    _, _, J, _ = fs["terms_ps"](q, qd)
    T0 = float(fs["energy"](q, qd)[0][0])
    T1 = float(fs["energy"](q, qd_plus)[0][0])
    rows.append(CheckRow("impact ps: |E qd+|", f"{np.abs(J @ qd_plus).max():.2e}", "< 1e-9",
                         np.abs(J @ qd_plus).max() < 1e-9))
    rows.append(CheckRow("impact ps: KE after / before", f"{T1 / T0:.4f}", "<= 1",
                         T1 <= T0 * (1 + 1e-12)))

    # 3. subsystem reproduces the full model's prosthesis motion under the same F_s
    u = rng.normal(scale=0.5, size=model.nu)
    qdd, lam = fs["dyn_ps"](q, qd, u)
    qdd, lam = qdd.copy(), lam.copy()
    qb, qbd, qbdd = sub.from_full(q, qd, qdd)
    qbdd_sub, lam_sub = sfs["sub_dyn"](qb, qbd, u[4:], lam[3:6])
    err = float(np.abs(qbdd_sub - qbdd).max())
    rows.append(CheckRow("subsystem vs full: max |qbar_dd| difference", f"{err:.2e}", "< 1e-8",
                         err < 1e-8))
    err_f = float(np.abs(lam_sub - lam[0:3]).max())
    rows.append(CheckRow("subsystem vs full: ground wrench difference [N]", f"{err_f:.2e}",
                         "< 1e-6", err_f < 1e-6))

    timing = {
        "terms_ps_us": _median_us(fs["terms_ps"], q, qd),
        "dyn_ps_us": _median_us(fs["dyn_ps"], q, qd, u),
        "sub_reduced_us": _median_us(sfs["reduced"], np.r_[q[10:12], qd[10:12]]),
    }
    return rows, timing


def _median_us(f, *args, n: int = 2000, repeat: int = 5) -> float:
    samples = []
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(n):
            f(*args)
        samples.append((time.perf_counter() - t) / n * 1e6)
    return float(np.median(samples))
