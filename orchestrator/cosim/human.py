"""The human side of a co-simulation: the FMU file (given, or built once per gait, model and
builder and cached: :func:`ensure_fmu`) and its instance for one run (:func:`started_fmu`)."""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from human_fmu.build import TrackedGait
from human_fmu.instance import HumanFmu
from orchestrator.cosim.config import CosimError
from orchestrator.cosim.faults import FaultPlan


def sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes (hex)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def ensure_fmu(gait_path: Path, model: Any, fmu: Path | None = None,
               progress: Callable[[str], None] | None = None, *,
               tracked: TrackedGait | None = None) -> Path:
    """The FMU file: ``fmu`` if given, else a cached build for this gait, model and builder
    (``$HPCOSIM_CACHE`` or ``~/.cache/hpcosim``/fmu/<digest>/human.fmu; the digest covers
    the gait file, the model parameters and :func:`human_fmu.build.builder_digest`);
    ``tracked``: what the FMU tracks of a gait of another graph than the paper's (the file's
    multi-contact gait)."""
    if fmu is not None:
        if not Path(fmu).is_file():
            raise FileNotFoundError(f"{fmu}: no such FMU")
        from fmpy import read_model_description

        try:
            read_model_description(str(fmu))
        except Exception as e:  # fmpy raises zip, XML and schema errors alike
            raise CosimError(f"{fmu}: not an FMU ({type(e).__name__}: {e})") from None
        return Path(fmu)
    from hp_model.compiled import cache_root
    from human_fmu import build_fmu
    from human_fmu.build import builder_digest

    # a tracked gait's hash too: its curves come from the file by code outside the builder's
    key = f"{sha256(gait_path)}\0{model.parameter_hash()}\0{builder_digest()}"
    digest = hashlib.sha256((key if tracked is None else f"{key}\0{tracked.hash}")
                            .encode()).hexdigest()[:16]
    out = cache_root() / "fmu" / digest / "human.fmu"
    if not out.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        build_fmu(gait_path if tracked is None else tracked, out, model=model,
                  progress=progress)
    return out


@contextlib.contextmanager
def started_fmu(path: Path, plan: FaultPlan, walk: tuple[Any, Any, Any] | None = None
                ) -> Iterator[HumanFmu]:
    """The FMU at ``path`` instantiated and started with the plan's human perturbation
    (:meth:`FaultPlan.fmu_parameters`), on ``walk`` when given (the gait per domain and the
    state (q0, qd0) it starts from: :meth:`HumanFmu.walk_values`; else the gait it was
    built for); freed when the block ends."""
    fmu = HumanFmu(path)
    try:
        real, integer = plan.fmu_parameters()
        if walk is not None:
            real = {**fmu.walk_values(*walk), **real}
        fmu.start(real, integer)
        yield fmu
    finally:
        fmu.free()
