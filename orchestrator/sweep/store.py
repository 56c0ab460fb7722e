"""The results of a sweep on disk, streamed as runs finish.

Layout of ``--out DIR``::

    sweep.json               manifest: spec (validated, with DIR-relative artifact copies),
                             identity and artifact hashes, one entry per session (start,
                             end, workers, runs done, wall time, how it ended)
    artifacts/               copies of the gait, tube (and FMU, subject, device) files
    results/part-*.parquet   one parquet file per batch of finished runs, each written
                             atomically (temporary name starting with '.', then rename);
                             read together as a pyarrow dataset
    report.md, report.json, fig_*.png       hpcosim sweep report

The JSON files are written by :mod:`hp_model.json_io` (a number that is not finite is
``null``).

A row is one run (``COLUMNS``; a fall as ``fall_reason``, the
:class:`hp_model.falls.FallReason` label, with ``fail_t``, ``fail_tau``, ``fail_domain``, and
``reason``, its one-line message for humans).  A key can appear twice only when an
infrastructure error (a task lost by Dask) was retried later: readers keep the newest row of
each key (:func:`read_results`).
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from hp_model.atomic_io import atomic_write_bytes, atomic_write_with
from hp_model.json_io import write_json
from orchestrator.sweep.spec import SpecError, SweepSpec, parse_spec

MANIFEST = "sweep.json"
KIND = "hpcosim-sweep"
SCHEMA_VERSION = 1

COLUMNS = pa.schema([
    ("key", pa.string()), ("controller", pa.string()), ("family", pa.string()),
    ("draw", pa.int64()), ("run_hash", pa.string()), ("backend", pa.string()),
    ("steps_requested", pa.int64()),
    ("draw_bezier_amplitude", pa.float64()), ("draw_bezier_seed", pa.int64()),
    ("draw_tube_scale", pa.float64()), ("draw_mass_scale", pa.float64()),
    ("draw_inertia_scale", pa.float64()), ("draw_com_scale", pa.float64()),
    ("draw_knee_offset", pa.float64()), ("draw_ankle_offset", pa.float64()),
    ("draw_offset_th_lh", pa.float64()), ("draw_offset_th_lk", pa.float64()),
    ("draw_offset_th_la", pa.float64()), ("draw_offset_th_rh", pa.float64()),
    ("draw_hat_mass", pa.float64()), ("draw_thigh_mass", pa.float64()),
    ("draw_shank_mass", pa.float64()), ("draw_foot_mass", pa.float64()),
    ("draw_hat_com", pa.float64()), ("draw_iwalk_mass", pa.float64()),
    ("draw_prosthesis_mass", pa.float64()), ("draw_prosthesis_inertia", pa.float64()),
    ("draw_prosthesis_com", pa.float64()), ("draw_human_stiffness", pa.float64()),
    ("draw_human_delay", pa.float64()), ("draw_angle_noise", pa.float64()),
    ("draw_velocity_noise", pa.float64()), ("draw_angle_resolution", pa.float64()),
    ("draw_velocity_resolution", pa.float64()), ("draw_sensor_seed", pa.int64()),
    ("draw_imu_bias", pa.float64()), ("draw_imu_noise", pa.float64()),
    ("draw_stride_cv", pa.float64()), ("draw_stride_seed", pa.int64()),
    ("draw_armature", pa.float64()), ("draw_speed_start", pa.float64()),
    ("draw_speed_end", pa.float64()),
    ("steps_completed", pa.int64()), ("success", pa.bool_()), ("failed", pa.bool_()),
    ("reason", pa.string()), ("fall_reason", pa.string()), ("fail_t", pa.float64()),
    ("fail_tau", pa.float64()),
    ("fail_domain", pa.string()), ("duration_s", pa.float64()),
    ("knee_rms_ps_rad", pa.float64()), ("knee_rms_all_rad", pa.float64()),
    ("fallback_count", pa.int64()), ("fallback_ticks", pa.int64()),
    ("fault_ticks", pa.int64()), ("max_torque_knee", pa.float64()),
    ("max_torque_ankle", pa.float64()), ("torque_finite", pa.bool_()),
    ("socket_force_in_tube", pa.float64()),
    ("error", pa.string()), ("error_kind", pa.string()),
    ("wall_s", pa.float64()), ("worker", pa.string()), ("setup", pa.string()),
    ("session", pa.string()),
    ("seq", pa.int64()),
])
#: columns that depend on where and when a run ran, not on what it computed
VOLATILE = ("wall_s", "worker", "setup", "session", "seq")
ARTIFACT_NAMES = {"gait": "gait.json", "tube": "tube.json", "fmu": "human.fmu",
                  "subject": "subject.toml", "device": "device.toml",
                  "library": "library.json"}


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


@dataclass
class ResultStore:
    """A sweep output folder (module docstring)."""

    root: Path

    @property
    def results(self) -> Path:
        return self.root / "results"

    @property
    def manifest_path(self) -> Path:
        return self.root / MANIFEST

    # -- manifest ---------------------------------------------------------------------------
    def manifest(self) -> dict[str, Any] | None:
        if not self.manifest_path.is_file():
            return None
        doc = json.loads(self.manifest_path.read_text())
        if doc.get("kind") != KIND or doc.get("schema_version") != SCHEMA_VERSION:
            raise SpecError(f"{self.manifest_path}: not an hpcosim sweep manifest (v1)")
        return doc

    def write_manifest(self, doc: dict[str, Any]) -> None:
        write_json(self.manifest_path, doc)

    def check(self, spec: SweepSpec, hashes: dict[str, str | None], artifacts_digest: str
              ) -> dict[str, Any] | None:
        """Whether the folder (if any) holds a sweep ``spec`` may resume: same identity
        (seed, steps, backend), same artifacts, and every family present in both defined
        alike (added controllers, families and draws are fine).  Raises :class:`SpecError`;
        returns the existing manifest (None for a new folder).  Writes nothing."""
        fams = {f: spec.family_hash(f) for f in spec.families}
        old = self.manifest()
        if old is not None:
            if old["identity"] != spec.identity():
                raise SpecError(f"{self.root} holds a sweep with other settings "
                                f"({old['identity']} vs {spec.identity()}); use another --out")
            if old["artifacts_digest"] != artifacts_digest:
                diff = [k for k, v in hashes.items() if old["artifact_hashes"].get(k) != v]
                raise SpecError(f"{self.root} holds a sweep of other files ({', '.join(diff)}"
                                " differ); use another --out")
            for f, h in fams.items():
                if f in old["family_hashes"] and old["family_hashes"][f] != h:
                    raise SpecError(f"{self.root}: family '{f}' is defined differently from "
                                    "the sweep there; rename it or use another --out")
        return old

    def open(self, spec: SweepSpec, hashes: dict[str, str | None], artifacts_digest: str,
             files: dict[str, bytes | None]) -> dict[str, Any]:
        """Create the folder for ``spec`` or reopen a compatible one (:meth:`check`), copy
        the artifacts, and return the manifest with the spec updated to this one."""
        old = self.check(spec, hashes, artifacts_digest)
        self.root.mkdir(parents=True, exist_ok=True)
        self.results.mkdir(exist_ok=True)
        fams = {**(old or {}).get("family_hashes", {}),
                **{f: spec.family_hash(f) for f in spec.families}}
        adir = self.root / "artifacts"
        adir.mkdir(exist_ok=True)
        local: dict[str, str] = {}
        for name, data in files.items():
            if data is None:
                continue
            p = adir / ARTIFACT_NAMES[name]
            if not p.is_file() or p.read_bytes() != data:
                atomic_write_bytes(p, data)
            local[name] = str(p.relative_to(self.root))
        sdoc = spec.model_dump(mode="json")
        sdoc.update({k: None for k in ARTIFACT_NAMES})
        sdoc.update(local)
        doc = {"kind": KIND, "schema_version": SCHEMA_VERSION, "spec": sdoc,
               "identity": spec.identity(), "artifacts_digest": artifacts_digest,
               "artifact_hashes": hashes, "family_hashes": fams,
               "sessions": (old or {}).get("sessions", [])}
        self.write_manifest(doc)
        return doc

    def spec(self) -> SweepSpec:
        """The spec of the latest session, with artifact paths into ``artifacts/``."""
        doc = self.manifest()
        if doc is None:
            raise FileNotFoundError(f"{self.root}: no sweep here ({MANIFEST} missing)")
        return parse_spec(dict(doc["spec"]), self.manifest_path)

    # -- results ----------------------------------------------------------------------------
    def write_part(self, rows: list[dict[str, Any]], session: str, seq: int) -> Path | None:
        """One batch of rows as ``results/part-<session>-<seq>.parquet`` (atomic)."""
        if not rows:
            return None
        table = pa.Table.from_pylist([{c: r.get(c) for c in COLUMNS.names} for r in rows],
                                     schema=COLUMNS)
        path = self.results / f"part-{session}-{seq:06d}.parquet"
        atomic_write_with(path, lambda tmp: pq.write_table(table, tmp), suffix=".parquet")
        return path

    def table(self) -> pa.Table:
        """Every stored row (all parts), possibly with superseded rows."""
        files = sorted(p for p in self.results.glob("part-*.parquet")) \
            if self.results.is_dir() else []
        if not files:
            return COLUMNS.empty_table()
        return ds.dataset([str(p) for p in files], schema=COLUMNS, format="parquet").to_table()

    def remove(self) -> None:  # pragma: no cover - used by callers that start over
        shutil.rmtree(self.root)


def read_results(root: str | os.PathLike[str]) -> pa.Table:
    """The results of a sweep folder: the newest row of each key (by session start, then
    batch and position), sorted by key."""
    t = ResultStore(Path(root)).table()
    if t.num_rows == 0:
        return t
    order = sorted(range(t.num_rows), key=lambda i: (t["session"][i].as_py(),
                                                     t["seq"][i].as_py()))
    keys = t["key"].to_pylist()
    newest: dict[str, int] = {}
    for i in order:
        newest[keys[i]] = i
    idx = sorted(newest.values(), key=lambda i: keys[i])
    return t.take(idx)


def done_keys(root: str | os.PathLike[str]) -> set[str]:
    """Keys with a result to keep: every row except infrastructure errors (retried)."""
    t = read_results(root)
    kind = t["error_kind"].to_pylist()
    return {k for k, e in zip(t["key"].to_pylist(), kind, strict=True)
            if e != "infrastructure"}


def new_session_id() -> str:
    """Sortable session id: UTC start time and the process id."""
    return time.strftime("%Y%m%dT%H%M%S", time.gmtime()) + f"-{os.getpid()}"


def session_entry(session: str, **kw: Any) -> dict[str, Any]:
    return {"session": session, "started": _now(), **kw}
