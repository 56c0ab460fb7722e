"""The recording of one co-simulation run (``hpcosim run --record``, MCAP; docs/cosim.md):
:class:`RunRecord` opens it with what the run is made of (configuration, versions, hashes,
the drives, the artifacts as attachments), gives the loop its deferred ground-truth recorder
and finishes it with the run's summary, whatever happened (a full disk: no file at all)."""

from __future__ import annotations

import platform
import subprocess
from collections.abc import Callable
from pathlib import Path

from human_fmu.instance import HumanFmu
from orchestrator.cosim.config import CosimConfig
from orchestrator.cosim.controller_process import ROOT
from orchestrator.cosim.human import sha256
from orchestrator.cosim.inputs import RunInputs
from orchestrator.cosim.recording import CONTROLLER_FILE, LIBRARY_FILE, SPEED_METADATA
from orchestrator.cosim.result import CosimResult
from orchestrator.loop.foxglove import WalkerFoxglove
from orchestrator.loop.recorder import GroundTruthRecorder


def versions() -> dict[str, str]:
    """The versions of Python, the packages the run depends on and the checkout (git)."""
    import importlib.metadata as md

    out = {"python": platform.python_version()}
    for p in ("eclipse-zenoh", "python-can", "mcap", "fmpy", "numpy", "casadi", "piqp"):
        try:
            out[p] = md.version(p)
        except md.PackageNotFoundError:
            out[p] = "missing"
    try:
        import hp_model

        out["hpcosim"] = hp_model.__version__
    except Exception:  # pragma: no cover
        pass
    try:
        out["git"] = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"],
                                    capture_output=True, text=True, timeout=5).stdout.strip()
    except Exception:  # pragma: no cover
        out["git"] = "unknown"
    return out


def _make_folders(folder: Path) -> list[Path]:
    """Make ``folder`` and its missing parents; the ones made, innermost first."""
    missing = []
    f = folder
    while not f.exists() and f != f.parent:
        missing.append(f)
        f = f.parent
    folder.mkdir(parents=True, exist_ok=True)
    return missing


def _remove_folders(folders: list[Path]) -> None:
    """Remove ``folders`` (innermost first) while they are empty."""
    for f in folders:
        try:
            f.rmdir()
        except OSError:
            return


class RunRecord:
    """The MCAP recording of one run at ``cfg.record`` (module docstring); ``rec`` is its
    :class:`bus_schemas.recording.recorder.Recorder` (the link queues the CAN records on it).
    On exit the summary of ``res`` (and the signal that ended the run, if one did) is
    added and the file finished."""

    def __init__(self, cfg: CosimConfig, run_id: str, inputs: RunInputs, fmu: HumanFmu,
                 res: CosimResult) -> None:
        from bus_schemas.recording.recorder import Recorder

        assert cfg.record is not None
        #: folders made for the recording, removed again if it is abandoned (innermost first)
        self._made = _make_folders(Path(cfg.record).parent)
        try:
            self.rec = Recorder(cfg.record, metadata={"run_id": run_id}, can_rates=0.1)
        except BaseException:
            _remove_folders(self._made)
            raise
        self.inputs, self.res = inputs, res
        #: the tick loop was given the recorder (:meth:`ground_truth`): from then on the
        #: recording holds the run, whatever ends it
        self.started = False
        try:
            self.rec.register_all()
            self._describe(cfg, fmu)
            # the reference panel's desired angles and tube: the paper graph's gait (a
            # multi-contact run's tube is over the controllers' stance phase, not tau)
            paper = inputs.tables is None and inputs.tube is not None
            self._walker = WalkerFoxglove(inputs.model, inputs.gait if paper else None,
                                          inputs.tube if paper else None)
        except BaseException:
            self.close(failed=True)
            raise

    def __enter__(self) -> RunRecord:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *exc: object) -> None:
        self.close(failed=exc_type is not None)

    def _describe(self, cfg: CosimConfig, fmu: HumanFmu) -> None:
        """What the run is made of: metadata and attachments."""
        from bus_schemas.transport.protocol import DBC_PATH

        rec, inputs = self.rec, self.inputs
        rec.add_metadata("config", cfg.to_dict())
        rec.add_metadata("versions", versions())
        rec.add_metadata("hashes", {"gait_sha256": sha256(cfg.gait),
                                    "tube_sha256": sha256(cfg.tube) if cfg.tube else "",
                                    "fmu_sha256": sha256(inputs.fmu_path),
                                    "gait_hash": inputs.gait_hash,
                                    "model_hash": inputs.model.parameter_hash(),
                                    "fmu_guid": fmu.md.guid})
        ratio = inputs.drives.ratio
        rec.add_metadata("device", {"gear_ratio_knee": ratio[0],
                                    "gear_ratio_ankle": ratio[1], "dt": cfg.dt})
        rec.add_attachment("gait.json", Path(cfg.gait).read_bytes(), "application/json")
        if cfg.tube is not None:
            rec.add_attachment("tube.json", Path(cfg.tube).read_bytes(), "application/json")
        if inputs.tables is not None:  # a multi-contact gait's controller
            rec.add_attachment(CONTROLLER_FILE, inputs.tables.read_bytes(),
                               "application/octet-stream")
        if cfg.library is not None:  # the person's gait library and the speed commanded
            rec.add_attachment(LIBRARY_FILE, Path(cfg.library).read_bytes(),
                               "application/json")
            rec.add_metadata(SPEED_METADATA, {"profile": inputs.profile.text(),
                                              "start": repr(inputs.start_speed)})
        rec.add_attachment("modelDescription.xml", fmu.model_description_xml(),
                           "application/xml")
        rec.add_attachment("ampro3.dbc", Path(DBC_PATH).read_bytes(), "text/plain")

    def ground_truth(self, log_ns: Callable[[float], int]) -> GroundTruthRecorder:
        """The loop's recorder: ``/ground_truth``, ``/controller/clf`` and the walker for
        Foxglove, deferred (serialized while the plant waits for the controller), at log
        times ``log_ns(t)``."""
        self.started = True
        return GroundTruthRecorder(self.rec, log_ns=log_ns, deferred=True, walker=self._walker)

    def close(self, *, failed: bool = False) -> None:
        """Finish the file with the run's summary; a failed write (a full disk) leaves no
        partial file (the write's error names the file), and neither does a run that
        ``failed`` before its first tick (nothing recorded: an error, not a recording)."""
        rec, res = self.rec, self.res
        if rec.write_failed or (failed and not self.started):
            rec.abort()
            if not self.started:
                _remove_folders(self._made)
        elif not rec.finished:
            try:
                if res.interrupted:
                    rec.add_metadata("signal", {"signal": res.interrupted,
                                                "messages": str(rec.message_count)})
                rec.add_metadata("summary", res.to_dict())
            finally:
                rec.finish()
