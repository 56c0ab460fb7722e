"""One sweep run, and what a worker builds once to run many.

:class:`Artifacts` carries the contents of the gait, tube (and FMU, subject, device) files,
so a worker needs no shared filesystem; :class:`Resources` is what a worker builds from them
once (model functions, closed loop, controller contexts, FMU instance) and
:func:`run_draw` is the run itself: a pure function of (artifacts, spec identity,
controller, draw) returning one results row (``orchestrator.sweep.store.COLUMNS``).  An
exception inside a run is caught and returned as the row's ``error``.

On Dask the resources are built by :class:`SweepSetup`, a worker plugin (once per worker
process, again on a worker that replaces a lost one); :func:`run_task` is the task.
"""

from __future__ import annotations

import hashlib
import math
import os
import socket
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from hp_model.artifacts import canonical_hash
from hp_model.compiled import CompileBackend
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.force_tube import ForceTube
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import BodyVariation, HumanProsthesisModel
from hp_model.json_io import finite_or_none
from orchestrator.experiments.scenarios import (
    ORACLE,
    Perturbation,
    PlantSetup,
    Scenario,
    ScenarioResult,
    initial_state,
    run_scenario,
    summary,
)
from orchestrator.loop import Encoder
from orchestrator.modes import SweepBackend
from orchestrator.sweep.contact import ContactResources, run_contact_draw
from orchestrator.sweep.draws import HUMAN_JOINTS, Draw, RunKey
from orchestrator.sweep.spec import SweepSpec
from orchestrator.sweep.tempdirs import WorkFolder
from prosthesis_controller.interface import ControllerMode

#: contexts (controller model x tube) kept per worker; a continuous tube_scale misses
CONTEXT_CACHE = 16
#: plants (model + compiled closed loop) kept per worker: the runs of a draw come together
PLANT_CACHE = 4


@dataclass(frozen=True)
class Artifacts:
    """File contents a run depends on (bytes; None = default or unused)."""

    gait: bytes
    tube: bytes | None
    fmu: bytes | None = None
    subject: bytes | None = None
    device: bytes | None = None
    library: bytes | None = None

    @classmethod
    def from_spec(cls, spec: SweepSpec, fmu: Path | None = None) -> Artifacts:
        """The spec's files (``fmu``: the FMU to use for the fmu backend)."""

        def read(p: Path | None) -> bytes | None:
            return Path(p).read_bytes() if p is not None else None

        return cls(spec.gait.read_bytes(), read(spec.tube),
                   read(fmu or spec.fmu) if spec.backend == SweepBackend.FMU else None,
                   read(spec.subject), read(spec.device), read(spec.library))

    def hashes(self) -> dict[str, str | None]:
        """sha256 of each file (None if absent; the library named only when given, so an
        older sweep's digest stands)."""
        out = {k: (hashlib.sha256(v).hexdigest() if v is not None else None)
               for k, v in (("gait", self.gait), ("tube", self.tube), ("fmu", self.fmu),
                            ("subject", self.subject), ("device", self.device))}
        if self.library is not None:
            out["library"] = hashlib.sha256(self.library).hexdigest()
        return out

    def digest(self) -> str:
        return canonical_hash(self.hashes())


def run_hash(spec: SweepSpec, artifacts_digest: str, key: RunKey) -> str:
    """Identity of one run: everything its result depends on."""
    return canonical_hash({"identity": spec.identity(), "artifacts": artifacts_digest,
                           "family": spec.family_hash(key.family),
                           "controller": key.controller, "draw": key.draw})


# ------------------------------------------------------------------ the draw, applied

def human_thetas(gait: Gait, draw: Draw) -> dict[Domain, np.ndarray]:
    """The packed gait parameters the human tracks in this draw: the Bezier perturbation of
    ``human_fmu.perturbation`` (amplitude, seed), then each human output's constant offset
    added to every coefficient of its row (a Bezier curve moves by a constant when all its
    coefficients do), in every domain where the joint is an output."""
    th = Perturbation("sweep", draw.bezier_amplitude, draw.bezier_seed).thetas(gait)
    L = gait.params[Domain.PS].layout
    for joint, off in zip(HUMAN_JOINTS, draw.output_offset, strict=True):
        if off == 0.0:
            continue
        for d in PAPER_DOMAINS:
            if joint in d.y2_coords:
                th[d][L.row(d.y2_row(joint))] += off
    return th


@dataclass(frozen=True)
class DrawPerturbation(Perturbation):
    """A :class:`~orchestrator.experiments.scenarios.Perturbation` carrying a whole draw's
    human side (so :func:`run_scenario` tracks the draw's thetas)."""

    draw: Draw = field(default_factory=lambda: Draw("nominal", 0))

    def thetas(self, gait: Gait) -> dict[Domain, np.ndarray]:
        return human_thetas(gait, self.draw)


def scaled_tube(tube: ForceTube, scale: float) -> ForceTube:
    """The tube the controller is given when the socket-force deviations exceed ``tube`` by
    ``scale``: deviation bounds divided by it (about the nominal F*).  A model-error bound
    (tube schema 2) is kept as it is: it bounds the model's error, not the socket force."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"tube_scale must be finite and > 0, got {scale}")
    if scale == 1.0:
        return tube
    return replace(tube, lower=tube.lower / scale, upper=tube.upper / scale)


def erroneous_model(model: HumanProsthesisModel, mass: float, inertia: float, com: float,
                    body: BodyVariation | None = None,
                    backend: CompileBackend = CompileBackend.AUTO
                    ) -> HumanProsthesisModel:
    """The model with the prosthesis links' (top, shin, foot) masses, inertias and COM
    positions scaled (re-validated: a non-positive mass fails), and the human ``body`` (the
    model's own when None): the model the controller believes in (``model.*``), or the
    plant the sweep simulates (``plant.*``); ``backend``: of its numeric functions."""
    from hp_model.config import DeviceConfig

    body = model.body if body is None else body
    if (mass, inertia, com) == (1.0, 1.0, 1.0):
        return model if body == model.body else \
            HumanProsthesisModel(model.subject, model.device, body, backend)
    doc = model.device.model_dump(mode="json")
    p = doc["prosthesis"]
    for link in ("top", "shin", "foot"):
        p[link]["mass"]["value"] *= mass
        p[link]["inertia"]["value"] *= inertia
        for c in ("com", "com_x", "com_z"):
            if c in p[link]:
                p[link][c]["value"] *= com
    return HumanProsthesisModel(model.subject, DeviceConfig.model_validate(doc), body,
                                backend)


def human_gains(gait: Gait, draw: Draw) -> np.ndarray:
    """The human's (eps, kp, kd) in a draw: the bandwidth scaled by ``human_stiffness`` s,
    (s eps, s^2 kp, s kd) (same damping ratio)."""
    s = draw.human_stiffness
    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"human stiffness must be finite and > 0, got {s}")
    return gait.gains_array * np.array([s, s * s, s])


def encoder_of(draw: Draw) -> Encoder:
    """What the prosthesis's encoders do to its measurements in a draw."""
    return Encoder(*draw.encoder, seed=draw.sensor_seed)


# ------------------------------------------------------------------ per-worker resources

class Resources:
    """Everything a worker builds once from :class:`Artifacts` (files written to
    ``workdir``): model, gait, tube, compiled closed loop, the nominal controller context,
    a small cache of perturbed contexts, and the FMU instance for the fmu backend."""

    def __init__(self, artifacts: Artifacts, workdir: Path | None = None) -> None:
        import hp_model
        from hp_model.closed_loop import ClosedLoop
        from hp_model.force_tube import load_tube
        from hp_model.gait_artifact import load_gait
        from prosthesis_controller import ControllerContext

        self.digest = artifacts.digest()
        #: identifies this set-up (host, process, time): one per worker, not per run
        self.setup_id = f"{socket.gethostname()}:{os.getpid()}:{time.time_ns()}"
        #: this worker's private folder; a killed worker's is removed by the next one
        self._folder = WorkFolder(self.digest[:12], workdir)
        self.workdir = self._folder.path
        gait_path = self._put("gait.json", artifacts.gait)
        tube_path = None if artifacts.tube is None else self._put("tube.json", artifacts.tube)
        fmu_path, subject_path, device_path = (
            None if data is None else self._put(name, data)
            for name, data in (("fmu.fmu", artifacts.fmu), ("subject.toml", artifacts.subject),
                               ("device.toml", artifacts.device)))
        self.model = hp_model.load_model(subject_path, device_path)
        self.gait = load_gait(gait_path, self.model.parameter_hash())
        if tube_path is None:
            raise ValueError("a sweep of the paper's graph needs its tube")
        self.tube = load_tube(tube_path, self.gait.hash())
        self.closed_loop = ClosedLoop(self.model, self.gait.degree)
        self.closed_loop.numeric()
        self.model.numeric()
        self._ctx_cls = ControllerContext
        self.context0 = ControllerContext(self.gait, self.tube, self.model)
        self._contexts: OrderedDict[tuple[float, ...], Any] = OrderedDict()
        self._models: dict[tuple[float, ...], HumanProsthesisModel] = {}
        self._plants: OrderedDict[tuple[Any, ...], tuple[HumanProsthesisModel, Any]] = \
            OrderedDict()
        self.fmu = None
        if fmu_path is not None:
            from orchestrator.sweep.fmu import open_fmu

            self.fmu = open_fmu(Path(fmu_path), self.workdir, self.gait)

    def _put(self, name: str, data: bytes) -> str:
        """Write an artifact into the work folder as ``name``; its path."""
        p = self.workdir / name
        p.write_bytes(data)
        return str(p)

    def context(self, draw: Draw) -> Any:
        """The controller context of a draw: its model errors and its tube scale."""
        key = (draw.tube_scale, draw.mass_scale, draw.inertia_scale, draw.com_scale)
        if key == (1.0, 1.0, 1.0, 1.0):
            return self.context0
        if key in self._contexts:
            self._contexts.move_to_end(key)
            return self._contexts[key]
        mk = key[1:]
        if mk not in self._models:
            self._models[mk] = erroneous_model(self.model, *mk)
        ctx = self._ctx_cls(self.gait, scaled_tube(self.tube, draw.tube_scale),
                            self._models[mk])
        self._contexts[key] = ctx
        if len(self._contexts) > CONTEXT_CACHE:
            self._contexts.popitem(last=False)
        return ctx

    def plant(self, draw: Draw) -> tuple[HumanProsthesisModel, Any]:
        """The simulated walker of a draw and its compiled closed loop (the nominal ones
        unless the draw has ``plant.*`` quantities; compiled once per worker, the library
        cached on disk by its source)."""
        from hp_model.closed_loop import ClosedLoop

        key = (draw.body, draw.plant_prosthesis)
        if key == (self.model.body, (1.0, 1.0, 1.0)):
            return self.model, self.closed_loop
        if key in self._plants:
            self._plants.move_to_end(key)
            return self._plants[key]
        # the model's own functions run a few times per step (impacts, start): interpreted;
        # the closed loop runs every step: compiled
        m = erroneous_model(self.model, *draw.plant_prosthesis, body=draw.body,
                            backend=CompileBackend.SX)
        cl = ClosedLoop(m, self.gait.degree)
        cl.numeric()
        self._plants[key] = (m, cl)
        if len(self._plants) > PLANT_CACHE:
            self._plants.popitem(last=False)
        return m, cl

    def close(self) -> None:
        """Free the FMU instance and remove the files written for this set-up."""
        try:
            if self.fmu is not None:
                self.fmu.free()
        finally:
            self._folder.close()


# ------------------------------------------------------------------ the run

def result_columns(r: ScenarioResult) -> dict[str, Any]:
    """The measured columns of one run (from :func:`orchestrator.experiments.scenarios.summary`)."""
    s = summary(r)
    tq = np.asarray(r.torque, float).reshape(-1, 2)
    finite = bool(np.all(np.isfinite(tq)))
    peak = np.abs(tq).max(axis=0) if tq.size else np.zeros(2)
    return {"steps_completed": int(s["steps_completed"]), "success": bool(s["success"]),
            "failed": bool(s["failed"]), "reason": str(s["reason"]),
            "fall_reason": s["fall_reason"],
            "fail_t": finite_or_none(s["fail_t"]), "fail_tau": finite_or_none(s["fail_tau"]),
            "fail_domain": s["fail_domain"], "duration_s": float(s["duration_s"]),
            "knee_rms_ps_rad": finite_or_none(s["knee_rms_ps_rad"]),
            "knee_rms_all_rad": finite_or_none(s["knee_rms_all_rad"]),
            "fallback_count": int(s["fallback_count"]),
            "fallback_ticks": int(s["modes"].get(ControllerMode.FALLBACK, 0)),
            "fault_ticks": int(s["modes"].get(ControllerMode.FAULT, 0)),
            "max_torque_knee": finite_or_none(peak[0]) if finite else None,
            "max_torque_ankle": finite_or_none(peak[1]) if finite else None,
            "torque_finite": finite,
            "socket_force_in_tube": finite_or_none(r.fs_in_tube) if r.fs_in_tube is not None
            else None}


EMPTY_RESULT: dict[str, Any] = {
    "steps_completed": None, "success": False, "failed": None, "reason": None,
    "fall_reason": None,
    "fail_t": None, "fail_tau": None, "fail_domain": None, "duration_s": None,
    "knee_rms_ps_rad": None, "knee_rms_all_rad": None, "fallback_count": None,
    "fallback_ticks": None, "fault_ticks": None, "max_torque_knee": None,
    "max_torque_ankle": None, "torque_finite": None, "socket_force_in_tube": None}


def base_row(spec: SweepSpec, artifacts_digest: str, key: RunKey, draw: Draw | None
             ) -> dict[str, Any]:
    """The identifying columns of a run's row."""
    row: dict[str, Any] = {"key": key.text, "controller": key.controller,
                           "family": key.family, "draw": key.draw,
                           "run_hash": run_hash(spec, artifacts_digest, key),
                           "backend": spec.backend, "steps_requested": spec.steps}
    row.update((draw or Draw(key.family, key.draw)).columns())
    return row


def make_resources(artifacts: Artifacts, workdir: Path | None = None
                   ) -> Resources | ContactResources:
    """A worker's resources for the sweep's gait: the paper's graph (:class:`Resources`) or
    a multi-contact gait (:class:`orchestrator.sweep.contact.ContactResources`)."""
    import json

    from hp_model.gait_artifact import MULTICONTACT_KIND

    try:
        kind = json.loads(artifacts.gait).get("kind")
    except (ValueError, AttributeError):
        kind = None
    if kind == MULTICONTACT_KIND:
        return ContactResources(artifacts, workdir)
    return Resources(artifacts, workdir)


def run_draw(res: Resources | ContactResources, spec: SweepSpec, key: RunKey, draw: Draw
             ) -> dict[str, Any]:
    """One run (module docstring): never raises for an error of the run itself."""
    if isinstance(res, ContactResources):
        return run_contact_draw(res, spec, key, draw)

    def measure() -> dict[str, Any]:
        ctx = res.context(draw)
        scenario = Scenario(key.controller, DrawPerturbation(
            f"{key.family}/{key.draw}", draw.bezier_amplitude, draw.bezier_seed, draw),
            spec.steps, (draw.knee_offset, draw.ankle_offset))
        if spec.backend == SweepBackend.SIMULATOR or key.controller == ORACLE:
            model, cl = res.plant(draw)
            setup = PlantSetup(human_gains=human_gains(res.gait, draw),
                               human_delay=draw.human_delay, encoder=encoder_of(draw))
            r = run_scenario(model, res.gait, ctx.tube, scenario, context=ctx,
                             closed_loop=cl, plant=setup)
        else:
            from orchestrator.sweep.fmu import run_fmu_scenario

            if res.fmu is None:
                raise ValueError("backend fmu but no FMU was given to the worker")
            q0, qd0 = initial_state(res.model, res.gait, scenario.initial_offset)
            r = run_fmu_scenario(res.fmu, res.model, res.gait, ctx, scenario, (q0, qd0),
                                 encoder=encoder_of(draw))
        return result_columns(r)

    return measured_row(spec, res.digest, res.setup_id, key, draw, measure)


def measured_row(spec: SweepSpec, digest: str, setup_id: str, key: RunKey, draw: Draw,
                 measure: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    """A run's row: its identity, ``measure()``'s columns (an exception in it is the row's
    ``error``: a run's own failure is a result, not a crash of the sweep), where and how
    long it ran."""
    t0 = time.perf_counter()
    row = base_row(spec, digest, key, draw)
    try:
        row.update(measure())
        row.update(error=None, error_kind=None)
    except Exception as e:
        row.update(EMPTY_RESULT)
        row.update(error=f"{type(e).__name__}: {e}", error_kind="run")
    row.update(wall_s=time.perf_counter() - t0, worker=f"{socket.gethostname()}:{os.getpid()}",
               setup=setup_id)
    return row


# ------------------------------------------------------------------ Dask glue

def plugin_name(artifacts_digest: str) -> str:
    return f"hpcosim-sweep-{artifacts_digest[:16]}"


try:  # distributed is a dependency; keep this module importable for replay without it
    from distributed.diagnostics.plugin import WorkerPlugin
except ImportError:  # pragma: no cover
    WorkerPlugin = object  # type: ignore[assignment,misc]  # a plain base stands in for it


class SweepSetup(WorkerPlugin):
    """Dask worker plugin: builds the :class:`Resources` once when a worker starts (or
    joins later, e.g. replacing a killed one)."""

    def __init__(self, artifacts: Artifacts) -> None:
        self.artifacts = artifacts
        self.name = plugin_name(artifacts.digest())
        self.resources: Resources | ContactResources | None = None

    def setup(self, worker: Any) -> None:
        self.resources = make_resources(self.artifacts, Path(worker.local_directory))

    def teardown(self, worker: Any) -> None:
        if self.resources is not None:
            self.resources.close()


def run_task(name: str, spec: SweepSpec, key: RunKey, draw: Draw) -> dict[str, Any]:
    """The Dask task: one run on this worker's resources."""
    from distributed import get_worker

    plugin = get_worker().plugins[name]
    if not isinstance(plugin, SweepSetup) or plugin.resources is None:  # pragma: no cover
        raise RuntimeError("worker resources not set up")  # setup runs before any task
    return run_draw(plugin.resources, spec, key, draw)
