"""The plant side of the closed loop: what the prosthesis senses, ground truth, how a walk
ends; one interface, two implementations (the in-process simulator, the human FMU).

A plant is stepped one control period at a time by :func:`orchestrator.loop.run_loop`:

    obs = plant.observe()        # the period's start: sensors, domain, steps, (a fall)
    truth = plant.actuate(u)     # hold the motor torque u over the period (None: the
                                 # plant's own feedback linearization, the oracle); the
                                 # ground truth under it; plant.fall may now be set
    plant.advance()              # integrate the period

What AMPRO3 senses (:func:`sensed`, the one sensor map): knee and ankle angle (rad) and
velocity (rad/s); the foot load cell, the ground normal force on the prosthesis foot in ps,
clipped at 0 (a load cell does not pull), 0 in pns; contact = the domain is ps; the socket
IMU's pitch (rad; NaN without one).  On the multi-contact graph the foot is on the ground
on its heel, flat or on its toe (:attr:`Domain.prosthesis_contact`), and the load is that
contact's normal force (:func:`wrench_rows`).  The FMU (the paper's graph) computes the
same outputs in its generated C (q, qd of th_pk, th_pa; lam[1]); :class:`FmuPlant` applies
the same clipping and contact rule to them through :func:`sensed`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple, Protocol, TypeAlias

import numpy as np

from hp_model.closed_loop import ClosedLoopMode
from hp_model.domains import PROSTHESIS, Domain
from hp_model.falls import Fall, FallReason
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.simulator import GaitSchedule, HybridSimulator, SimState
from human_fmu.instance import HumanFmu

#: a short vector of floats as the plants and links give it: a tuple, a list or a 1-D array
Vector: TypeAlias = Sequence[float] | np.ndarray


class Sensed(NamedTuple):
    """What the prosthesis's own sensors see (before encoder noise and quantization).
    (The loop's records are NamedTuples: immutable, and built every period at a third of a
    frozen dataclass's cost.)"""

    knee_angle: float  # rad
    ankle_angle: float  # rad
    knee_velocity: float  # rad/s
    ankle_velocity: float  # rad/s
    foot_load: float  # N, >= 0
    contact: bool
    socket_pitch: float  # rad, NaN without an IMU row


def sensed(domain: str, angles: tuple[float, float], velocities: tuple[float, float],
           normal_force: float, socket_pitch: float) -> Sensed:
    """The one map from the plant's state to what AMPRO3 senses (module docstring);
    ``normal_force``: the ground's normal force on the prosthesis foot (N) when it is on the
    ground (flat, on its heel or its toe: :attr:`Domain.prosthesis_contact`; the paper's ps)."""
    contact = Domain(domain).prosthesis_contact is not None
    return Sensed(float(angles[0]), float(angles[1]), float(velocities[0]),
                  float(velocities[1]), max(float(normal_force), 0.0) if contact else 0.0,
                  contact, float(socket_pitch))


class WrenchRows(NamedTuple):
    """Where a domain's constraint wrenches lam hold what the loop reads: the row of the
    ground's normal force on the prosthesis foot (None when it swings) and the socket's
    wrench (F_x, F_z, M_y)."""

    load: int | None
    socket: slice


def wrench_rows(model: HumanProsthesisModel) -> dict[Domain, WrenchRows]:
    """:class:`WrenchRows` of every domain of ``model``'s graph, from its constraint stacks
    (the paper's: ps load row 1, the socket rows 3:6 in both)."""
    rows = {}
    for d in model.graph.domains:
        stack, c = model.domains[d], d.prosthesis_contact
        load = None if c is None else stack.wrench_slice(c.name).start + 1  # (F_x, F_z, ..)
        rows[d] = WrenchRows(load, stack.wrench_slice("socket"))
    return rows


class Observation(NamedTuple):
    """The plant at the start of period ``k`` (t = k dt)."""

    k: int
    t: float  # s
    domain: Domain
    steps: int  # impacts so far
    tau: float  # the plant's phase (ground truth, not a sensor)
    sensed: Sensed
    #: the plant ended the walk during the previous period and holds that period's state:
    #: nothing new to observe (the FMU's friction-cone, non-finite and diverged falls)
    held: bool = False


class Truth(NamedTuple):
    """Ground truth of a period under the applied motor torque (for logs and recordings)."""

    q: Vector  # (12,) rad / m, model coordinates
    qd: Vector  # (12,)
    socket_force: Vector  # (3,) F_x, F_z (N), M_y (N m) on the socket
    torque: Vector  # (2,) motor torques applied (N m, after the plant's bound)


class Plant(Protocol):
    """What :func:`orchestrator.loop.run_loop` drives (module docstring)."""

    dt: float

    def observe(self) -> Observation: ...

    def actuate(self, torque: Vector | None) -> Truth: ...

    def advance(self) -> None: ...

    @property
    def fall(self) -> Fall | None: ...


def observe_state(k: int, st: SimState, knee_ankle: tuple[int, int],
                  pitch_row: np.ndarray | None = None, load_row: int | None = 1
                  ) -> Observation:
    """The observation of the simulator's state ``st`` at period ``k``: the model
    coordinates ``knee_ankle`` of th_pk, th_pa; ``pitch_row``: the model's
    ``pitch_row("socket")`` for the IMU's socket pitch (NaN without it); ``load_row``: the
    row of ``st.lam`` with the prosthesis foot's normal force (:class:`WrenchRows`; the
    paper's ps: 1)."""
    pk, pa = knee_ankle
    pitch = math.nan if pitch_row is None else float(pitch_row @ st.q)
    load = 0.0 if load_row is None else float(st.lam[load_row])
    s = sensed(st.domain, (st.q[pk], st.q[pa]), (st.qd[pk], st.qd[pa]), load, pitch)
    return Observation(k, st.t, st.domain, st.steps, st.tau, s)


class SimulatorPlant:
    """The in-process hybrid simulator (:class:`HybridSimulator`) as a plant, started from
    (q0, qd0) in ``domain``; ``mode`` "human" (the prosthesis torque comes from the loop)
    or "full" (the plant's own feedback linearization of all six torques: the oracle);
    ``gaits``: the gait the simulated person tracks in each domain it enters (a speed
    profile on a gait library; None: the simulator's gait throughout)."""

    def __init__(self, sim: HybridSimulator, q0: np.ndarray, qd0: np.ndarray,
                 domain: str = Domain.PS, *, mode: ClosedLoopMode | str = ClosedLoopMode.HUMAN,
                 gaits: GaitSchedule | None = None) -> None:
        self.sim = sim
        self.model: HumanProsthesisModel = sim.model
        self.dt = sim.opt.dt
        self.run = sim.start(q0, qd0, domain, mode=mode, gaits=gaits)
        self._pk, self._pa = (self.model.coord_names.index(c) for c in PROSTHESIS)
        self._pitch = self.model.pitch_row("socket")
        self._rows = wrench_rows(self.model)
        self._k = 0

    @property
    def fall(self) -> Fall | None:
        return self.run.fall

    def observe(self) -> Observation:
        st = self.run.observe()
        return observe_state(self._k, st, (self._pk, self._pa), self._pitch,
                             self._rows[st.domain].load)

    def actuate(self, torque: Vector | None) -> Truth:
        self.run.apply(None if torque is None else np.asarray(torque, dtype=float))
        q, qd, u, lam = self.run.last_sample()
        return Truth(q, qd, lam[self._rows[self.run.domain].socket], u[4:6])

    def advance(self) -> None:
        self.run.advance()
        self._k += 1


class FmuEndError(RuntimeError):
    """The FMU ended the run (fmi2Discard, fmi2Terminated) without a fall code."""


class FmuPlant:
    """The human FMU (:class:`HumanFmu`, already started) as a plant; the step size is
    ``dt``.  The run ends the FMI 2.0 way: a doStep that returns fmi2Discard with
    fmi2Terminated ends it, and ``fmi2LastSuccessfulTime`` tells which state the outputs
    hold: the end of that step (the fall is observed there, like the simulator's), or its
    start (falls 1, 5, 8: the previous observation's state, already logged, where the fall
    happened).  The ``fall_code`` output gives the reason (:class:`FmuEndError` without one);
    the :class:`Fall` has the observed time, domain and phase (the FMU reports its code,
    not the event's numbers).  A fall of the initial state (no step taken) is read from the
    ``fall`` output.

    ``gaits``: the gait the human tracks in each domain it enters (a person changing speed:
    :data:`hp_model.simulator.GaitSchedule`), the FMU started on the schedule's gaits at
    t = 0.  Before each step the plant sets the gait of the domain that follows the
    current one to the schedule's at the step's start (:meth:`HumanFmu.set_gait`; the FMU
    takes it up as it enters that domain): the in-process plant asks at the entry's time
    instead, within one period of it."""

    def __init__(self, fmu: HumanFmu, dt: float, gaits: GaitSchedule | None = None) -> None:
        if gaits is not None and fmu.graph is None:
            raise ValueError("a gait schedule needs an FMU of a known domain graph")
        self.fmu, self.dt, self.gaits = fmu, float(dt), gaits
        self._domain: Domain | None = None
        self._k = 0
        self._fall: Fall | None = None
        self._obs: Observation | None = None
        self._state: list[float] | None = []
        #: the state read apart from the sensors (:meth:`read_truth`): a HumanFmu (a
        #: wrapper overriding its ``read`` keeps the one full read)
        self._apart = type(fmu) is HumanFmu
        self._ended_at: float | None = None  # fmi2LastSuccessfulTime once the run has ended

    @property
    def fall(self) -> Fall | None:
        return self._fall

    def observe(self) -> Observation:
        r = self.fmu.read(False) if self._apart else self.fmu.read()
        y = r.sensors
        dom = Domain.from_code(r.domain)
        s = sensed(dom, (y[0], y[1]), (y[2], y[3]), y[4], y[6])
        obs = Observation(self._k, self._k * self.dt, dom, r.steps, float(y[5]), s)
        if self._ended_at is not None or r.fell:
            if not r.fell or r.fall_code == FallReason.NONE:
                raise FmuEndError(f"the FMU ended the run at t = {self._ended_at} s (fmi2Discard, "
                               "fmi2Terminated) without a fall code")
            # held: the outputs are at the start of the discarded step, the previous
            # observation's state, where the fall happened
            held = (self._ended_at is not None and self._obs is not None
                    and self._ended_at < obs.t - 0.5 * self.dt)
            at = self._obs if held and self._obs is not None else obs
            self._fall = Fall(FallReason(r.fall_code), at.t, at.domain, at.tau)
            obs = obs._replace(held=held)
        self._state = None if self._apart else r.state
        if not obs.held:
            self._obs = obs
        self._domain = dom
        return obs

    def read_truth(self) -> None:
        """Read the state the period's ground truth holds (q, qd at its start), apart from
        the sensors :meth:`observe` read: the loop calls it while the controller works
        (run_loop's ``idle``), else :meth:`actuate` reads it.  (The socket force depends
        on the torque: :meth:`actuate` reads it.)"""
        if self._state is None:
            self._state = self.fmu.read_state()

    def actuate(self, torque: Vector | None) -> Truth:
        if torque is None:
            raise ValueError("the FMU plant needs a prosthesis torque (no oracle mode)")
        u0, u1 = float(torque[0]), float(torque[1])
        st = self._state
        if st is None:
            st = self._state = self.fmu.read_state()
        self.fmu.set_torque(u0, u1)
        return Truth(st[:12], st[12:], self.fmu.forces(), (u0, u1))

    def advance(self) -> None:
        if self._ended_at is not None:
            raise RuntimeError("the FMU has ended the run")
        t = self._k * self.dt
        if self.gaits is not None and self._domain is not None and self.fmu.graph is not None:
            nxt = self.fmu.graph.next(self._domain)
            self.fmu.set_gait(nxt, self.gaits(nxt, t))
        if not self.fmu.step(t, self.dt):  # fmi2Discard + fmi2Terminated
            self._ended_at = self.fmu.last_successful_time()
        self._k += 1
