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
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from hp_model.human_prosthesis import BodyVariation
from orchestrator.experiments.scenarios import ORACLE  # the run that labels a draw walkable
from orchestrator.sweep.spec import Choice, Fixed, Normal, SweepSpec, Uniform

#: the human outputs an output offset moves (one draw each, in this order)
HUMAN_JOINTS = ("th_lh", "th_lk", "th_la", "th_rh")
#: the human segments whose masses ``plant.segment_mass`` scales (one draw each)
SEGMENTS = ("hat", "thigh", "shank", "foot")
__all__ = ["ORACLE", "Draw", "RunKey", "make_draw", "run_keys"]
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
    # the plant (the simulated walker), which the controller's model does not follow
    segment_mass: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)  # SEGMENTS
    hat_com: float = 1.0
    iwalk_mass: float = 1.0
    prosthesis_mass: float = 1.0
    prosthesis_inertia: float = 1.0
    prosthesis_com: float = 1.0
    human_stiffness: float = 1.0  # factor on the human's tracking bandwidth
    human_delay: float | None = None  # s; None: the continuous human
    # AMPRO3's encoders (0: ideal)
    angle_noise: float = 0.0  # rad, standard deviation
    velocity_noise: float = 0.0  # rad/s, standard deviation
    angle_resolution: float = 0.0  # rad, quantization step
    velocity_resolution: float = 0.0  # rad/s, quantization step
    sensor_seed: int = 0
    # AMPRO3's IMU on the top link (socket pitch)
    imu_bias: float = 0.0  # rad
    imu_noise: float = 0.0  # rad, standard deviation
    # the person's pace from stride to stride (multi-contact gaits)
    stride_cv: float = 0.0  # coefficient of variation
    stride_seed: int = 0
    armature: float = 1.0  # factor on the plant's drives' armature (multi-contact gaits)
    # the person's walking speed over a gait library (m/s): the one it starts at and the one
    # it changes to (orchestrator.sweep.contact.speed_change); None: the gait's own
    speed_start: float | None = None
    speed_end: float | None = None

    def columns(self) -> dict[str, Any]:
        """The draw as flat result columns (``draw_`` prefix, offsets and segment masses one
        column each)."""
        d = asdict(self)
        off = d.pop("output_offset")
        seg = d.pop("segment_mass")
        d.pop("family")
        d.pop("index")
        out = {f"draw_{k}": v for k, v in d.items()}
        out.update({f"draw_offset_{j}": float(v) for j, v in zip(HUMAN_JOINTS, off,
                                                                   strict=True)})
        out.update({f"draw_{s}_mass": float(v) for s, v in zip(SEGMENTS, seg, strict=True)})
        return out

    @classmethod
    def from_columns(cls, family: str, index: int, row: dict[str, Any]) -> Draw:
        """The draw stored in a results row (:meth:`columns`; a column missing from an
        older sweep's row takes the nominal value)."""
        kw: dict[str, Any] = {}
        for f in fields(cls):
            if f.name in ("family", "index"):
                continue
            if f.name == "output_offset":
                kw[f.name] = tuple(float(row.get(f"draw_offset_{j}", 0.0))
                                   for j in HUMAN_JOINTS)
            elif f.name == "segment_mass":
                kw[f.name] = tuple(float(row.get(f"draw_{s}_mass", 1.0)) for s in SEGMENTS)
            else:  # a column absent or null in an older sweep's row: the nominal value
                v = row.get(f"draw_{f.name}")
                kw[f.name] = f.default if v is None else v
        return cls(family, index, **kw)

    @property
    def is_bezier_only(self) -> bool:
        """Only the human Bezier perturbation (what ``hpcosim run --perturb human:A:S`` sets)."""
        return self == Draw(self.family, self.index, self.bezier_amplitude, self.bezier_seed)

    @property
    def body(self) -> BodyVariation:
        """The plant's human body (:class:`hp_model.human_prosthesis.BodyVariation`)."""
        hat, thigh, shank, foot = self.segment_mass
        return BodyVariation(hat, thigh, shank, foot, self.hat_com, self.iwalk_mass)

    @property
    def plant_prosthesis(self) -> tuple[float, float, float]:
        """(mass, inertia, COM) factors of the plant's prosthesis links."""
        return self.prosthesis_mass, self.prosthesis_inertia, self.prosthesis_com

    @property
    def encoder(self) -> tuple[float, float, float, float, float, float]:
        """:class:`orchestrator.loop.Encoder`'s fields (but the seed), in order."""
        return (self.angle_noise, self.velocity_noise, self.angle_resolution,
                self.velocity_resolution, self.imu_bias, self.imu_noise)


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
    seg = get("plant.segment_mass", [1.0] * len(SEGMENTS), len(SEGMENTS))
    sensor_seed = 0
    if any(k.startswith("sensor.") for k in q):
        sensor_seed = int(quantity_rng(spec.seed, family, index, "sensor.seed")
                          .integers(0, SEED_LIMIT))
    return Draw(family, index, amp, seed, tuple(off), get("socket.tube_scale", 1.0),
                get("model.mass_scale", 1.0), get("model.inertia_scale", 1.0),
                get("model.com_scale", 1.0), get("initial.knee", 0.0),
                get("initial.ankle", 0.0), tuple(seg), get("plant.hat_com", 1.0),
                get("plant.iwalk_mass", 1.0), get("plant.prosthesis_mass", 1.0),
                get("plant.prosthesis_inertia", 1.0), get("plant.prosthesis_com", 1.0),
                get("human.stiffness", 1.0), get("human.delay", None),
                get("sensor.angle_noise", 0.0), get("sensor.velocity_noise", 0.0),
                get("sensor.angle_resolution", 0.0), get("sensor.velocity_resolution", 0.0),
                sensor_seed, get("sensor.imu_bias", 0.0), get("sensor.imu_noise", 0.0),
                get("human.stride_cv", 0.0),
                int(quantity_rng(spec.seed, family, index, "human.stride_seed")
                    .integers(0, SEED_LIMIT)) if "human.stride_cv" in q else 0,
                get("plant.armature", 1.0), *get("human.speed", [None, None], 2))


def run_keys(spec: SweepSpec) -> Iterator[RunKey]:
    """Every run of the spec, draw-major (all controllers and families of draw 0 first), so
    an interrupted sweep has comparable numbers of runs per cell; with ``label_walkable``
    each draw's :data:`ORACLE` run comes before its controllers'."""
    for i in range(spec.draws):
        for f in spec.families:
            for c in spec.run_controllers:
                yield RunKey(c, f, i)
