"""Where the run's two processes spend their CPU: the CPU each one runs on
(:func:`cpu_plan`, :func:`pinned`) and how long a receive polls before it blocks
(:func:`bus_poll_us`)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

from orchestrator.cosim.config import CosimConfig
from orchestrator.modes import CosimMode
from prosthesis_controller.timing import pin_thread


def cpu_plan(cfg: CosimConfig) -> tuple[int | None, int | None]:
    """(plant CPU, controller CPU) in lockstep mode when ``pin_cpus`` and this process may
    use two CPUs, else (None, None): a pair of the allowed CPUs, chosen by process id on a
    larger machine so that runs started side by side spread out (on two CPUs: both).

    Lockstep alternates between the two processes, each always busy or about to be; on a
    small shared machine, letting the scheduler place them makes each wake-up (the reply
    arriving, the next cycle's frames) land on a CPU busy with the other process or other
    jobs. Each process on its own CPU, with its zenoh threads, keeps those hand-offs local
    (measured: docs/cosim.md). Realtime mode idles between ticks and is better
    served by any free CPU: pinned, a pinned process stuck behind another job missed 50
    periods in a row in 2 of 6 runs at the 2 ms cycle, unpinned in none.
    """
    avail = sorted(os.sched_getaffinity(0))
    if not cfg.pin_cpus or cfg.mode != CosimMode.LOCKSTEP or len(avail) < 2:
        return None, None
    i = 2 * (os.getpid() % (len(avail) // 2))
    return avail[i], avail[i + 1]


@contextlib.contextmanager
def pinned(cpu: int | None) -> Iterator[None]:
    """The calling thread on ``cpu`` only (None: left as it is) until the block ends, then
    its affinity restored; threads started meanwhile (zenoh's) inherit the CPU."""
    if cpu is None:
        yield
        return
    before = pin_thread(cpu)
    try:
        yield
    finally:
        os.sched_setaffinity(0, before)


def bus_poll_us(cfg: CosimConfig) -> float:
    """How long a receive polls before it blocks, on both sides [us]: ``poll_us`` in lockstep
    (the next frame is due within a fraction of a millisecond), 0 in realtime mode (pacing
    to the wall clock: nothing to gain, a CPU to keep free)."""
    return float(cfg.poll_us) if cfg.mode == CosimMode.LOCKSTEP else 0.0
