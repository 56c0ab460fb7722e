"""Memory over a long lockstep co-simulation (clfqp, 1 kHz, MCAP recording by default): the
orchestrator's resident memory (RSS, this process: it runs the plant loop) after a warm-up
and at the end, its growth in per cent, and the slope of a straight line through the samples
after the warm-up (MB per simulated hour); the controller node's RSS alike (its process).

    PYTHONPATH=. python benchmarks/bench_memory.py --gait gait.json --tube tube.json \
        [--duration 3600] [--warmup 60] [--no-record] [--controller clfqp] \
        [--fmu human.fmu] [--json out.json]

``--duration`` is simulated seconds (3600: 15-40 min here, depending on the machine's load);
a shorter one (``--duration 600``) measures the slope and states the 3600 s extrapolation.
The walker walks as long as it can (the step limit is out of reach); a run that ends early
(a fall, a fault) is started again, in the same process, until the duration is walked
(``restarts`` counts them; the RSS is this process's over all of them).  The recording (one
per run, in a temporary folder, deleted after) holds every tick: about 0.86 MB per
simulated second (3 GB for an hour).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from hp_model.atomic_io import atomic_write_text
from orchestrator.cosim.config import CosimConfig
from orchestrator.cosim.master import run_cosim

#: RSS sampled every this many ticks (progress comes every 100)
SAMPLE_TICKS = 5000


def rss_mb(pid: int | str = "self") -> float | None:
    """Resident set size of process ``pid`` [MB] (None once it is gone)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def children() -> list[int]:
    """This process's child processes (the controller node of the current run)."""
    out: list[int] = []
    for task in Path("/proc/self/task").iterdir():
        try:
            out += [int(p) for p in (task / "children").read_text().split()]
        except OSError:
            continue
    return out


class Sampler:
    """RSS samples of this process and of the node, against the simulated time walked."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, float, float | None]] = []  # (t [s], plant, node) MB
        self.offset = 0.0  # simulated time of the runs before this one

    def progress(self, k: int, t: float, _steps: int) -> None:
        if k % SAMPLE_TICKS:
            return
        kids = children()
        node = rss_mb(kids[0]) if kids else None
        plant = rss_mb()
        assert plant is not None
        self.rows.append((self.offset + t, plant, node))


def slope_per_hour(rows: list[tuple[float, float]]) -> float:
    """Least-squares slope of (t [s], MB) in MB per simulated hour (0 with < 2 rows)."""
    if len(rows) < 2:
        return 0.0
    n = len(rows)
    mt = sum(t for t, _ in rows) / n
    mv = sum(v for _, v in rows) / n
    den = sum((t - mt) ** 2 for t, _ in rows)
    return 3600 * sum((t - mt) * (v - mv) for t, v in rows) / den if den else 0.0


def growth(rows: list[tuple[float, float | None]], warmup: float, duration: float
           ) -> dict[str, float]:
    """After ``warmup`` s: RSS then (the first sample) and at the end (the last), the
    largest, growth in %, the slope (MB/h) and the growth the slope gives at ``duration``
    and at 3600 s (% of the warm RSS)."""
    after = [(t, v) for t, v in rows if t >= warmup and v is not None]
    if not after:
        return {}
    warm, end = after[0][1], after[-1][1]
    s = slope_per_hour(after)
    span = max(0.0, duration - after[0][0])
    return {"warm_mb": warm, "end_mb": end, "max_mb": max(v for _, v in after),
            "growth_pct": 100 * (end - warm) / warm, "slope_mb_per_h": s,
            "fit_growth_pct": 100 * s * span / 3600 / warm,
            "extrapolated_3600_pct": 100 * s * max(0.0, 3600 - after[0][0]) / 3600 / warm}


def walk(a: argparse.Namespace, folder: Path, sampler: Sampler) -> dict[str, Any]:
    """Run until ``a.duration`` simulated seconds are walked; the runs' ends."""
    ends: list[str] = []
    ticks = 0
    t0 = time.perf_counter()
    while sampler.offset < a.duration - 1e-9:
        n = len(ends)
        cfg = CosimConfig(controller=a.controller, gait=Path(a.gait), tube=Path(a.tube),
                          steps=10**9, max_time=a.duration - sampler.offset,
                          record=None if a.no_record else folder / f"run{n}.mcap",
                          fmu=Path(a.fmu) if a.fmu else None)
        res = run_cosim(cfg, progress=sampler.progress)
        if cfg.record is not None:
            Path(cfg.record).unlink(missing_ok=True)
        ticks += res.ticks
        sampler.offset += res.sim_time
        why = (f"fault: {res.fault_reason}" if res.faulted else
               f"fell: {res.fall_reason}" if res.fell else "walked")
        ends.append(f"{why} at {res.sim_time:.3f} s ({res.steps} steps)")
        print(f"run {n}: {ends[-1]}; RSS {rss_mb():.1f} MB, load {os.getloadavg()[0]:.2f}",
              flush=True)
        if res.ticks == 0:
            raise SystemExit(f"bench_memory: run {n} made no tick: {why}")
    return {"ends": ends, "restarts": len(ends) - 1, "ticks": ticks,
            "wall_s": time.perf_counter() - t0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gait", required=True)
    ap.add_argument("--tube", required=True)
    ap.add_argument("--controller", default="clfqp")
    ap.add_argument("--duration", type=float, default=3600.0, help="simulated s (3600)")
    ap.add_argument("--warmup", type=float, default=60.0, help="simulated s (60)")
    ap.add_argument("--no-record", action="store_true", help="no MCAP recording")
    ap.add_argument("--fmu")
    ap.add_argument("--json")
    a = ap.parse_args()
    for name in ("gait", "tube", "fmu"):
        f = getattr(a, name)
        if f is not None and not Path(f).is_file():
            ap.error(f"--{name} {f}: no such file")
    if not (a.duration > 0 and 0 <= a.warmup < a.duration):
        ap.error("--duration must be > 0 and --warmup in [0, duration)")
    sampler = Sampler()
    with tempfile.TemporaryDirectory() as tmp:
        out = walk(a, Path(tmp), sampler)
    rows = sampler.rows
    out.update(duration_s=a.duration, warmup_s=a.warmup, record=not a.no_record,
               plant=growth([(t, p) for t, p, _ in rows], a.warmup, a.duration),
               node=growth([(t, n) for t, _, n in rows], a.warmup, a.duration),
               samples=[list(r) for r in rows], load=os.getloadavg()[0])
    for who in ("plant", "node"):
        g = out[who]
        if g:
            print(f"{who}: RSS {g['warm_mb']:.1f} MB after {a.warmup:g} s -> {g['end_mb']:.1f} "
                  f"MB at the end (max {g['max_mb']:.1f}): {g['growth_pct']:+.2f} %; slope "
                  f"{g['slope_mb_per_h']:+.2f} MB/h ({g['extrapolated_3600_pct']:+.2f} % "
                  "over 3600 s)")
    print(f"{out['ticks']} ticks in {out['wall_s']:.0f} s wall, {out['restarts']} restarts")
    if a.json:
        atomic_write_text(Path(a.json), json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
