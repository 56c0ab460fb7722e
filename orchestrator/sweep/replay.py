"""Rerun one stored run of a sweep in this process and compare it with its results row."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from orchestrator.modes import SweepBackend
from orchestrator.sweep.draws import RunKey, make_draw
from orchestrator.sweep.engine import prepare_fmu
from orchestrator.sweep.runs import Artifacts, make_resources, run_draw
from orchestrator.sweep.store import VOLATILE, ResultStore, read_results


@dataclass
class Replay:
    key: str
    row: dict[str, Any]  # recomputed now
    stored: dict[str, Any] | None  # from the results (None: not run yet)
    differences: dict[str, tuple[Any, Any]]  # column -> (stored, now)

    @property
    def identical(self) -> bool:
        return self.stored is not None and not self.differences


#: columns computed from the phase tau, which the FMU's C evaluates with another summation
#: order than numpy (the last bit may differ; human_fmu README)
TAU_COLUMNS = ("fail_tau", "knee_rms_ps_rad", "knee_rms_all_rad")
#: share of ps samples whose socket force may fall on the other side of the tube's edge
#: between the backends (_same_across_backends)
SOCKET_SHARE_TOL = 0.02


def _same_across_backends(k: str, a: Any, b: Any) -> bool:
    if k in ("backend", "run_hash"):
        return True
    if k in TAU_COLUMNS and a is not None and b is not None:
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
    if k == "socket_force_in_tube" and a is not None and b is not None:
        # the FMU outputs the socket force under the previous period's motor torque, the
        # simulator logs it under the new one: samples at the tube's edge may differ
        return abs(a - b) <= SOCKET_SHARE_TOL
    if k == "reason" and a and b:  # worded by each backend (the simulator with the event's
        return True  # numbers); the fall is compared by fall_reason, fail_t, fail_tau, ...
    return a == b


def compare_rows(a: dict[str, Any], b: dict[str, Any], across_backends: bool = False
                 ) -> dict[str, tuple[Any, Any]]:
    """Columns (other than where/when it ran) whose values differ: exactly, or with
    ``across_backends`` up to the backend's identity, the last bits of tau and the wording
    of the fall (its reason label, time, domain and tau must agree)."""
    out = {}
    for k in sorted(set(a) | set(b)):
        if k in VOLATILE:
            continue
        va, vb = a.get(k), b.get(k)
        same = _same_across_backends(k, va, vb) if across_backends else va == vb
        if not same:
            out[k] = (va, vb)
    return out


def replay_run(out: str | Path, key: str, backend: SweepBackend | str | None = None
               ) -> Replay:
    """Run ``key`` (CONTROLLER/FAMILY/DRAW) of the sweep in ``out`` again, from the
    artifacts stored there (on ``backend`` instead of the sweep's when given), and compare
    with its stored row."""
    backend = None if backend is None else SweepBackend(backend)
    store = ResultStore(Path(out))
    spec = store.spec()
    k = RunKey.parse(key)
    if k.controller not in spec.run_controllers:
        raise ValueError(f"controller '{k.controller}' is not in the sweep "
                         f"({', '.join(spec.run_controllers)})")
    if k.draw >= spec.draws:
        raise ValueError(f"draw {k.draw} is beyond the sweep's {spec.draws} draws")
    other = backend is not None and backend != spec.backend
    if other:
        spec = spec.model_copy(update={"backend": backend, "fmu": None})
    draw = make_draw(spec, k.family, k.draw)
    res = make_resources(Artifacts.from_spec(spec, prepare_fmu(spec)))
    try:
        row = run_draw(res, spec, k, draw)
    finally:
        res.close()
    t = read_results(out)
    stored = next((r for r in t.to_pylist() if r["key"] == k.text), None)
    diffs = compare_rows(stored, row, across_backends=other) if stored is not None else {}
    return Replay(k.text, row, stored, diffs)
