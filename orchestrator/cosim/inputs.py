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
    #: a gait library's run: the library (characterization.gait.library.GaitLibrary) and
    #: the speed the person is commanded (hp_model.speed_profile.SpeedProfile)
    library: Any = None
    profile: Any = None

    @property
    def start_speed(self) -> float | None:
        """The person's first commanded speed (m/s; None: not a library's run)."""
        return None if self.profile is None else self.profile.at(0.0)

    def walk_start(self) -> tuple[dict[Any, Any], Any, Any] | None:
        """A library's run: the person's gait per domain at its first speed and its state
        there (q0, qd0: the cycle's start at that speed), what the FMU starts on; None
        otherwise."""
        if self.library is None or self.start_speed is None:
            return None
        from characterization.gait.library import start_at
        from characterization.gait.multicontact import GRAPH

        v0 = self.start_speed
        return ({d: self.library.theta_at(v0, d) for d in GRAPH.domains},
                *start_at(self.library, v0))

    def gaits(self) -> Any:
        """A library's run: the gait the person tracks entering each domain at t s
        (:func:`characterization.gait.library.speed_schedule`); None otherwise."""
        if self.library is None or self.profile is None:
            return None
        from characterization.gait.library import speed_schedule

        return speed_schedule(self.library, self.profile)

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
        if cfg.library is not None:
            raise CosimError(f"--library {cfg.library}: a gait library is walked by a "
                             f"multi-contact gait's person; --gait {cfg.gait} is of the "
                             "paper's graph")
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
        from orchestrator.cosim.contact_controllers import ensure_controller_file, load_contact_run
        from orchestrator.cosim.following import ensure_following_file

        if cfg.subject is not None or cfg.device is not None:
            raise CosimError(f"--gait {cfg.gait}: a multi-contact gait carries its subject "
                             "and device; drop --subject/--device")
        from prosthesis_controller.gait_tables import LAWS

        if cfg.controller not in LAWS:
            raise CosimError(f"--controller {cfg.controller}: a multi-contact gait runs "
                             f"{', '.join(LAWS)} (the paper's graph runs the others)")
        if cfg.library is not None and cfg.controller != ControllerName.CLFQP:
            raise CosimError(f"--controller {cfg.controller}: a gait library's run follows "
                             f"the person with {ControllerName.CLFQP.value}")
        run = load_contact_run(cfg.gait)
        model, tracked = run.model, run.tracked
        tube = None if cfg.tube is None else load_tube(cfg.tube, run.hash)
        library, profile = (None, None) if cfg.library is None else cls._library(cfg, run)
        fmu_path = ensure_fmu(Path(cfg.gait), model, cfg.fmu, say, tracked=tracked)
        check_fmu_identity(fmu_path, tracked.hash, model, cfg.gait,
                           "--fmu" if cfg.fmu is not None else "the cached FMU")
        if library is not None and cfg.library is not None:
            try:
                tables = ensure_following_file(Path(cfg.library), library, say)
            except ValueError as e:  # a held oracle fell: that speed's gait does not walk
                raise CosimError(f"--library {cfg.library}: no controller: {e}") from None
            return cls(model, tracked, None, fmu_path, Drives.of(model), tracked.hash, tables,
                       library, profile)
        try:
            tables = ensure_controller_file(
                Path(cfg.gait), run, say,
                None if tube is None or cfg.tube is None
                else (Path(cfg.tube), tube.model_error), str(cfg.controller))
        except ValueError as e:  # the held oracle fell: the gait does not walk
            raise CosimError(f"--gait {cfg.gait}: no controller tables: {e}") from None
        return cls(model, tracked, tube, fmu_path, Drives.of(model), tracked.hash, tables)

    @staticmethod
    def _library(cfg: CosimConfig, run: Any) -> tuple[Any, Any]:
        """A gait library's run (``cfg.library``): the library, of the person of ``run``
        (the gait's), and the speed commanded (within the library's speeds; default: the
        gait's own).  ``clfqp`` follows the person over it (its file made once and cached:
        :func:`orchestrator.cosim.following.ensure_following_file`)."""
        from characterization.gait.library import load_gait_library
        from hp_model.artifacts import ArtifactError
        from hp_model.speed_profile import SpeedProfile

        assert cfg.library is not None
        if cfg.tube is not None:
            raise CosimError(f"--tube {cfg.tube}: a gait library's controllers have no "
                             "model-error bound (a tube is fitted around one gait); drop --tube")
        try:
            library = load_gait_library(cfg.library)
        except (ArtifactError, OSError) as e:
            raise CosimError(f"--library {' '.join(str(e).split())}") from None
        if library.model.parameter_hash() != run.model.parameter_hash():
            raise CosimError(f"--library {cfg.library}: not of --gait {cfg.gait}'s subject and "
                             "device (its model's parameters differ)")
        sizes = {d: t.size for d, t in run.tracked.thetas.items()}
        if any(library.theta_at(library.speeds[0], d).size != n for d, n in sizes.items()):
            raise CosimError(f"--library {cfg.library}: its curves are of another degree than "
                             f"--gait {cfg.gait}'s (the FMU tracks those)")
        source = next((g.speed for g in library.gaits if g.source), library.speeds[0])
        profile = cfg.profile or SpeedProfile.constant(float(source))
        lo, hi = float(library.speeds[0]), float(library.speeds[-1])
        if min(profile.speeds) < lo - 1e-9 or max(profile.speeds) > hi + 1e-9:
            raise CosimError(f"--speed-profile {profile.text()}: outside --library "
                             f"{cfg.library}'s speeds, {lo:.2f}-{hi:.2f} m/s")
        return library, profile


def _opt(path: Path | None) -> str | None:
    return None if path is None else str(path)
