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
from collections.abc import Collection
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError

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


class SubjectLengths(StrictConfig):
    """Measured segment lengths, metres."""

    thigh: Positive  # hip centre to knee centre
    shank: Positive  # knee centre to ankle centre
    ankle_height: Positive  # ankle centre above the sole
    foot: Positive  # heel to toe
    heel: NonNegative  # heel behind the ankle centre
    trunk: Positive  # hip to shoulder: the head-arms-trunk (HAT) length


class SubjectConfig(StrictConfig):
    """A person: body mass (kg), sex (selects the table column), segment lengths."""

    schema_version: Literal[1]
    name: str
    sex: Sex
    body_mass: Positive
    radii_of_gyration: RadiiTable
    lengths: SubjectLengths
    notes: str = ""


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
    """Load and validate a subject TOML file."""
    return _load(path, SubjectConfig)


def load_device(path: Path | str) -> DeviceConfig:
    """Load and validate a device TOML file."""
    return _load(path, DeviceConfig)


def default_subject_path() -> Path:
    """The example subject shipped with the package."""
    return Path(str(resources.files("hp_model") / "configs" / "subject_example.toml"))


def default_device_path() -> Path:
    """The AMPRO3 + iWalk device estimates shipped with the package."""
    return Path(str(resources.files("hp_model") / "configs" / "device_ampro3.toml"))
