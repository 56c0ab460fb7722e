"""The controllers by name: :data:`CONTROLLERS` (a :class:`ControllerName` -> how to build
it and what it is, in one line), :func:`make_controller` and :func:`describe` (the help text
of a ``--controller`` option).

Adding a controller: a module with a :class:`~prosthesis_controller.base.BaseController`
subclass, a member of :class:`ControllerName` and a row here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

from hp_model.force_tube import ForceTube
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.prosthesis import ProsthesisSubsystem
from prosthesis_controller.base import BaseController
from prosthesis_controller.config import ControllerConfig
from prosthesis_controller.context import ControllerContext
from prosthesis_controller.interface import ControllerName
from prosthesis_controller.loop_clfqp import LoopClfQpController
from prosthesis_controller.paper_clfqp import ClfQpController
from prosthesis_controller.passive import PassiveController
from prosthesis_controller.pd import PDController, PhasePdController


@dataclass(frozen=True)
class ControllerEntry:
    """How to build a controller on a context, and what it is (one line)."""

    build: Callable[[ControllerContext], BaseController]
    description: str


#: every controller, in :class:`ControllerName` order
CONTROLLERS: dict[ControllerName, ControllerEntry] = {
    ControllerName.CLFQP: ControllerEntry(
        partial(LoopClfQpController, relaxed=True),
        "interaction-aware robust CLF-QP, relaxed (the default)"),
    ControllerName.CLFQP_EXACT: ControllerEntry(
        partial(LoopClfQpController, relaxed=False),
        "interaction-aware robust CLF-QP, exact (no relaxation)"),
    ControllerName.CLFQP_PAPER: ControllerEntry(
        partial(ClfQpController, relaxed=True),
        "the paper's robust CLF-QP with the socket-force tube, relaxed (falls in the loop)"),
    ControllerName.CLFQP_PAPER_EXACT: ControllerEntry(
        partial(ClfQpController, relaxed=False),
        "the paper's robust CLF-QP with the socket-force tube, exact (falls in the loop)"),
    ControllerName.PD: ControllerEntry(
        PDController, "joint PD on the nominal stance trajectory (baseline)"),
    ControllerName.PASSIVE: ControllerEntry(
        PassiveController, "Spong's robust passivity-based law (baseline)"),
    ControllerName.PHASE_PD: ControllerEntry(
        PhasePdController,
        "nominal torque + knee PD + hip-velocity feedback (reference, not in the paper)"),
}


def describe(separator: str = "\n") -> str:
    """Each controller's name and description, ``name: description``, joined by
    ``separator``."""
    return separator.join(f"{name}: {entry.description}" for name, entry in CONTROLLERS.items())


def make_controller(name: ControllerName | str, gait: Gait | None, tube: ForceTube | None,
                    model: HumanProsthesisModel | None, config: ControllerConfig | None = None,
                    *, context: ControllerContext | None = None,
                    subsystem: ProsthesisSubsystem | None = None,
                    strict_tube: bool = True) -> BaseController:
    """The controller ``name`` (:data:`CONTROLLERS`).  Pass ``context`` to share the compiled
    terms between controllers (then gait, tube, model and config are taken from it and may
    be None).  Another name is a one-line ``ValueError`` naming the :class:`ControllerName`
    choices."""
    name = ControllerName(name)
    if context is None:
        if gait is None or tube is None or model is None:
            raise ValueError("make_controller needs a gait, a tube and a model, or a context")
        context = ControllerContext(gait, tube, model, config, subsystem=subsystem,
                                    strict_tube=strict_tube)
    return CONTROLLERS[name].build(context)
