"""The prosthesis controllers that follow the person's speed over a gait library, made for a
run (:class:`prosthesis_controller.speed_following.SpeedFollowing`): each library speed's
controller made from its gait's held walk (:mod:`orchestrator.cosim.contact_controllers`),
the speed estimate calibrated on the person walking each speed, and the co-simulation's
cached file of it (:func:`ensure_following_file`)."""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from characterization.gait.contact_gait import GAINS
from characterization.gait.library import GaitLibrary, start_at
from characterization.gait.multicontact import GRAPH
from hp_model.closed_loop import ClosedLoop
from hp_model.compiled import cache_root
from hp_model.leg_kinematics import LegKinematics
from orchestrator.cosim.contact_controllers import (
    MAKERS,
    HeldOracleFellError,
    LoopSetup,
    held_walk,
    loop_simulator,
    make_controller,
)
from prosthesis_controller import speed_following as speed_following_module
from prosthesis_controller.contact_phase_pd import DEFAULT_SWING_PHASE, ContactGaitTables
from prosthesis_controller.gait_tables import save_speed_following
from prosthesis_controller.passive import PassiveLaw
from prosthesis_controller.speed_following import (
    SPEED_RESOLUTION,
    FollowingSetup,
    SpeedFollowing,
    filled,
    flat_stance_rate,
    rising,
)

#: the controllers that follow the person's speed over a gait library (:func:`following_setup`)
FOLLOWERS = ("clfqp", "contact-pd", "pd", "passive")


def ensure_following_file(library_path: Path, library: GaitLibrary,
                          say: Callable[[str], None] | None = None) -> Path:
    """The file of ``clfqp`` following the person's speed over the gait library at
    ``library_path`` (``library``: it loaded; :func:`following_setup`,
    :func:`prosthesis_controller.gait_tables.save_speed_following`), made once (about a
    minute) and cached (``$HPCOSIM_CACHE`` or ``~/.cache/hpcosim``/controller/<digest>/
    following.npz; the digest covers the library file, its model and the code that makes
    the controllers).  HeldOracleFellError naming a speed whose held walk falls."""
    data = Path(library_path).read_bytes()
    h = hashlib.sha256(data)
    h.update(library.model.parameter_hash().encode())
    for f in (*MAKERS, Path(__file__), Path(str(speed_following_module.__file__))):
        h.update(f.read_bytes())
    out = cache_root() / "controller" / h.hexdigest()[:16] / "following.npz"
    if not out.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        setup = following_setup(library, "clfqp", say=say)
        save_speed_following(out, setup, library.model, hashlib.sha256(data).hexdigest())
    return out


def following_setup(library: GaitLibrary, controller: str = "clfqp",
                    swing_phase: str = DEFAULT_SWING_PHASE, closed_loop: ClosedLoop | None = None,
                    resolution: float = SPEED_RESOLUTION,
                    say: Callable[[str], None] | None = None) -> FollowingSetup:
    """What the controller following the person's speed over ``library`` is made of
    (:class:`~prosthesis_controller.speed_following.FollowingSetup`): ``controller``
    (one of :data:`FOLLOWERS`) made from each speed's gait and its held walk, switched
    between every ``resolution`` m/s (:func:`~prosthesis_controller.speed_following.filled`),
    its estimate calibrated on the person walking each of those speeds (:func:`walk_rate`,
    about 0.4 s each; progress through ``say``).  HeldOracleFellError naming the speed whose
    held walk falls (no tables from it)."""
    if controller not in FOLLOWERS:
        raise ValueError(f"controller {controller!r}: choose {', '.join(FOLLOWERS)}")
    say = say or (lambda _m: None)
    model = library.model
    passive = PassiveLaw(model) if controller == "passive" else None
    cl = closed_loop or ClosedLoop(model, library.curves[0].params[GRAPH.domains[0]].degree)
    ctls: list[Any] = []
    leg = LegKinematics.of(model)
    for g, curves in zip(library.gaits, library.curves, strict=True):
        say(f"the controller at {g.speed:.2f} m/s (the gait walked once)")
        sim = loop_simulator(model, curves, GAINS, cl)
        try:
            setup = LoopSetup(sim, held_walk(sim, g.trajectory))
        except HeldOracleFellError as e:
            raise HeldOracleFellError(f"the library's gait at {g.speed:.2f} m/s: {e}") from None
        ctls.append(make_controller(controller, model, curves, g.trajectory, setup,
                                    swing_phase=swing_phase, passive_law=passive))
    grid, speeds = filled(ctls, library.speeds.tolist(), resolution)
    rates = []
    for c, v in zip(grid, speeds, strict=True):
        say(f"the speed estimate's calibration: the person at {v:.2f} m/s")
        rates.append(walk_rate(leg, c.tables, library, float(v), cl))
    keep = rising(rates)
    return FollowingSetup(tuple(ctls), tuple(float(v) for v in library.speeds), resolution,
                          tuple(float(speeds[i]) for i in keep), tuple(rates[i] for i in keep))


def speed_following(library: GaitLibrary, controller: str = "clfqp",
                    speed: float | None = None, swing_phase: str = DEFAULT_SWING_PHASE,
                    closed_loop: ClosedLoop | None = None, resolution: float = SPEED_RESOLUTION
                    ) -> SpeedFollowing:
    """The prosthesis controller that follows the person's speed over ``library``
    (:class:`~prosthesis_controller.speed_following.SpeedFollowing`, made as
    :func:`following_setup` says), starting on ``speed`` (m/s; None: the fitted gait's)."""
    setup = following_setup(library, controller, swing_phase, closed_loop, resolution)
    start = next(g.speed for g in library.gaits if g.source) if speed is None else speed
    return setup.controller(start)


def walk_rate(leg: LegKinematics, tables: ContactGaitTables, library: GaitLibrary,
              speed: float, closed_loop: ClosedLoop) -> float:
    """The flat stance's hip rate (m/s) of the person walking ``library`` at ``speed``
    (m/s) with the held oracle, as a controller of ``tables`` on ``leg`` reads it
    (:func:`~prosthesis_controller.speed_following.flat_stance_rate`; about 0.4 s).
    HeldOracleFellError if that walk falls."""
    sim = loop_simulator(library.model, library.gait_at(speed), GAINS, closed_loop)
    slower = library.gaits[max(int(np.searchsorted(library.speeds, speed)) - 1, 0)]
    try:
        walk = held_walk(sim, slower.trajectory, start_at(library, speed))
    except HeldOracleFellError as e:
        raise HeldOracleFellError(f"the library's gait at {speed:.2f} m/s: {e}") from None
    p0, p1 = tables.progress
    phase = np.array([(leg.progress(*x[:3]) - p0) / (p1 - p0) for x in walk.sensed])
    return flat_stance_rate(tables, walk.t, phase, walk.contact)
