"""What a co-simulation is built from, loaded from its configuration and checked before any
process starts (:class:`RunInputs`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from orchestrator.cosim.config import CosimConfig
from orchestrator.cosim.drives import Drives
from orchestrator.cosim.human import ensure_fmu


@dataclass(frozen=True)
class RunInputs:
    """The model (of the configuration's subject and device), the gait and force tube
    loaded for it, the human FMU file and the prosthesis drives."""

    model: Any  # hp_model.human_prosthesis.HumanProsthesisModel
    gait: Any  # hp_model.gait_artifact.Gait
    tube: Any  # hp_model.force_tube.ForceTube
    fmu_path: Path
    drives: Drives

    @classmethod
    def load(cls, cfg: CosimConfig, model: Any = None,
             say: Callable[[str], None] | None = None) -> RunInputs:
        """Load ``cfg``'s artifacts (``model``: the model of ``cfg.subject`` and
        ``cfg.device`` if already built); a gait or tube made for another model or gait is
        refused here, not in the controller process. The FMU is built if not cached
        (progress through ``say``)."""
        import hp_model
        from hp_model.force_tube import load_tube
        from hp_model.gait_artifact import load_gait

        model = model or hp_model.load_model(_opt(cfg.subject), _opt(cfg.device))
        gait = load_gait(cfg.gait, model.parameter_hash())
        tube = load_tube(cfg.tube, gait.hash())
        fmu_path = ensure_fmu(Path(cfg.gait), model, cfg.fmu, say)
        return cls(model, gait, tube, fmu_path, Drives.of(model))


def _opt(path: Path | None) -> str | None:
    return None if path is None else str(path)
