"""Lockstep co-simulation at 1 kHz with MCAP recording: real-time factor and the per-tick
overhead of the orchestrator beyond (zenoh round trip incl. controller tick + FMU step),
measured in the same run.

    PYTHONPATH=. python benchmarks/bench_cosim.py --gait gait.json --tube tube.json \
        [--controller clfqp] [--steps 20] [--fmu human.fmu]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from orchestrator.cosim import CosimConfig, run_cosim


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--gait", required=True, type=Path)
    p.add_argument("--tube", required=True, type=Path)
    p.add_argument("--fmu", type=Path)
    p.add_argument("--controller", default="clfqp")
    p.add_argument("--steps", type=int, default=20)
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as td:
        res = run_cosim(CosimConfig(controller=a.controller, gait=a.gait, tube=a.tube,
                                    fmu=a.fmu, steps=a.steps, record=Path(td) / "b.mcap"))
        size = (Path(td) / "b.mcap").stat().st_size
    t = res.timing_us
    core = t["round_trip"] + t["fmu"]
    print(f"ticks {res.ticks}, sim {res.sim_time:.3f} s, wall {res.wall_time:.3f} s, "
          f"steps {res.steps}, faulted {res.faulted}, fell {res.fell}, MCAP {size / 1e6:.1f} MB")
    print(f"real-time factor: {res.real_time_factor:.2f} (target >= 3)")
    print(f"per tick us: total {t['tick']:.1f}, round trip {t['round_trip']:.1f}, "
          f"FMU {t['fmu']:.1f}, orchestrator overhead {t['overhead']:.1f} "
          f"= {100 * t['overhead'] / t['tick']:.1f} % of the tick, "
          f"{100 * t['overhead'] / core:.1f} % of (round trip + FMU) (target <= 30 %)")
    print(f"reply latency us: {res.latency_us}")


if __name__ == "__main__":
    main()
