"""Run keys and draws: every run of a sweep is a pure function of (spec, controller, family,
draw index).

The random numbers of one quantity of one draw come from their own generator,
``SeedSequence(spec.seed, spawn_key=(crc32(family), draw, crc32(quantity)))`` (numpy
``default_rng``), so a draw does not depend on the number of draws, on the other families
or quantities, or on the controller: every controller of a sweep meets the same draws.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from orchestrator.sweep_spec import Choice, Fixed, Normal, SweepSpec, Uniform

#: the human outputs an output offset moves (one draw each, in this order)
HUMAN_JOINTS = ("th_lh", "th_lk", "th_la", "th_rh")
SEED_LIMIT = 2**31  # the FMU's human_seed is a 32-bit signed Integer


@dataclass(frozen=True, order=True)
class RunKey:
    """One run: ``controller/family/draw`` (the text form is the results' ``key``)."""

    controller: str
    family: str
    draw: int

    @property
    def text(self) -> str:
        return f"{self.controller}/{self.family}/{self.draw}"

    @classmethod
    def parse(cls, text: str) -> RunKey:
        parts = text.split("/")
        if len(parts) != 3 or not parts[2].isdigit():
            raise ValueError(f"run key '{text}': expected CONTROLLER/FAMILY/DRAW, e.g. "
                             "clfqp/human/17")
        return cls(parts[0], parts[1], int(parts[2]))


@dataclass(frozen=True)
class Draw:
    """The perturbation of one draw (nominal values where the family gives none)."""

    family: str
    index: int
    bezier_amplitude: float = 0.0  # rad
    bezier_seed: int = 0
    output_offset: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # rad
    tube_scale: float = 1.0
    mass_scale: float = 1.0
    inertia_scale: float = 1.0
    com_scale: float = 1.0
    knee_offset: float = 0.0  # rad
    ankle_offset: float = 0.0  # rad

    def columns(self) -> dict[str, Any]:
        """The draw as flat result columns (``draw_`` prefix, offsets one column each)."""
        d = asdict(self)
        off = d.pop("output_offset")
        d.pop("family")
        d.pop("index")
        out = {f"draw_{k}": v for k, v in d.items()}
        out.update({f"draw_offset_{j}": float(v) for j, v in zip(HUMAN_JOINTS, off,
                                                                   strict=True)})
        return out

    @property
    def is_bezier_only(self) -> bool:
        """Only the human Bezier perturbation (what ``hpcosim run --perturb human:A:S`` sets)."""
        return self == Draw(self.family, self.index, self.bezier_amplitude, self.bezier_seed)


def _crc(text: str) -> int:
    return zlib.crc32(text.encode("utf-8"))


def quantity_rng(seed: int, family: str, draw: int, quantity: str) -> np.random.Generator:
    """The generator of one quantity of one draw (module docstring)."""
    ss = np.random.SeedSequence(seed, spawn_key=(_crc(family), draw, _crc(quantity)))
    return np.random.default_rng(ss)


def sample(dist: Fixed | Uniform | Normal | Choice, rng: np.random.Generator,
           size: int | None = None) -> Any:
    """Values of a spec distribution (float, or an array of ``size``)."""
    if isinstance(dist, Fixed):
        v = np.full(size or 1, dist.value)
    elif isinstance(dist, Uniform):
        v = rng.uniform(dist.low, dist.high, size or 1)
    elif isinstance(dist, Normal):
        v = rng.normal(dist.mean, dist.std, size or 1)
    else:
        v = np.asarray(dist.values, float)[rng.integers(0, len(dist.values), size or 1)]
    return [float(x) for x in v] if size else float(v[0])


def make_draw(spec: SweepSpec, family: str, index: int) -> Draw:
    """Draw ``index`` of ``family`` (module docstring)."""
    if family not in spec.families:
        raise ValueError(f"family '{family}' is not in the spec ({', '.join(spec.families)})")
    if index < 0:
        raise ValueError(f"draw index {index} must be >= 0")
    q = spec.families[family].quantities()

    def get(name: str, default: Any, size: int | None = None) -> Any:
        if name not in q:
            return default
        return sample(q[name], quantity_rng(spec.seed, family, index, name), size)

    amp = get("human.bezier_amplitude", 0.0)
    seed = 0
    if "human.bezier_amplitude" in q:
        seed = int(quantity_rng(spec.seed, family, index, "human.bezier_seed")
                   .integers(0, SEED_LIMIT))
    off = get("human.output_offset", [0.0] * len(HUMAN_JOINTS), len(HUMAN_JOINTS))
    return Draw(family, index, amp, seed, tuple(off), get("socket.tube_scale", 1.0),
                get("model.mass_scale", 1.0), get("model.inertia_scale", 1.0),
                get("model.com_scale", 1.0), get("initial.knee", 0.0),
                get("initial.ankle", 0.0))


def run_keys(spec: SweepSpec) -> Iterator[RunKey]:
    """Every run of the spec, draw-major (all controllers and families of draw 0 first), so
    an interrupted sweep has comparable numbers of runs per cell."""
    for i in range(spec.draws):
        for f in spec.families:
            for c in spec.controllers:
                yield RunKey(c, f, i)
