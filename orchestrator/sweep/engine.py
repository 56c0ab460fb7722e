"""Run a sweep on Dask distributed and stream its results to disk.

- Cluster: a ``LocalCluster`` on this machine (``workers`` processes, default the number of
  cores, 1 thread each, loopback only, no dashboard), or the existing scheduler at
  ``scheduler`` (its workers must be able to import hpcosim; they need no shared files: the
  artifacts travel in the worker plugin).
- Setup once per worker: :class:`orchestrator.sweep.runs.SweepSetup` (registered with the
  client; Dask runs it on every current worker and on any worker that joins later).
- Runs are submitted as futures (at most ``window`` in flight, topped up as they finish) and
  consumed with ``as_completed``; rows are buffered and written as one parquet part per
  ``spec.batch`` rows (or every ``flush_s`` seconds), and whatever is buffered is written
  when the sweep ends, fails or is interrupted.
- Resume: runs whose key already has a result in ``out`` are not submitted.
- A run's own exception is a row with its error (:func:`orchestrator.sweep.runs.run_draw`);
  a task Dask loses (e.g. its worker died more often than Dask's allowed-failures) is a row
  with ``error_kind = "infrastructure"``, retried by the next resume.  A worker killed
  mid-sweep is replaced by its nanny and its runs are recomputed elsewhere.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from orchestrator.modes import SweepBackend
from orchestrator.sweep.draws import RunKey, make_draw, run_keys
from orchestrator.sweep.runs import Artifacts, SweepSetup, base_row, run_task
from orchestrator.sweep.spec import SweepSpec
from orchestrator.sweep.store import (
    ResultStore,
    done_keys,
    new_session_id,
    session_entry,
)

#: (done, total, errors, runs per minute) after every finished run
Progress = Callable[[int, int, int, float], None]


@dataclass
class SweepOutcome:
    """What one session of a sweep did."""

    out: Path
    session: str
    total: int  # runs in the spec
    skipped: int  # already in the results (resume)
    done: int  # finished in this session
    errors: int  # rows with an error in this session
    workers: int
    wall_s: float  # from the first submission to the last result
    setup_s: float  # cluster start + worker setup
    status: str  # completed / interrupted / failed

    @property
    def runs_per_min(self) -> float:
        return 60.0 * self.done / self.wall_s if self.wall_s > 0 else 0.0


class SweepError(RuntimeError):
    """A sweep that cannot start (one line), e.g. an unreachable scheduler."""


#: the Dask protocols a scheduler on another process or machine is reached by
SCHEDULER_SCHEMES = ("tcp", "tls", "ws", "wss")
_SECURE = ("tls", "wss")


def check_scheduler(address: str) -> str:
    """``address`` if it is one of a Dask scheduler (``[tcp|tls|ws|wss://]HOST:PORT``, port
    1-65535; ``tls``/``wss`` with Dask's TLS configuration), else SweepError naming
    ``--scheduler``: before any work, and without Dask's own tracebacks."""
    def bad(why: str) -> SweepError:
        return SweepError(f"--scheduler {address!r}: {why}")

    scheme, sep, rest = address.strip().rpartition("://")
    scheme = scheme if sep else "tcp"
    if scheme not in SCHEDULER_SCHEMES:
        raise bad(f"protocol {scheme!r}; expected one of {', '.join(SCHEDULER_SCHEMES)}")
    host, colon, port = rest.rpartition(":")
    if not colon or not host.strip("[]") or not port.isdigit() or not 0 < int(port) < 65536:
        raise bad("expected [PROTOCOL://]HOST:PORT with a port 1-65535, e.g. "
                  "tcp://127.0.0.1:8786")
    if scheme in _SECURE:
        from distributed.security import Security

        if Security().get_connection_args("client").get("ssl_context") is None:
            raise bad(f"{scheme} needs Dask's TLS configuration (distributed.comm.tls: "
                      "ca-file and the client's cert and key)")
    return address.strip()


@contextlib.contextmanager
def dask_client(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """A client of ``scheduler`` (checked: :func:`check_scheduler`), or of a new
    LocalCluster of ``workers`` processes."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(check_scheduler(scheduler), timeout=10)
        except SweepError:
            raise
        except Exception as e:  # Dask's error for a user's address, of any kind
            raise SweepError(f"--scheduler {scheduler}: cannot reach the Dask scheduler: "
                             f"{str(e).splitlines()[0] if str(e) else type(e).__name__}"
                             ) from None
        try:
            yield client
        finally:
            client.close()
        return
    n = workers or os.cpu_count() or 1
    # loopback only; no dashboard, and its HTTP routes on a free port (not 8787)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None,
                           scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                           silence_logs=logging.ERROR, worker_dashboard_address=None)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def prepare_fmu(spec: SweepSpec) -> Path | None:
    """The FMU of an fmu-backend sweep: the spec's, or one built and cached for the gait."""
    if spec.backend != SweepBackend.FMU:
        return None
    import hp_model
    from orchestrator.cosim.human import ensure_fmu

    model = hp_model.load_model(str(spec.subject) if spec.subject else None,
                                str(spec.device) if spec.device else None)
    if spec.fmu is None:
        return ensure_fmu(spec.gait, model)
    from hp_model.gait_artifact import load_gait
    from orchestrator.cosim.config import CosimError
    from orchestrator.cosim.inputs import check_fmu_identity

    try:  # an FMU built for another gait or model: refused before the cluster starts
        check_fmu_identity(spec.fmu, load_gait(spec.gait, model.parameter_hash()).hash(), model,
                           spec.gait, "the spec's fmu")
    except CosimError as e:
        raise SweepError(str(e)) from None
    return spec.fmu


@dataclass
class _Parts:
    """Buffers result rows and writes them as parquet parts (``batch`` rows or every
    ``flush_s`` seconds); numbers rows in the order they were consumed."""

    store: ResultStore
    session: str
    batch: int
    flush_s: float
    rows: list[dict[str, Any]] = field(default_factory=list)
    part: int = 0
    seq: int = 0
    last: float = field(default_factory=time.perf_counter)
    written: int = 0  # rows on disk: what a session reports as done, whenever it stopped
    errors: int = 0  # of those, rows with an error

    def add(self, row: dict[str, Any]) -> None:
        row.update(session=self.session, seq=self.seq)
        self.seq += 1
        self.rows.append(row)
        if len(self.rows) >= self.batch or time.perf_counter() - self.last >= self.flush_s:
            self.flush()

    def flush(self) -> None:
        if self.rows:
            self.store.write_part(self.rows, self.session, self.part)
            self.part += 1
            self.written += len(self.rows)
            self.errors += sum(r.get("error") is not None for r in self.rows)
            self.rows = []
        self.last = time.perf_counter()


@dataclass(frozen=True)
class Streaming:
    """How runs flow through a session: at most ``window`` in flight (None: 8 per worker,
    at least 32), buffered result rows written at least every ``flush_s`` seconds."""

    window: int | None = None
    flush_s: float = 10.0


@dataclass(frozen=True)
class _Session:
    """One session of a sweep on a Dask client: the worker plugin's name, the spec and its
    artifacts' digest, the session id, where its rows go and what it reports."""

    client: Any
    plugin: str
    spec: SweepSpec
    digest: str
    session: str
    parts: _Parts
    outcome: SweepOutcome


def _consume(ses: _Session, todo: list[RunKey], window: int,
             on_result: Callable[[dict[str, Any]], None] | None,
             progress: Progress | None, stop: threading.Event | None = None) -> None:
    """Submit ``todo`` (at most ``window`` in flight) and store each result as it comes;
    ``stop`` set (Ctrl-C) ends it with KeyboardInterrupt after the result in hand is
    stored."""
    from distributed import as_completed

    spec, digest, parts, outcome = ses.spec, ses.digest, ses.parts, ses.outcome
    pending = iter(todo)
    by_future: dict[Any, RunKey] = {}

    def submit(k: RunKey) -> Any:
        fut = ses.client.submit(run_task, ses.plugin, spec, k,
                                make_draw(spec, k.family, k.draw),
                                key=f"hpcosim-run-{digest[:8]}-{ses.session}-{k.text}",
                                pure=False)
        by_future[fut] = k
        return fut

    first = [submit(k) for k in itertools.islice(pending, window)]
    t0 = time.perf_counter()
    ac = as_completed(first, with_results=True, raise_errors=False)
    for fut, result in ac:
        k = by_future.pop(fut)
        if fut.status != "finished" or not isinstance(result, dict):
            exc = result[1] if isinstance(result, tuple) and len(result) == 3 else result
            row = base_row(spec, digest, k, make_draw(spec, k.family, k.draw))
            row.update(error=f"{type(exc).__name__}: {exc}", error_kind="infrastructure",
                       success=False)
        else:
            row = result
        nxt = next(pending, None)
        if nxt is not None:
            ac.add(submit(nxt))
        parts.add(row)
        outcome.done += 1
        outcome.errors += row.get("error") is not None
        outcome.wall_s = time.perf_counter() - t0
        if on_result is not None:
            on_result(row)
        if progress is not None:
            progress(outcome.done, len(todo), outcome.errors, outcome.runs_per_min)
        if stop is not None and stop.is_set():
            raise KeyboardInterrupt
    if stop is not None and stop.is_set():
        raise KeyboardInterrupt


@contextlib.contextmanager
def _interrupt_flag(stop: threading.Event) -> Iterator[None]:
    """While running: SIGINT sets ``stop`` instead of raising wherever the main thread is
    (inside a Dask call a KeyboardInterrupt can cancel the runs in flight, which then
    count as errors, and the sweep goes on); outside the main thread, nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, lambda _s, _f: stop.set())
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def run_sweep(spec: SweepSpec, out: Path, *, scheduler: str | None = None,
              workers: int | None = None, progress: Progress | None = None,
              on_result: Callable[[dict[str, Any]], None] | None = None,
              say: Callable[[str], None] | None = None,
              streaming: Streaming = Streaming()) -> SweepOutcome:
    """Run (or resume) ``spec`` into ``out`` (module docstring).  Nothing is written
    before the cluster is up (a spec that does not fit ``out``, an unreachable scheduler or
    an interrupt during start-up leave ``out`` as it was).  ``streaming``: runs in flight
    and how often rows are written (:class:`Streaming`)."""
    say = say or (lambda _m: None)
    if scheduler is not None:
        check_scheduler(scheduler)  # a bad address: before any work
    t_setup = time.perf_counter()
    art = Artifacts.from_spec(spec, prepare_fmu(spec))
    digest = art.digest()
    store = ResultStore(Path(out))
    files = {"gait": art.gait, "tube": art.tube, "fmu": art.fmu, "subject": art.subject,
             "device": art.device, "library": art.library}
    store.check(spec, art.hashes(), digest)
    keys = list(run_keys(spec))
    have = done_keys(out)
    todo = [k for k in keys if k.text not in have]
    session = new_session_id()
    outcome = SweepOutcome(Path(out), session, len(keys), len(keys) - len(todo), 0, 0, 0, 0.0,
                           0.0, "failed")
    if not todo:
        outcome.status = "completed"
        return outcome
    with dask_client(scheduler, workers) as client:
        say("setting up workers (model functions, controllers)")
        plugin = SweepSetup(art)
        client.register_plugin(plugin)
        outcome.workers = len(client.scheduler_info()["workers"])
        outcome.setup_s = time.perf_counter() - t_setup
        manifest = store.open(spec, art.hashes(), digest, files)
        entry = session_entry(session, scheduler=scheduler or "local", runs_total=len(keys),
                              runs_skipped=outcome.skipped, workers=outcome.workers)
        manifest["sessions"].append(entry)
        store.write_manifest(manifest)
        say(f"{outcome.workers} workers ready; {len(todo)} runs to do")
        parts = _Parts(store, session, spec.batch, streaming.flush_s)
        ses = _Session(client, plugin.name, spec, digest, session, parts, outcome)
        stop = threading.Event()
        try:
            with _interrupt_flag(stop):
                _consume(ses, todo, streaming.window or max(32, 8 * outcome.workers),
                         on_result, progress, stop)
            outcome.status = "completed"
        except KeyboardInterrupt:
            outcome.status = "interrupted"
            raise
        finally:
            parts.flush()
            # counted from what is on disk: a Ctrl-C between storing a row and counting it
            # must not leave the session's count one short of its rows
            outcome.done, outcome.errors = parts.written, parts.errors
            entry.update(finished=session_entry(session)["started"], status=outcome.status,
                         runs_done=outcome.done, errors=outcome.errors,
                         wall_s=outcome.wall_s, setup_s=outcome.setup_s,
                         runs_per_min=outcome.runs_per_min)
            store.write_manifest(manifest)
            with contextlib.suppress(Exception):  # leave an external cluster as it was
                client.unregister_worker_plugin(plugin.name)
    return outcome
