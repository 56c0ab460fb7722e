"""The per-tick exchange with the human FMU through preallocated fmi2 value buffers.

fmpy's ``getReal``/``setReal`` build new ctypes arrays on every call (2-4 us each); the
co-simulation reads and writes the same variables every 1 ms tick, so this port allocates
the value-reference and value arrays once and calls fmpy's checked ``fmi2GetReal`` etc.
(a status above warning raises ``fmpy``'s ``FMICallException`` as before).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from fmpy.fmi2 import fmi2Boolean, fmi2Integer, fmi2Real, fmi2ValueReference

from human_fmu.instance import step_or_end

#: sensor outputs in the order the plant reads them (rad, rad/s, N, phase tau, rad)
SENSORS = ("knee_angle", "ankle_angle", "knee_velocity", "ankle_velocity", "foot_load", "tau",
           "socket_pitch")
FORCES = ("socket_Fx", "socket_Fz", "socket_My")
STATE = tuple(f"q[{i}]" for i in range(1, 13)) + tuple(f"qd[{i}]" for i in range(1, 13))
COUNTS = ("domain", "steps", "fall_code")
INPUTS = ("u_knee", "u_ankle")


class _Vars:
    def __init__(self, vr: dict[str, int], names: Sequence[str], ctype: Any) -> None:
        self.n = len(names)
        self.refs = (fmi2ValueReference * self.n)(*(vr[n] for n in names))
        self.values = (ctype * self.n)()


class FmuPort:
    """Reads and writes of one co-simulation tick on an instantiated ``FMU2Slave``.

    :meth:`read` -> sensors (7, :data:`SENSORS`), state (24: q then qd, model
    coordinates), (domain 0 ps / 1 pns, step count, fall code), fall flag;
    :meth:`set_torque` the knee and ankle motor torques [N m]; :meth:`forces` the
    socket force (Fx, Fz [N], My [N m]) for the torque just set; :meth:`step`.
    """

    def __init__(self, slave: Any, vr: dict[str, int]) -> None:
        self._f = slave
        self._c = slave.component
        self._sens = _Vars(vr, SENSORS + STATE, fmi2Real)
        self._ints = _Vars(vr, COUNTS, fmi2Integer)
        self._fall = _Vars(vr, ("fall",), fmi2Boolean)
        self._u = _Vars(vr, INPUTS, fmi2Real)
        self._forces = _Vars(vr, FORCES, fmi2Real)

    def read(self) -> tuple[list[float], list[float], list[int], bool]:
        f, c = self._f, self._c
        s, i, b = self._sens, self._ints, self._fall
        f.fmi2GetReal(c, s.refs, s.n, s.values)
        f.fmi2GetInteger(c, i.refs, i.n, i.values)
        f.fmi2GetBoolean(c, b.refs, b.n, b.values)
        v = s.values[:]
        n = len(SENSORS)
        return v[:n], v[n:], i.values[:], b.values[0] != 0

    def set_torque(self, knee: float, ankle: float) -> None:
        u = self._u
        u.values[0], u.values[1] = knee, ankle
        self._f.fmi2SetReal(self._c, u.refs, u.n, u.values)

    def forces(self) -> list[float]:
        g = self._forces
        self._f.fmi2GetReal(self._c, g.refs, g.n, g.values)
        return g.values[:]

    def step(self, t: float, dt: float) -> bool:
        """doStep(t, dt): False once the FMU has ended the walk (a fall: fmi2Discard)."""
        return step_or_end(self._f, self._c, t, dt)
