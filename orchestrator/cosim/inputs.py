"""What a co-simulation is built from, loaded from its configuration and checked before any
process starts (:class:`RunInputs`), and the human FMU's build identity
(:func:`fmu_identity`, :func:`check_fmu_identity`)."""

from __future__ import annotations

import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

from orchestrator.cosim.config import CosimConfig, CosimError
from orchestrator.cosim.drives import Drives
from orchestrator.cosim.human import ensure_fmu
from prosthesis_controller.interface import ControllerName

#: where an hpcosim FMU's modelDescription.xml names its build: FMI 2.0 VendorAnnotations,
#: FMI 3.0 Annotations (human_fmu.build, human_fmu.fmi3)
_BUILD = ("./VendorAnnotations/Tool[@name='hpcosim']/Build",
          "./Annotations/Annotation[@type='hpcosim']/Build")
_MAX_XML = 16 << 20  # bytes of modelDescription.xml read at most


def fmu_identity(path: Path) -> dict[str, str]:
    """The build identity an hpcosim FMU carries in its modelDescription.xml: ``model_hash``
    (the subject and device parameters), ``gait_hash``, ``gait_file``, ``subject``,
    ``device``; CosimError naming the file when it has none (not an hpcosim build)."""
    try:
        with zipfile.ZipFile(path) as z:
            info = z.getinfo("modelDescription.xml")
            if info.file_size > _MAX_XML:
                raise CosimError(f"{path}: modelDescription.xml of {info.file_size} bytes")
            root = ET.fromstring(z.read(info))
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError) as e:
        raise CosimError(f"{path}: not an FMU ({type(e).__name__}: {e})") from None
    for where in _BUILD:
        build = root.find(where)
        if build is not None and build.get("model_hash") and build.get("gait_hash"):
            return dict(build.attrib)
    raise CosimError(f"{path}: no hpcosim build identity (model and gait hashes) in its "
                     "modelDescription.xml; build the FMU with hpcosim fmu build")


def check_fmu_identity(path: Path, gait_hash: str, model: Any, gait_path: Path | str,
                       option: str = "--fmu") -> None:
    """Refuse the FMU at ``path`` (given as ``option``) unless it was built for the gait of
    hash ``gait_hash`` (the one loaded from ``gait_path``) and ``model`` (the subject and
    device): one line naming the FMU, what it was built for and the options that differ."""
    ident = fmu_identity(path)
    if ident["model_hash"] != model.parameter_hash():
        raise CosimError(
            f"{option} {path}: built for another subject or device (model {ident['model_hash']}: "
            f"{ident.get('subject', '?')}, {ident.get('device', '?')}) than --subject/--device "
            f"give (model {model.parameter_hash()}); build one with hpcosim fmu build")
    if ident["gait_hash"] != gait_hash:
        raise CosimError(
            f"{option} {path}: built for another gait ({ident.get('gait_file', '?')}, gait "
            f"{ident['gait_hash']}) than --gait {gait_path} (gait {gait_hash}); build one "
            f"with hpcosim fmu build --gait {gait_path}")


@dataclass(frozen=True)
class RunInputs:
    """The model (of the configuration's subject and device), the gait and force tube
    loaded for it, the human FMU file and the prosthesis drives.  A multi-contact gait
    (:data:`hp_model.gait_artifact.MULTICONTACT_KIND`) carries its model; its controller
    comes from ``tables`` (made for the run, with the robust term of the tube's model-error
    bound when a tube is given:
    :func:`orchestrator.cosim.contact_controllers.ensure_controller_file`)."""

    model: Any  # hp_model.human_prosthesis.HumanProsthesisModel
    gait: Any  # hp_model.gait_artifact.Gait, or human_fmu.build.TrackedGait (multi-contact)
    tube: Any  # hp_model.force_tube.ForceTube (None: a multi-contact run without one)
    fmu_path: Path
    drives: Drives
    gait_hash: str  # the gait's identity (the FMU's build names it)
    tables: Path | None = None  # the multi-contact controller's file

    @classmethod
    def load(cls, cfg: CosimConfig, model: Any = None,
             say: Callable[[str], None] | None = None) -> RunInputs:
        """Load ``cfg``'s artifacts (``model``: the model of ``cfg.subject`` and
        ``cfg.device`` if already built); a gait, tube or FMU made for another model or
        gait is refused here, not in the controller process or at the walker's first
        steps. The FMU is built if not cached (progress through ``say``)."""
        import hp_model
        from hp_model.force_tube import load_tube
        from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind, load_gait

        if artifact_kind(cfg.gait) == MULTICONTACT_KIND:
            return cls._multicontact(cfg, say)
        if cfg.tube is None:
            raise CosimError(f"--gait {cfg.gait}: a gait of the paper's graph runs with its "
                             "force tube; give --tube")
        model = model or hp_model.load_model(_opt(cfg.subject), _opt(cfg.device))
        gait = load_gait(cfg.gait, model.parameter_hash())
        tube = load_tube(cfg.tube, gait.hash())
        fmu_path = ensure_fmu(Path(cfg.gait), model, cfg.fmu, say)
        check_fmu_identity(fmu_path, gait.hash(), model, cfg.gait,
                           "--fmu" if cfg.fmu is not None else "the cached FMU")
        return cls(model, gait, tube, fmu_path, Drives.of(model), gait.hash())

    @classmethod
    def _multicontact(cls, cfg: CosimConfig, say: Callable[[str], None] | None
                      ) -> RunInputs:
        """A multi-contact gait's run: its model, what the FMU tracks, the FMU and the
        controller's file (both built for it once and cached), the tube when given."""
        from hp_model.force_tube import load_tube
        from orchestrator.cosim.contact_controllers import (
            ensure_controller_file,
            load_contact_run,
        )

        if cfg.subject is not None or cfg.device is not None:
            raise CosimError(f"--gait {cfg.gait}: a multi-contact gait carries its subject "
                             "and device; drop --subject/--device")
        if cfg.controller != ControllerName.CLFQP:
            raise CosimError(f"--controller {cfg.controller}: a multi-contact gait runs "
                             f"{ControllerName.CLFQP.value} (the paper's graph runs the others)")
        run = load_contact_run(cfg.gait)
        model, tracked = run.model, run.tracked
        tube = None if cfg.tube is None else load_tube(cfg.tube, run.hash)
        fmu_path = ensure_fmu(Path(cfg.gait), model, cfg.fmu, say, tracked=tracked)
        check_fmu_identity(fmu_path, tracked.hash, model, cfg.gait,
                           "--fmu" if cfg.fmu is not None else "the cached FMU")
        try:
            tables = ensure_controller_file(
                Path(cfg.gait), run, say,
                None if tube is None or cfg.tube is None
                else (Path(cfg.tube), tube.model_error))
        except ValueError as e:  # the held oracle fell: the gait does not walk
            raise CosimError(f"--gait {cfg.gait}: no controller tables: {e}") from None
        return cls(model, tracked, tube, fmu_path, Drives.of(model), tracked.hash, tables)


def _opt(path: Path | None) -> str | None:
    return None if path is None else str(path)
