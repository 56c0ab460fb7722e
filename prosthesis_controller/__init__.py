"""Prosthesis controllers (robust CLF-QP exact and relaxed, PD, robust-passive, swing, and
the phase-PD reference).
Depends only on :mod:`hp_model` (and numpy, scipy, piqp, casadi).  See ``README.md`` here.
"""

from prosthesis_controller.config import (
    ClfConfig,
    ControllerConfig,
    DomainConfig,
    PassiveConfig,
    PdConfig,
    PhasePdConfig,
    SafetyConfig,
    SwingConfig,
)
from prosthesis_controller.controllers import (
    BaseController,
    ClfQpController,
    ControllerContext,
    PassiveController,
    PDController,
    PhasePdController,
    make_controller,
)
from prosthesis_controller.interface import (
    Active,
    Controller,
    ControllerMode,
    ControllerName,
    ControlOutput,
    Diagnostics,
    QpOutcome,
)
from prosthesis_controller.measurement import Fault, ProsthesisMeasurement, validate

__all__ = [
    "Active",
    "BaseController",
    "ClfConfig",
    "ClfQpController",
    "ControlOutput",
    "Controller",
    "ControllerConfig",
    "ControllerContext",
    "ControllerMode",
    "ControllerName",
    "Diagnostics",
    "DomainConfig",
    "Fault",
    "PDController",
    "PassiveConfig",
    "PassiveController",
    "PdConfig",
    "PhasePdConfig",
    "PhasePdController",
    "ProsthesisMeasurement",
    "QpOutcome",
    "SafetyConfig",
    "SwingConfig",
    "make_controller",
    "validate",
]
