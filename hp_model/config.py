"""Subject and device configuration files (TOML), validated on load; and the one base and
range types of every validated config in hpcosim (this module's, the controller's, the
mocap mapping's, the sweep spec's).

A subject config holds what is measured on the person (body mass, sex, limb lengths) and
names the radius-of-gyration table.  A device config holds AMPRO3 and iWalk parameters;
none of them is public, so every numeric value carries ``estimate`` and ``source``.

Every config model derives from :class:`StrictConfig`: frozen, an unknown field is an
error (a typo is never a silently ignored option), and **every float is finite** (NaN and
+-inf refused) unless its type says otherwise; of the range types below only
:data:`PositiveOrInf` does (+inf: no bound).  The range types carry the rule themselves,
so they hold in any pydantic model.

Errors are :class:`ConfigError` with one line naming the file and the field
(:func:`validation_message`), e.g.
``subject.toml: field 'lengths.thigh': Input should be greater than 0``.
"""

from __future__ import annotations

import tomllib
from collections.abc import Collection, Mapping
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from hp_model.anthropometry import RadiiTable, Sex

SCHEMA_VERSION = 1

#: > 0, finite
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
#: >= 0, finite
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
#: in [0, 1]
UnitInterval = Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]
#: > 0 or +inf (a bound that is off); NaN refused
PositiveOrInf = Annotated[float, Field(gt=0, allow_inf_nan=True)]


class ConfigError(ValueError):
    """A configuration file that cannot be used; the message is one line."""


class StrictConfig(BaseModel):
    """The base of every config model: frozen, unknown fields refused, floats finite."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


AnyConfig = TypeVar("AnyConfig", bound=StrictConfig)


def validation_message(e: ValidationError, skip: Collection[str] = ()) -> str:
    """One line for a failed validation: ``field 'a.b': <reason>`` of the first error, with
    ``(and N more)`` when there are more; ``skip`` drops location parts that name no field
    (the tags of a tagged union)."""
    errors = e.errors()
    loc = ".".join(str(p) for p in errors[0]["loc"] if p not in skip) or "<top>"
    msg = errors[0]["msg"].removeprefix("Value error, ")
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return f"field '{loc}': {msg}{more}"


#: plausible ranges of a person's measures: statures 1.0-2.3 m (Winter 2009's fractions of
#: stature for the lengths, with margins), masses of adolescents to the heaviest prosthesis
#: users the tables were made for; a value outside is a unit or typing error
BODY_MASS_RANGE = (20.0, 250.0)  # kg
HEIGHT_RANGE = (1.0, 2.3)  # m
LENGTH_RANGES: dict[str, tuple[float, float]] = {
    "thigh": (0.2, 0.65), "shank": (0.2, 0.65), "ankle_height": (0.03, 0.15),
    "foot": (0.12, 0.4), "heel": (0.0, 0.12), "trunk": (0.3, 0.9)}
#: thigh / shank: people measure 0.8-1.25 (Winter: 0.245 H / 0.246 H)
THIGH_SHANK_RATIO = (0.7, 1.45)


def _in_range(v: float, lo: float, hi: float, unit: str) -> float:
    if not lo <= v <= hi:
        raise ValueError(f"{v:g} {unit} is outside the plausible {lo:g}-{hi:g} {unit} (a unit "
                         "or typing error?)")
    return v


class SubjectLengths(StrictConfig):
    """Measured segment lengths, metres (ranges :data:`LENGTH_RANGES`)."""

    thigh: Positive  # hip centre to knee centre
    shank: Positive  # knee centre to ankle centre
    ankle_height: Positive  # ankle centre above the sole
    foot: Positive  # heel to toe
    heel: NonNegative  # heel behind the ankle centre
    trunk: Positive  # hip to shoulder: the head-arms-trunk (HAT) length

    @field_validator(*LENGTH_RANGES)
    @classmethod
    def _plausible(cls, v: float, info: ValidationInfo) -> float:
        lo, hi = LENGTH_RANGES[str(info.field_name)]
        return _in_range(v, lo, hi, "m")

    @model_validator(mode="after")
    def _consistent(self) -> SubjectLengths:
        if not self.heel < self.foot / 2:
            raise ValueError(f"heel {self.heel:g} m must be less than half the foot "
                             f"({self.foot:g} m): the ankle lies in the foot's rear half")
        if not self.ankle_height < self.shank / 2:
            raise ValueError(f"ankle_height {self.ankle_height:g} m must be less than half "
                             f"the shank ({self.shank:g} m)")
        lo, hi = THIGH_SHANK_RATIO
        if not lo <= self.thigh / self.shank <= hi:
            raise ValueError(f"thigh / shank = {self.thigh:g} / {self.shank:g} m = "
                             f"{self.thigh / self.shank:.2f}, outside [{lo}, {hi}] (a swapped "
                             "or mistyped length?)")
        return self


class SubjectConfig(StrictConfig):
    """A person: body mass (kg), sex (selects the table column), segment lengths."""

    schema_version: Literal[1]
    name: str
    sex: Sex
    body_mass: Positive
    radii_of_gyration: RadiiTable
    lengths: SubjectLengths
    notes: str = ""

    @field_validator("body_mass")
    @classmethod
    def _plausible_mass(cls, v: float) -> float:
        return _in_range(v, *BODY_MASS_RANGE, "kg")


class SubjectMeasures(StrictConfig):
    """What a lab states of a person (a mocap mapping's ``[subject]`` table): body mass
    (kg), height (m), sex; each optional."""

    mass_kg: Positive | None = None
    height_m: Positive | None = None
    sex: Sex | None = None

    @field_validator("mass_kg")
    @classmethod
    def _plausible_mass(cls, v: float | None) -> float | None:
        return None if v is None else _in_range(v, *BODY_MASS_RANGE, "kg")

    @field_validator("height_m")
    @classmethod
    def _plausible_height(cls, v: float | None) -> float | None:
        return None if v is None else _in_range(v, *HEIGHT_RANGE, "m")


class Estimate(StrictConfig):
    """A device parameter with its provenance."""

    value: float
    estimate: bool
    source: str


class PositiveEstimate(Estimate):
    value: Positive


class NonNegativeEstimate(Estimate):
    value: NonNegative


class IWalkConfig(StrictConfig):
    """The iWalk hands-free crutch carrying the bent shank (lumped into the right thigh)."""

    mass: PositiveEstimate  # kg
    length: PositiveEstimate  # m, knee platform to the pin connection (socket point)


class LinkConfig(StrictConfig):
    """A prosthesis link along its own -z axis from its proximal joint."""

    length: PositiveEstimate  # m, proximal joint to distal joint
    mass: PositiveEstimate  # kg
    com: NonNegativeEstimate  # m, COM distance from the proximal joint along the link
    inertia: PositiveEstimate  # kg m^2 about the COM


class FootConfig(StrictConfig):
    """The prosthesis foot: sole below the ankle, heel behind it."""

    ankle_height: PositiveEstimate  # m
    length: PositiveEstimate  # m, heel to toe
    heel: NonNegativeEstimate  # m, heel behind the ankle axis
    mass: PositiveEstimate  # kg
    com_x: Estimate  # m, forward of the ankle axis
    com_z: Estimate  # m, above (+) or below (-) the ankle axis
    inertia: PositiveEstimate  # kg m^2 about the COM


class ActuatorConfig(StrictConfig):
    """One prosthesis joint drive: joint torque = gear_ratio * motor torque."""

    gear_ratio: PositiveEstimate
    torque_limit: PositiveEstimate  # N m, motor side
    #: kg m^2, motor side: rotor and gear input.  A device file without it (written before
    #: the armature was modelled) has none, and keeps its model hash: absent, it is not in
    #: the dump the hash is taken of
    rotor_inertia: NonNegativeEstimate | None = Field(default=None,
                                                      exclude_if=lambda v: v is None)

    @property
    def armature(self) -> float:
        """The reflected rotor inertia at the joint, J_rotor N^2 (kg m^2): what the drive
        adds to the mass matrix's diagonal at its joint (Pinocchio's ``model.armature``);
        0 without ``rotor_inertia``."""
        if self.rotor_inertia is None:
            return 0.0
        return self.rotor_inertia.value * self.gear_ratio.value ** 2


class ProsthesisConfig(StrictConfig):
    top: LinkConfig  # socket adapter and pylon: pin connection to knee axis
    shin: LinkConfig  # knee axis to ankle axis
    foot: FootConfig
    knee: ActuatorConfig
    ankle: ActuatorConfig


class DeviceConfig(StrictConfig):
    """AMPRO3 worn through an iWalk adapter."""

    schema_version: Literal[1]
    name: str
    iwalk: IWalkConfig
    prosthesis: ProsthesisConfig
    notes: str = ""

    def with_armature_scaled(self, factor: float) -> DeviceConfig:
        """This device with its drives' rotor inertia (so their armature) times ``factor``
        (> 0; a device without rotor inertia stays without)."""
        if not (factor > 0 and factor < float("inf")):
            raise ValueError(f"an armature factor must be finite and > 0, got {factor}")
        p = self.prosthesis
        drives = {}
        for j in ("knee", "ankle"):
            a = getattr(p, j)
            r = a.rotor_inertia
            drives[j] = a if r is None else a.model_copy(update={
                "rotor_inertia": r.model_copy(update={"value": r.value * factor})})
        return self.model_copy(update={"prosthesis": p.model_copy(update=drives)})

    def without_armature(self) -> DeviceConfig:
        """This device with its drives' rotor inertia left out (rigid links and ideal
        drives: the paper's model), its dump and hash those of a file without it."""
        p = self.prosthesis
        drives = {j: getattr(p, j).model_copy(update={"rotor_inertia": None})
                  for j in ("knee", "ankle")}
        return self.model_copy(update={"prosthesis": p.model_copy(update=drives)})


def read_toml(path: Path | str, error: type[Exception] = ValueError) -> dict[str, Any]:
    """The TOML document at ``path``; an unreadable or invalid file raises ``error`` with a
    one-line message naming the file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise error(f"{path}: cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise error(f"{path}: not a TOML text file (not UTF-8 at byte {e.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise error(f"{path}: not valid TOML: {e}") from None


def _load(path: Path | str, model: type[AnyConfig]) -> AnyConfig:
    path = Path(path)
    data = read_toml(path, ConfigError)
    if "schema_version" in data and data["schema_version"] != SCHEMA_VERSION:
        raise ConfigError(
            f"{path}: field 'schema_version': version {data['schema_version']!r} is not "
            f"supported (this hpcosim reads version {SCHEMA_VERSION})"
        )
    try:
        return model.model_validate(data)
    except ValidationError as e:
        raise ConfigError(f"{path}: {validation_message(e)}") from None


def load_subject(path: Path | str) -> SubjectConfig:
    """Load and validate a subject: a TOML file, or the subject stored in a steps file
    (``.npz``/``.json`` of ``mocap process``) or a gait file (``.json``)
    (:func:`stored_subject`)."""
    p = Path(path)
    if p.suffix in ARTIFACT_SUFFIXES:
        found = stored_subject(p)
        if found is None:
            raise ConfigError(f"{p}: field '{SUBJECT_KEY}': missing (made before the subject "
                              "was stored with it; give a subject TOML)")
        return found[0]
    return _load(path, SubjectConfig)


#: the section of a steps or gait file that holds its subject: {"config": the subject
#: config's fields, "provenance": field -> where its value came from}
SUBJECT_KEY = "subject"
ARTIFACT_SUFFIXES = (".json", ".npz")


def subject_record(subject: SubjectConfig, provenance: Mapping[str, str] | None = None
                   ) -> dict[str, Any]:
    """The ``subject`` section an artifact stores (:data:`SUBJECT_KEY`)."""
    return {"config": subject.model_dump(mode="json"), "provenance": dict(provenance or {})}


def subject_from_record(record: Any, src: str) -> tuple[SubjectConfig, dict[str, str]]:
    """The subject and its provenance of a stored ``subject`` section; :class:`ConfigError`
    naming ``src`` and the field when it is not a valid subject."""
    if not isinstance(record, Mapping) or not isinstance(record.get("config"), Mapping):
        raise ConfigError(f"{src}: field '{SUBJECT_KEY}.config': missing or not an object")
    try:
        s = SubjectConfig.model_validate(record["config"])
    except ValidationError as e:
        raise ConfigError(f"{src}: {SUBJECT_KEY}.config: {validation_message(e)}") from None
    prov = record.get("provenance") or {}
    return s, {str(k): str(v) for k, v in prov.items()} if isinstance(prov, Mapping) else {}


def stored_subject(path: Path | str) -> tuple[SubjectConfig, dict[str, str]] | None:
    """The subject (and provenance) a steps (``.npz``/``.json``) or gait (``.json``) file
    stores, None when it stores none (a file made before subjects were stored)."""
    import json

    p = Path(path)
    try:
        if p.suffix == ".npz":
            import numpy as np
            with np.load(p, allow_pickle=False) as z:
                if SUBJECT_KEY not in z.files:
                    return None
                record = json.loads(str(z[SUBJECT_KEY]))
        else:
            doc = json.loads(p.read_text(encoding="utf-8"))
            if not isinstance(doc, dict) or doc.get(SUBJECT_KEY) is None:
                return None
            record = doc[SUBJECT_KEY]
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such file") from None
    except (OSError, ValueError, KeyError) as e:  # zip, JSON and decoding errors
        raise ConfigError(f"{p}: cannot read its subject ({type(e).__name__})") from None
    return subject_from_record(record, str(p))


def load_device(path: Path | str) -> DeviceConfig:
    """Load and validate a device TOML file."""
    return _load(path, DeviceConfig)


def default_subject_path() -> Path:
    """The example subject shipped with the package."""
    return Path(str(resources.files("hp_model") / "configs" / "subject_example.toml"))


def default_device_path() -> Path:
    """The AMPRO3 + iWalk device estimates shipped with the package."""
    return Path(str(resources.files("hp_model") / "configs" / "device_ampro3.toml"))
