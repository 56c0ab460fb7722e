"""Rerun one stored run of a sweep in this process and compare it with its results row."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from orchestrator.sweep_draws import RunKey, make_draw
from orchestrator.sweep_engine import prepare_fmu
from orchestrator.sweep_runs import Artifacts, Resources, run_draw
from orchestrator.sweep_store import VOLATILE, ResultStore, read_results


@dataclass
class Replay:
    key: str
    row: dict[str, Any]  # recomputed now
    stored: dict[str, Any] | None  # from the results (None: not run yet)
    differences: dict[str, tuple[Any, Any]]  # column -> (stored, now)

    @property
    def identical(self) -> bool:
        return self.stored is not None and not self.differences


def compare_rows(a: dict[str, Any], b: dict[str, Any]) -> dict[str, tuple[Any, Any]]:
    """Columns (other than where/when it ran) whose values differ, exactly."""
    return {k: (a.get(k), b.get(k)) for k in sorted(set(a) | set(b))
            if k not in VOLATILE and a.get(k) != b.get(k)}


def replay_run(out: str | Path, key: str, backend: str | None = None) -> Replay:
    """Run ``key`` (CONTROLLER/FAMILY/DRAW) of the sweep in ``out`` again, from the
    artifacts stored there, and compare with its stored row."""
    store = ResultStore(Path(out))
    spec = store.spec()
    k = RunKey.parse(key)
    if k.controller not in spec.controllers:
        raise ValueError(f"controller '{k.controller}' is not in the sweep "
                         f"({', '.join(spec.controllers)})")
    if k.draw >= spec.draws:
        raise ValueError(f"draw {k.draw} is beyond the sweep's {spec.draws} draws")
    other = backend is not None and backend != spec.backend
    if other:
        spec = spec.model_copy(update={"backend": backend, "fmu": None})
    draw = make_draw(spec, k.family, k.draw)
    res = Resources(Artifacts.from_spec(spec, prepare_fmu(spec)))
    try:
        row = run_draw(res, spec, k, draw)
    finally:
        res.close()
    t = read_results(out)
    stored = next((r for r in t.to_pylist() if r["key"] == k.text), None)
    diffs = compare_rows(stored, row) if stored is not None else {}
    if other:  # the same run on the other backend: only these two may differ
        diffs = {k: v for k, v in diffs.items() if k not in ("backend", "run_hash")}
    return Replay(k.text, row, stored, diffs)
