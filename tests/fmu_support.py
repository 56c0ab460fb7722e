"""Shared pieces of the FMU tests: one FMU build per test run (shared by parallel workers), the
nominal-PD policy table of a gait, and the matching in-process simulator run."""

from __future__ import annotations

import fcntl
import hashlib
from pathlib import Path

import numpy as np

from hp_model.closed_loop import ClosedLoop
from hp_model.compiled import cache_root
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.gait_artifact import Gait, save_gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.simulator import HybridSimulator, SimOptions, SimResult
from human_fmu import build_fmu
from human_fmu.build import builder_digest
from tests.fmu_runner import NominalPD

#: PD gains (joint N m/rad, N m s/rad): stiff in stance, softer on the light swinging leg.
#: On the committed template gait every ps pair from (300, 10) to (2000, 40) with pns (200, 4)
#: walks 10 steps; with pns (50, 1) the swing lags and (300, 10), (500, 20) fall: these are
#: in the middle of the walking range, not on its edge.
PD_GAINS = {Domain.PS: (1000.0, 30.0), Domain.PNS: (200.0, 4.0)}

_BUILT: dict[str, Path] = {}


def built_fmu(tmp_path_factory, model: HumanProsthesisModel, gait: Gait,
              fmi_version: int = 2) -> tuple[Path, Path]:
    """(fmu path, gait path), built once per test run for this gait and FMI version: in the
    session's private cache (tests/conftest.py, ``private_cache``), which parallel workers
    share; a worker that wants an FMU another one is building waits for it (a file lock).
    Read only: a test that changes an FMU or its gait copies it first."""
    key = hashlib.sha256(f"{gait.hash()}\0{model.parameter_hash()}\0{builder_digest()}"
                         .encode()).hexdigest()[:16] + f"-fmi{fmi_version}"
    d = cache_root() / "test-fmu" / key
    if str(d) not in _BUILT:
        d.mkdir(parents=True, exist_ok=True)
        with open(d.parent / f".{key}.lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not (d / "human.fmu").is_file():
                save_gait(d / "gait.json", gait)
                build_fmu(d / "gait.json", d / "human.fmu", model=model,
                          fmi_version=fmi_version)
        _BUILT[str(d)] = d
    return d / "human.fmu", d / "gait.json"


def simulator(model: HumanProsthesisModel, gait: Gait, thetas=None,
              options: SimOptions | None = None) -> HybridSimulator:
    cl = ClosedLoop(model, gait.degree)
    th = thetas or {d: gait.theta(d) for d in PAPER_DOMAINS}
    return HybridSimulator(model, cl, th, gait.gains_array, options)


def policy_table(model: HumanProsthesisModel, gait: Gait, sim: HybridSimulator) -> dict:
    """The NominalPD table: nominal prosthesis angles, velocities and motor torques of the
    gait's collocation trajectory over its phase."""
    k, a = model.roles[Domain.PS].prosthesis
    ratio = [float(model.B[k, 4]), float(model.B[a, 5])]
    table: dict = {"ratio": ratio, "gains": {d: list(PD_GAINS[d]) for d in PAPER_DOMAINS},
                   "phase": {}, "nominal": {}}
    for d in PAPER_DOMAINS:
        vc, th = sim.cl.vcs[d], sim.thetas[d]
        table["phase"][d] = {"c_row": vc.c_row.tolist(), "p_min": float(th[vc.layout.p_min]),
                             "p_max": float(th[vc.layout.p_max])}
        tr = gait.trajectory[d]
        taus = [sim.phase(d, tr["q"][:, i]) for i in range(tr["q"].shape[1])]
        table["nominal"][d] = {"tau": taus, "q": tr["q"][[k, a]].tolist(),
                               "qd": tr["qd"][[k, a]].tolist(), "u": tr["u"][4:6].tolist()}
    return table


def python_run(sim: HybridSimulator, pd: NominalPD, q0: np.ndarray, qd0: np.ndarray,
               domain: str = Domain.PS, **kw) -> SimResult:
    """The in-process run with the same policy (tau = the simulator's phase of q)."""
    return sim.run(q0, qd0, domain, policy=lambda t, st: pd(st.domain, st.tau, st.q[10:12],
                                                            st.qd[10:12]), **kw)


def start_state(gait: Gait) -> tuple[np.ndarray, np.ndarray]:
    tr = gait.trajectory[Domain.PS]
    return tr["q"][:, 0].copy(), tr["qd"][:, 0].copy()
