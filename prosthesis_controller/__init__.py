"""Prosthesis controllers (robust CLF-QP exact and relaxed, PD, robust-passive, swing, and
the phase-PD reference).
Depends only on :mod:`hp_model` (and numpy, scipy, piqp, casadi).  See ``README.md`` here,
"Layout" for which module holds what.
"""

from prosthesis_controller.base import BaseController, StanceResult
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
from prosthesis_controller.context import ControllerContext
from prosthesis_controller.interface import (
    Active,
    Controller,
    ControllerMode,
    ControllerName,
    ControlOutput,
    Diagnostics,
    QpOutcome,
)
from prosthesis_controller.loop_clfqp import LoopClfQpController
from prosthesis_controller.measurement import Fault, ProsthesisMeasurement, validate
from prosthesis_controller.paper_clfqp import ClfQpController
from prosthesis_controller.passive import PassiveController
from prosthesis_controller.pd import PDController, PhasePdController
from prosthesis_controller.registry import CONTROLLERS, describe, make_controller

__all__ = [
    "CONTROLLERS",
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
    "LoopClfQpController",
    "PDController",
    "PassiveConfig",
    "PassiveController",
    "PdConfig",
    "PhasePdConfig",
    "PhasePdController",
    "ProsthesisMeasurement",
    "QpOutcome",
    "SafetyConfig",
    "StanceResult",
    "SwingConfig",
    "describe",
    "make_controller",
    "validate",
]
