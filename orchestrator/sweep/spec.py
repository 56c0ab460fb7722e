"""The sweep specification (TOML, ``schema_version = 1``), validated on load.

A sweep runs every (controller, family, draw) of the spec: ``draws`` random draws of each
perturbation *family*, each draw run once per controller (the controllers face the same
draws: a paired comparison).  A family combines any of four groups of perturbations, each
quantity given as a number (fixed) or a distribution::

    [families.NAME]
    human.bezier_amplitude = {dist = "uniform", low = 0.0, high = 0.02}  # rad, every
                            # Bezier coefficient of the human's outputs, SplitMix64 generator
                            # of human_fmu.perturbation (its seed is drawn per run)
    human.output_offset    = {dist = "normal", mean = 0.0, std = 0.02}   # rad, a constant
                            # added to each human output (th_lh, th_lk, th_la, th_rh; drawn
                            # independently per joint, same in both domains)
    socket.tube_scale      = {dist = "uniform", low = 1.0, high = 3.0}   # the socket-force
                            # deviations exceed the controller's tube by this factor (its
                            # tube is the spec's tube divided by it, about F*)
    model.mass_scale       = {dist = "choice", values = [0.8, 1.2]}      # controller model
    model.inertia_scale    = 1.0                                          # errors: prosthesis
    model.com_scale        = 1.0                                          # links (fixed/choice)
    initial.knee           = {dist = "uniform", low = -0.05, high = 0.05} # rad, prosthesis
    initial.ankle          = 0.0                                          # initial offsets
    human.stiffness        = {dist = "uniform", low = 0.5, high = 1.0}    # the human's
                            # tracking bandwidth: (eps, kp, kd) -> (s eps, s^2 kp, s kd)
    human.delay            = {dist = "uniform", low = 0.0, high = 0.03}   # s, the human's
                            # feedback delay (hp_model.simulator); absent: continuous human
    human.stride_cv        = {dist = "uniform", low = 0.0, high = 0.03}   # the person's
                            # pace varying from stride to stride, coefficient of variation
                            # (characterization.gait.pace_variability; multi-contact gaits only)
    human.speed            = {dist = "uniform", low = 0.7, high = 1.3}    # m/s, the speed the
                            # person starts at and the one it changes to (two draws), walking
                            # the spec's gait library (orchestrator.sweep.contact; multi-contact)
    plant.segment_mass     = {dist = "uniform", low = 0.8, high = 1.2}    # the simulated
                            # human's segment masses (hat, thigh, shank, foot, each drawn)
    plant.hat_com          = 1.0      # HAT COM distance from the hip, factor
    plant.iwalk_mass       = 1.0      # factor
    plant.prosthesis_mass  = 1.0      # the plant's prosthesis links (the controller keeps
    plant.prosthesis_inertia = 1.0    # the nominal ones): mass, inertia, COM factors
    plant.prosthesis_com   = 1.0
    plant.armature         = {dist = "choice", values = [0.5, 1.5]}  # the plant's drives'
                            # reflected rotor inertia (the device's armature), factor; fixed
                            # or choice (each value compiles a walker); multi-contact only
    sensor.angle_noise     = 0.0      # rad, std of white noise on the encoder angles
    sensor.velocity_noise  = 0.0      # rad/s, std on the joint velocities
    sensor.angle_resolution = 0.0     # rad, quantization step (0: none)
    sensor.velocity_resolution = 0.0  # rad/s
    sensor.imu_bias        = 0.0      # rad, constant error of the IMU's socket pitch
    sensor.imu_noise       = 0.0      # rad, std of white noise on the socket pitch

``plant.*`` and ``human.stiffness`` / ``human.delay`` change the simulated walker, not the
controller: the controller keeps the nominal model.  Each distinct plant body compiles its
model once per worker (about 7 s; the compiled library is cached on disk by its source).
With ``label_walkable`` (default true) each draw is also run once by the ``oracle``, the
controller-independent walkability rule: the prosthesis under full-state feedback
linearization with perfect knowledge of the plant and perfect sensing
(:func:`orchestrator.experiments.scenarios.run_scenario`); a draw is walkable when the
oracle walks it, and the report gives every controller's success among walkable draws.

Distributions: a number, ``{dist = "fixed", value}``, ``{dist = "uniform", low, high}``,
``{dist = "normal", mean, std}``, ``{dist = "choice", values = [...]}``.  Model errors take
only fixed or choice values (each distinct value compiles a controller model once per
worker).  An unbounded normal distribution on a quantity with a range (amplitude >= 0,
scales > 0) is allowed; a draw outside the range makes that run fail with its error
recorded.

A multi-contact gait (``gait fit --domains multicontact``) sweeps the person's graph
(:mod:`orchestrator.sweep.contact`): its controllers ``clfqp`` and ``phase-pd``, the
simulator backend, the quantities ``human.bezier_amplitude``, ``human.output_offset``,
``human.stiffness``, ``human.stride_cv``, ``human.speed`` (with ``library``, a gait library
of the gait's person: ``hpcosim gait library``), ``plant.armature``, ``initial.*`` and
``sensor.*``, and
optionally a tube fitted around it (:func:`orchestrator.sweep.contact_spec.check_multicontact`).

A bad spec is refused with one line naming the file and the field (:class:`SpecError`).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from hp_model.artifacts import canonical_hash
from hp_model.config import (
    ConfigError,
    NonNegative,
    StrictConfig,
    read_toml,
    validation_message,
)
from orchestrator.modes import SweepBackend
from prosthesis_controller import ControllerName

SCHEMA_VERSION = 1
BACKENDS = ("simulator", "fmu")
FAMILY_NAME = re.compile(r"^[A-Za-z0-9_-]+$")


class SpecError(ConfigError):
    """A sweep spec that cannot be run (one line: file, field, reason)."""


class Fixed(StrictConfig):
    dist: Literal["fixed"] = "fixed"
    value: float


class Uniform(StrictConfig):
    dist: Literal["uniform"]
    low: float
    high: float

    @model_validator(mode="after")
    def _order(self) -> Uniform:
        if self.low > self.high:
            raise ValueError(f"low ({self.low}) must not exceed high ({self.high})")
        return self


class Normal(StrictConfig):
    dist: Literal["normal"]
    mean: float
    std: NonNegative


class Choice(StrictConfig):
    dist: Literal["choice"]
    values: tuple[float, ...] = Field(min_length=1)


Dist = Annotated[Fixed | Uniform | Normal | Choice, Field(discriminator="dist")]
#: the tags of :data:`Dist` (in a validation error's location, not fields)
DISTRIBUTIONS = ("fixed", "uniform", "normal", "choice")


def _as_dist(v: Any) -> Any:
    """A bare number is a fixed value."""
    if isinstance(v, int | float) and not isinstance(v, bool):
        return {"dist": "fixed", "value": v}
    return v


def support(d: Fixed | Uniform | Normal | Choice) -> tuple[float, float] | None:
    """(min, max) of the values a distribution can draw; None if unbounded."""
    if isinstance(d, Fixed):
        return d.value, d.value
    if isinstance(d, Uniform):
        return d.low, d.high
    if isinstance(d, Choice):
        return min(d.values), max(d.values)
    return (d.mean, d.mean) if d.std == 0 else None


class _Group(StrictConfig):
    @model_validator(mode="before")
    @classmethod
    def _numbers(cls, data: Any) -> Any:
        return {k: _as_dist(v) for k, v in data.items()} if isinstance(data, dict) else data


def _check_range(d: Any, lo: float, strict: bool) -> Any:
    if d is None:
        return d
    s = support(d)
    if s is not None and (s[0] < lo or (strict and s[0] <= lo)):
        rel = ">" if strict else ">="
        raise ValueError(f"must be {rel} {lo:g}; this distribution draws {s[0]:g}")
    return d


class HumanGroup(_Group):
    """The human's gait: Bezier coefficient perturbation and constant output offsets."""

    bezier_amplitude: Dist | None = None
    output_offset: Dist | None = None
    stiffness: Dist | None = None
    delay: Dist | None = None
    stride_cv: Dist | None = None
    speed: Dist | None = None

    @field_validator("bezier_amplitude", "delay", "stride_cv")
    @classmethod
    def _nonnegative(cls, d: Any) -> Any:
        return _check_range(d, 0.0, strict=False)

    @field_validator("speed")
    @classmethod
    def _speed(cls, d: Any) -> Any:
        from hp_model.speed_profile import SPEED_RANGE

        s = None if d is None else support(d)
        if d is not None and (s is None or s[0] < SPEED_RANGE[0] or s[1] > SPEED_RANGE[1]):
            raise ValueError(f"must draw within {SPEED_RANGE[0]:g}-{SPEED_RANGE[1]:g} m/s "
                             "(a bounded distribution)")
        return d

    @field_validator("stiffness")
    @classmethod
    def _positive(cls, d: Any) -> Any:
        return _check_range(d, 0.0, strict=True)


class SocketGroup(_Group):
    """Socket-force deviation beyond the controller's tube."""

    tube_scale: Dist | None = None

    @field_validator("tube_scale")
    @classmethod
    def _positive(cls, d: Any) -> Any:
        return _check_range(d, 0.0, strict=True)


class ModelGroup(_Group):
    """Parameter errors of the controller's model (prosthesis links)."""

    mass_scale: Dist | None = None
    inertia_scale: Dist | None = None
    com_scale: Dist | None = None

    @field_validator("mass_scale", "inertia_scale", "com_scale")
    @classmethod
    def _discrete(cls, d: Any, info: ValidationInfo) -> Any:
        if d is not None and not isinstance(d, Fixed | Choice):
            raise ValueError("model errors take a fixed value or a choice (each distinct "
                             "value compiles a controller model)")
        return _check_range(d, 0.0, strict=info.field_name != "com_scale")


class PlantGroup(_Group):
    """The simulated walker's parameters (factors; the controller keeps the nominal)."""

    segment_mass: Dist | None = None
    hat_com: Dist | None = None
    iwalk_mass: Dist | None = None
    prosthesis_mass: Dist | None = None
    prosthesis_inertia: Dist | None = None
    prosthesis_com: Dist | None = None
    armature: Dist | None = None

    @field_validator("segment_mass", "hat_com", "iwalk_mass", "prosthesis_mass",
                     "prosthesis_inertia")
    @classmethod
    def _positive(cls, d: Any) -> Any:
        return _check_range(d, 0.0, strict=True)

    @field_validator("armature")
    @classmethod
    def _armature(cls, d: Any) -> Any:
        if d is not None and not isinstance(d, Fixed | Choice):
            raise ValueError("the armature takes a fixed value or a choice (each distinct "
                             "value compiles the walker's model)")
        return _check_range(d, 0.0, strict=True)

    @field_validator("prosthesis_com")
    @classmethod
    def _nonnegative(cls, d: Any) -> Any:
        return _check_range(d, 0.0, strict=False)


class SensorGroup(_Group):
    """AMPRO3's encoders: white noise (standard deviations) and quantization steps; its IMU:
    a constant bias and white noise on the socket pitch."""

    angle_noise: Dist | None = None
    velocity_noise: Dist | None = None
    angle_resolution: Dist | None = None
    velocity_resolution: Dist | None = None
    imu_bias: Dist | None = None
    imu_noise: Dist | None = None

    @field_validator("angle_noise", "velocity_noise", "angle_resolution",
                     "velocity_resolution", "imu_noise")
    @classmethod
    def _nonnegative(cls, d: Any) -> Any:
        return _check_range(d, 0.0, strict=False)


class InitialGroup(_Group):
    """Offsets (rad) of the prosthesis knee and ankle from the gait's initial state."""

    knee: Dist | None = None
    ankle: Dist | None = None


GROUPS = ("human", "socket", "model", "initial", "plant", "sensor")
#: quantities only the in-process simulator models (the FMU backend refuses them)
SIMULATOR_ONLY = ("plant.", "human.stiffness", "human.delay")


class Family(StrictConfig):
    """One perturbation family (module docstring); empty = the nominal case."""

    human: HumanGroup = HumanGroup()
    socket: SocketGroup = SocketGroup()
    model: ModelGroup = ModelGroup()
    initial: InitialGroup = InitialGroup()
    plant: PlantGroup = PlantGroup()
    sensor: SensorGroup = SensorGroup()

    def quantities(self) -> dict[str, Any]:
        """The given quantities by dotted name (``human.bezier_amplitude``, ...)."""
        out = {}
        for g in GROUPS:
            for k, v in getattr(self, g):
                if v is not None:
                    out[f"{g}.{k}"] = v
        return out


class SweepSpec(StrictConfig):
    """A validated sweep spec; artifact paths are absolute after :func:`load_spec`."""

    schema_version: Literal[1] = 1
    name: str = "sweep"
    gait: Path
    tube: Path | None = None
    #: a gait library of the gait's person (``hpcosim gait library``): ``human.speed``'s
    library: Path | None = None
    subject: Path | None = None
    device: Path | None = None
    controllers: tuple[ControllerName, ...] = Field(min_length=1)
    families: dict[str, Family] = Field(min_length=1)
    draws: int = Field(ge=1)
    seed: int = Field(ge=0)
    steps: int = Field(10, ge=1)
    backend: SweepBackend = SweepBackend.SIMULATOR
    fmu: Path | None = None
    batch: int = Field(25, ge=1)
    label_walkable: bool = True

    @field_validator("controllers", mode="before")
    @classmethod
    def _controllers(cls, cs: Any) -> Any:
        if not isinstance(cs, list | tuple):
            return cs
        cs = tuple(ControllerName(c) for c in cs)  # one line naming the choices
        if len(set(cs)) != len(cs):
            raise ValueError("a controller is listed twice")
        return cs

    @field_validator("families")
    @classmethod
    def _family_names(cls, fams: dict[str, Family]) -> dict[str, Family]:
        for f in fams:
            if not FAMILY_NAME.match(f):
                raise ValueError(f"family name '{f}': use letters, digits, '_' and '-'")
        return fams

    @model_validator(mode="after")
    def _fmu(self) -> SweepSpec:
        if self.fmu is not None and self.backend != SweepBackend.FMU:
            raise ValueError("'fmu' is given but backend is not 'fmu'")
        if self.backend == SweepBackend.FMU:
            for name, fam in self.families.items():
                bad = [k for k in fam.quantities() if k.startswith(SIMULATOR_ONLY)]
                if bad:
                    raise ValueError(f"family '{name}': {', '.join(bad)} change the simulated "
                                     "walker, which the FMU does not model; use backend "
                                     "'simulator'")
        return self

    @property
    def run_controllers(self) -> tuple[str, ...]:
        """The runs of each draw: the oracle (with ``label_walkable``), then the
        controllers."""
        from orchestrator.sweep.draws import ORACLE

        return ((ORACLE,) if self.label_walkable else ()) + self.controllers

    @property
    def n_runs(self) -> int:
        return len(self.run_controllers) * len(self.families) * self.draws

    def identity(self) -> dict[str, Any]:
        """What a run's result depends on besides its controller, family and draw index
        (artifact contents enter through :func:`orchestrator.sweep.runs.Artifacts.digest`)."""
        return {"seed": self.seed, "steps": self.steps, "backend": self.backend}

    def family_hash(self, family: str) -> str:
        return canonical_hash(self.families[family].model_dump(mode="json"))


def _fail(path: Path, loc: str, msg: str) -> SpecError:
    return SpecError(f"{path}: field '{loc}': {msg}")


def parse_spec(data: dict[str, Any], path: Path) -> SweepSpec:
    """Validate a spec document; relative artifact paths are taken from ``path``'s folder."""
    if "schema_version" in data and data["schema_version"] != SCHEMA_VERSION:
        raise _fail(path, "schema_version", f"version {data['schema_version']!r} is not "
                    f"supported (this hpcosim reads version {SCHEMA_VERSION})")
    try:
        spec = SweepSpec.model_validate(data)
    except ValidationError as e:
        raise SpecError(f"{path}: {validation_message(e, skip=DISTRIBUTIONS)}") from None
    base = path.parent
    files: dict[str, Path] = {}
    for name in ("gait", "tube", "library", "subject", "device", "fmu"):
        p = getattr(spec, name)
        if p is None:
            continue
        p = p if p.is_absolute() else (base / p)
        if not p.is_file():
            raise _fail(path, name, f"no such file: {p}")
        files[name] = p.resolve()
    from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind
    from orchestrator.sweep.contact_spec import check_multicontact, check_paper

    if artifact_kind(files["gait"]) == MULTICONTACT_KIND:  # said here, before any worker
        check_multicontact(spec, path, files)
    else:
        check_paper(spec, path, files)
    return spec.model_copy(update=files)


def load_spec(path: str | Path, overrides: dict[str, Any] | None = None) -> SweepSpec:
    """Read and validate a sweep spec TOML; ``overrides`` replace top-level fields (CLI)."""
    path = Path(path)
    data = read_toml(path, SpecError)
    data.update({k: v for k, v in (overrides or {}).items() if v is not None})
    return parse_spec(data, path)
