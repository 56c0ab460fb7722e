"""The one Python wrapper of the human FMU: an fmpy ``FMU2Slave`` with name-based value
references and the per-tick exchange through preallocated fmi2 value buffers.

The co-simulation master, the sweeps' FMU backend and the closed loop's FMU plant all drive
the FMU through :class:`HumanFmu`.  (``tests/fmu_runner.py`` is a deliberately independent
importer: it runs in a Python where this project cannot be imported, as a user with only
fmpy would.)

fmpy's ``getReal``/``setReal`` build new ctypes arrays on every call (2-4 us each); a loop
reads and writes the same variables every 1 ms tick, so the value-reference and value
arrays are allocated once, and the per-tick calls go straight to the FMU's fmi2 functions
as fmpy loaded them from its shared library (the ctypes functions with fmpy's argument
types), without fmpy's Python wrapper around each (its optional call logging and status
check): the status is checked here the same way (above warning raises fmpy's
``FMICallException``).
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import json
import os
import re
import shutil
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from hp_model.domains import Domain, DomainGraph

#: sensor outputs in the order :meth:`HumanFmu.read` returns them (rad, rad/s, N, phase, rad)
SENSORS = ("knee_angle", "ankle_angle", "knee_velocity", "ankle_velocity", "foot_load", "tau",
           "socket_pitch")
#: the socket force (N, N, N m): depends on the torque inputs (read after setting them)
FORCES = ("socket_Fx", "socket_Fz", "socket_My")
#: the full state: q then qd in the model's coordinate order
STATE = tuple(f"q[{i}]" for i in range(1, 13)) + tuple(f"qd[{i}]" for i in range(1, 13))
COUNTS = ("domain", "steps", "fall_code")
INPUTS = ("u_knee", "u_ankle")


class FmuReading(NamedTuple):
    """One read of the FMU's outputs at the start of a period."""

    sensors: list[float]  # SENSORS
    state: list[float]  # STATE (q, qd)
    domain: int  # 0 ps, 1 pns
    steps: int  # impacts so far
    fall_code: int  # hp_model.falls.FallReason value (0: walking)
    fell: bool


_WARNING = 1  # fmi2Warning: a status above it is a failed call


def _checked(f: Any, name: str) -> Any:
    """The fmi2 function ``f`` (a ctypes function of the FMU's library) raising fmpy's
    ``FMICallException`` for a status above warning, as fmpy's wrapper does."""
    from fmpy.fmi1 import FMICallException

    def call(*args: Any) -> int:
        status = f(*args)
        if status > _WARNING:
            raise FMICallException(function=name, status=status)
        return int(status)
    return call


def step_or_end(slave: Any, component: Any, t: float, dt: float,
                do_step: Any = None) -> bool:
    """``slave.fmi2DoStep(component, t, dt, fmi2True)`` on an fmpy ``FMU2Slave`` (or
    ``do_step(component, t, dt, fmi2True)``, a checked call of the same function): True on
    success, False when the FMU discards the step and reports itself terminated (the end of
    the walk), else the ``FMICallException`` propagates."""
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import fmi2Boolean, fmi2Discard, fmi2Terminated, fmi2True

    try:
        (do_step or slave.fmi2DoStep)(component, t, dt, fmi2True)
        return True
    except FMICallException as e:
        if e.status != fmi2Discard:
            raise
    done = fmi2Boolean()
    slave.fmi2GetBooleanStatus(component, fmi2Terminated, ctypes.byref(done))
    if not done.value:
        raise FMICallException(function="fmi2DoStep", status=fmi2Discard)
    return False


#: a private extraction folder in the temporary folder: ``hpcosim-fmu-<pid>-<random>``
EXTRACT_PREFIX = "hpcosim-fmu-"
_EXTRACTED = re.compile(rf"{EXTRACT_PREFIX}(\d+)-")


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def folder_held(path: str) -> bool:
    """The folder is locked by its (living) owner: a shared lock held while it is in use."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC | os.O_NOFOLLOW)
    except OSError:
        return True  # cannot tell: keep it
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return False
    except BlockingIOError:
        return True
    finally:
        os.close(fd)


def sweep_dead_extractions(folder: str | Path | None = None) -> list[Path]:
    """Remove this user's ``hpcosim-fmu-<pid>-*`` folders in ``folder`` (default: the
    temporary folder) whose process is dead and whose lock nobody holds (left by a run
    killed with SIGKILL); the paths removed."""
    gone = []
    with contextlib.suppress(OSError):
        for e in os.scandir(folder or tempfile.gettempdir()):
            m = _EXTRACTED.match(e.name)
            if (m is None or not e.is_dir(follow_symlinks=False)
                    or e.stat(follow_symlinks=False).st_uid != os.geteuid()
                    or pid_alive(int(m.group(1))) or folder_held(e.path)):
                continue
            shutil.rmtree(e.path, ignore_errors=True)
            gone.append(Path(e.path))
    return gone


def extract_private(path: str | Path) -> tuple[Path, int]:
    """Extract the FMU at ``path`` into a new private folder (mode 0700) named after this
    process, first removing the folders of dead runs (:func:`sweep_dead_extractions`);
    ``(folder, fd)``: ``fd`` holds the folder's shared lock until it is closed."""
    from fmpy import extract

    sweep_dead_extractions()
    d = tempfile.mkdtemp(prefix=f"{EXTRACT_PREFIX}{os.getpid()}-")
    try:
        fd = os.open(d, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        fcntl.flock(fd, fcntl.LOCK_SH)
    except BaseException:
        shutil.rmtree(d, ignore_errors=True)
        raise
    try:
        extract(str(path), unzipdir=d)
    except BaseException:
        _release(Path(d), fd)
        raise
    return Path(d), fd


def _release(folder: Path, fd: int | None) -> None:
    """Remove an extraction folder and drop its lock."""
    shutil.rmtree(folder, ignore_errors=True)
    if fd is not None:
        with contextlib.suppress(OSError):
            os.close(fd)


class _Buffer:
    """Preallocated value references and values of one fmi2 type."""

    def __init__(self, vr: Mapping[str, int], names: Sequence[str], ctype: Any) -> None:
        from fmpy.fmi2 import fmi2ValueReference

        self.n = len(names)
        self.refs = (fmi2ValueReference * self.n)(*(vr[n] for n in names))
        self.values = (ctype * self.n)()


class HumanFmu:
    """The human FMU at ``path``, extracted into ``unzipdir`` (default: a private folder
    named after this process, :func:`extract_private`; removed by :meth:`free`, or at the
    next start by any process if this one is killed) and instantiated once; :meth:`start`
    (re)initialises it for a run.  Refuses an FMI 3.0 FMU (the loops drive FMI 2.0; the two
    are bit-identical)."""

    def __init__(self, path: str | Path, *, unzipdir: str | Path | None = None,
                 instance: str = "human") -> None:
        from fmpy import extract, read_model_description

        self.path = Path(path)
        self.md = read_model_description(str(path))
        if self.md.fmiVersion != "2.0":
            from human_fmu.build import FmuBuildError

            raise FmuBuildError(f"{path}: an FMI {self.md.fmiVersion} FMU; the co-simulation "
                                "and the sweeps drive FMI 2.0 FMUs (hpcosim fmu build "
                                "without --fmi 3; the two are bit-identical)")
        self._lock: int | None = None
        if unzipdir is None:
            self.unzipdir, self._lock = extract_private(path)
        else:
            self.unzipdir = Path(extract(str(path), unzipdir=str(unzipdir)))
        try:
            self._instantiate(instance)
        except BaseException:
            _release(self.unzipdir, self._lock)
            raise

    def _instantiate(self, instance: str) -> None:
        """Read the build info, instantiate the FMU and allocate the exchange buffers."""
        from fmpy.fmi2 import FMU2Slave, fmi2Boolean, fmi2Integer, fmi2Real

        info = self.unzipdir / "resources" / "build_info.json"
        self.build_info: dict[str, Any] = json.loads(info.read_text()) if info.is_file() else {}
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        #: the domains the FMU's human tracks (its graph's), each with its packed gait's size
        self.theta_sizes = {d: sum(1 for n in self.vr if n.startswith(f"theta_{d}["))
                            for d in Domain if f"theta_{d}[1]" in self.vr}
        #: its graph (the domains it tracks a gait in) and each domain's gait's references
        self.graph = next((g for g in DomainGraph if set(g.domains) == set(self.theta_sizes)),
                          None)
        self._theta_refs = {d: self.vrs(f"theta_{d}[{i + 1}]" for i in range(n))
                            for d, n in self.theta_sizes.items()}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(self.unzipdir),
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName=instance)
        self.fmu.instantiate()
        self._c = self.fmu.component
        self._out = _Buffer(self.vr, SENSORS + STATE, fmi2Real)
        self._sensors = _Buffer(self.vr, SENSORS, fmi2Real)
        self._state = _Buffer(self.vr, STATE, fmi2Real)
        self._ints = _Buffer(self.vr, COUNTS, fmi2Integer)
        self._fall = _Buffer(self.vr, ("fall",), fmi2Boolean)
        self._u = _Buffer(self.vr, INPUTS, fmi2Real)
        self._forces = _Buffer(self.vr, FORCES, fmi2Real)
        dll = self.fmu.dll  # the functions fmpy loaded, with its argument types
        self._get_real = _checked(dll.fmi2GetReal, "fmi2GetReal")
        self._get_integer = _checked(dll.fmi2GetInteger, "fmi2GetInteger")
        self._get_boolean = _checked(dll.fmi2GetBoolean, "fmi2GetBoolean")
        self._set_real = _checked(dll.fmi2SetReal, "fmi2SetReal")
        self._do_step = _checked(dll.fmi2DoStep, "fmi2DoStep")
        self._n_sensors = len(SENSORS)
        self._started = False

    # -- set-up ------------------------------------------------------------------------------
    def vrs(self, names: Iterable[str]) -> list[int]:
        """Value references of ``names`` (KeyError for an unknown name)."""
        return [self.vr[n] for n in names]

    def check_gait(self, gait_hash: str) -> None:
        """Refuse an FMU built for another gait (its build_info gait hash)."""
        h = self.build_info.get("gait_hash")
        if h is not None and h != gait_hash:
            raise ValueError(f"the FMU was built for gait {h}, not for this gait "
                             f"({gait_hash})")

    def start(self, real: Mapping[str, float] | None = None,
              integer: Mapping[str, int] | None = None) -> None:
        """(Reset if already started,) setupExperiment(t = 0), set the start values, enter
        and exit initialization."""
        f = self.fmu
        if self._started:
            f.reset()
        f.setupExperiment(startTime=0.0)
        if real:
            f.setReal(self.vrs(real), [float(v) for v in real.values()])
        if integer:
            f.setInteger(self.vrs(integer), [int(v) for v in integer.values()])
        f.enterInitializationMode()
        f.exitInitializationMode()
        self._started = True

    def start_walk(self, thetas: Mapping[Domain, np.ndarray], q0: np.ndarray, qd0: np.ndarray,
                   real: Mapping[str, float] | None = None) -> None:
        """Start a run where the human tracks ``thetas`` (packed gait per domain) from
        (q0, qd0) in its graph's first domain (ps), with no FMU-side perturbation or offset:
        the state the in-process simulator starts from; ``real``: other Real parameters (e.g.
        fall limits)."""
        values = self.walk_values(thetas, q0, qd0)
        values.update(human_perturbation=0.0, offset_knee=0.0, offset_ankle=0.0)
        values.update(real or {})
        self.start(values, {"human_seed": 0, "initial_domain": 0})

    def walk_values(self, thetas: Mapping[Domain, np.ndarray], q0: np.ndarray,
                    qd0: np.ndarray) -> dict[str, float]:
        """The Real start values of the human tracking ``thetas`` (packed gait per domain of
        its graph) from (q0, qd0) (:meth:`start`'s ``real``).  ValueError for a gait of
        another size than the FMU's."""
        values: dict[str, float] = {}
        for d, size in self.theta_sizes.items():
            th = np.asarray(thetas[d], float)
            if th.size != size:
                raise ValueError(f"theta_{d} of size {th.size}; the FMU has {size}")
            values.update({f"theta_{d}[{i + 1}]": float(v) for i, v in enumerate(th)})
        values.update({f"q0[{i + 1}]": float(v) for i, v in enumerate(q0)})
        values.update({f"qd0[{i + 1}]": float(v) for i, v in enumerate(qd0)})
        return values

    def set_gait(self, domain: Domain, theta: np.ndarray) -> None:
        """The packed gait the human tracks the next time it enters ``domain`` (the theta
        parameters are tunable in step mode: the FMU takes them up at the domain's entry,
        with its human perturbation on top).  ValueError for a gait of the wrong size."""
        refs = self._theta_refs[Domain(domain)]
        th = np.asarray(theta, float)
        if th.size != len(refs):
            raise ValueError(f"theta_{domain} of size {th.size}; the FMU has {len(refs)}")
        self.fmu.setReal(refs, th.tolist())

    def model_description_xml(self) -> bytes:
        return (self.unzipdir / "modelDescription.xml").read_bytes()

    # -- the per-tick exchange -------------------------------------------------------------
    def read(self, state: bool = True) -> FmuReading:
        """The outputs at the start of the current period; ``state`` False: all but the
        state (``FmuReading.state`` empty; :meth:`read_state` reads it, the same values
        until the next step)."""
        c = self._c
        i, b = self._ints, self._fall
        if not state:
            s = self._sensors
            self._get_real(c, s.refs, s.n, s.values)
            self._get_integer(c, i.refs, i.n, i.values)
            self._get_boolean(c, b.refs, b.n, b.values)
            dom, steps, code = i.values
            return FmuReading(s.values[:], [], dom, steps, code, b.values[0] != 0)
        s = self._out
        self._get_real(c, s.refs, s.n, s.values)
        self._get_integer(c, i.refs, i.n, i.values)
        self._get_boolean(c, b.refs, b.n, b.values)
        n, v = self._n_sensors, s.values
        dom, steps, code = i.values
        return FmuReading(v[:n], v[n:], dom, steps, code, b.values[0] != 0)

    def read_state(self) -> list[float]:
        """The state (``STATE``: q, qd) at the start of the current period."""
        s = self._state
        self._get_real(self._c, s.refs, s.n, s.values)
        return s.values[:]

    def set_torque(self, knee: float, ankle: float) -> None:
        """The prosthesis motor torques held over the next step [N m]."""
        u = self._u
        u.values[0], u.values[1] = knee, ankle
        self._set_real(self._c, u.refs, u.n, u.values)

    def forces(self) -> list[float]:
        """The socket force (Fx, Fz [N], My [N m]) under the torque just set."""
        g = self._forces
        self._get_real(self._c, g.refs, g.n, g.values)
        return g.values[:]

    def step(self, t: float, dt: float) -> bool:
        """fmi2DoStep(t, dt): True while the walk goes on, False once the FMU has ended it
        (fmi2Discard with fmi2Terminated: a fall; the outputs hold the last valid state).
        Any other failure raises fmpy's ``FMICallException``."""
        return step_or_end(self.fmu, self._c, t, dt, self._do_step)

    def last_successful_time(self) -> float:
        """fmi2GetRealStatus(fmi2LastSuccessfulTime) [s]: after the walk has ended, the time
        of the state the outputs hold (human_fmu/README.md)."""
        from fmpy.fmi2 import fmi2LastSuccessfulTime, fmi2Real

        t = fmi2Real()
        self.fmu.fmi2GetRealStatus(self._c, fmi2LastSuccessfulTime, ctypes.byref(t))
        return float(t.value)

    def start_value(self, name: str) -> float:
        """The start value of variable ``name`` in the model description (a parameter's
        default)."""
        v = next(v for v in self.md.modelVariables if v.name == name)
        return float(v.start)

    def free(self) -> None:
        """Terminate and free the instance, then remove the extracted files."""
        try:
            self.fmu.terminate()
            self.fmu.freeInstance()
        finally:
            _release(self.unzipdir, self._lock)
            self._lock = None
