"""The planar human-prosthesis model, written once in CasADi (paper Sec. III and V).

- :mod:`hp_model.tree`: generic planar kinematic trees and symbolic kinematics.
- :mod:`hp_model.dynamics`: D, H, constraint terms, KKT dynamics, impact map.
- :mod:`hp_model.hybrid`: actuated trees with constraint domains, compiled evaluation.
- :mod:`hp_model.human_prosthesis`: the 12-DOF human-prosthesis model (domains ps, pns).
- :mod:`hp_model.prosthesis`: the 5-DOF prosthesis subsystem and its 4-state form.
- :mod:`hp_model.config`: subject and device configs (TOML, validated).
"""

from hp_model.config import (
    ConfigError,
    DeviceConfig,
    SubjectConfig,
    default_device_path,
    default_subject_path,
    load_device,
    load_subject,
)
from hp_model.domains import Domain
from hp_model.human_prosthesis import ACTUATED, COORDS, HumanProsthesisModel
from hp_model.prosthesis import SUB_COORDS, ProsthesisSubsystem

__version__ = "0.1.0"

__all__ = [
    "ACTUATED",
    "COORDS",
    "SUB_COORDS",
    "ConfigError",
    "DeviceConfig",
    "Domain",
    "HumanProsthesisModel",
    "ProsthesisSubsystem",
    "SubjectConfig",
    "default_device_path",
    "default_subject_path",
    "load_device",
    "load_model",
    "load_subject",
]


def load_model(subject: str | None = None, device: str | None = None) -> HumanProsthesisModel:
    """Build the 12-DOF model from config paths (defaults: the shipped example files)."""
    s = load_subject(subject or default_subject_path())
    d = load_device(device or default_device_path())
    return HumanProsthesisModel(s, d)
