"""The walker, animated (issue 21): a stick figure of a closed-loop run as a GIF.

From the run's full configuration q (n, 12) and the model's frames (:meth:`hp_model.
HumanProsthesisModel.numeric` ``frames``: x, z of every joint and sole point): the human
(trunk, left leg, the thigh in the iWalk) in blue, the prosthesis (socket to foot) in
orange, the ground, the socket force on the prosthesis as an arrow at the socket (world
frame; 1 m per ``FORCE_SCALE`` N, at most ``MAX_ARROW`` m long, drawn ``ARROW_OFFSET`` m in front
of the socket so that it does not hide the shank, with its magnitude written at its tail), and the
time, domain, phase and step count.  The view follows the hip (the x axis in m and marks on
the ground every ``GROUND_MARK`` m show the walk's progress); a run that fell ends on its last
pose, held ``FALL_HOLD`` s under a banner naming the fall.  Frames are taken every ``1 / fps``
s of the 1 kHz log and written with matplotlib's Pillow writer (no other dependency).  The
poses are copied out of the compiled ``frames`` function's output, which its next call
overwrites (:func:`walker_poses`).
"""

from __future__ import annotations

import math
import tempfile
import textwrap
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hp_model.domains import Domain
from hp_model.falls import Fall, FallReason
from hp_model.human_prosthesis import HumanProsthesisModel
from orchestrator.loop.walker_figure import FORCE_SCALE, HUMAN, IWALK, PROSTHESIS

if TYPE_CHECKING:  # matplotlib is imported when a GIF is drawn
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

MAX_ARROW = 0.45  # m: longer arrows are shortened (direction kept) to stay in the frame
ARROW_OFFSET = 0.15  # m along x: the tail in front of the socket, clear of the shank and of
#: the swing leg (behind the prosthesis while the load peaks, early in stance)
ARROW_COLOUR = "#b00020"
FALL_COLOUR = "#d0006f"  # the fall's banner (magenta: apart from the arrow's red)
FALL_HOLD = 1.0  # s: a run that fell ends on its last pose, held this long with the banner
GROUND_MARK = 0.25  # m between the ground's marks (the view follows the hip: they move back)
SPEED_WINDOW = 1.0  # s: the walking speed shown is the hip's mean over this (about a stride)


def arrow_vector(fx: float, fz: float) -> tuple[float, float]:
    """The arrow (m) of a world-frame force (N): ``FORCE_SCALE`` N per metre, shortened to
    ``MAX_ARROW`` m with its direction kept."""
    n = math.hypot(fx, fz) / FORCE_SCALE
    k = 1.0 / FORCE_SCALE if n <= MAX_ARROW else MAX_ARROW / n / FORCE_SCALE
    return fx * k, fz * k


def walker_poses(model: HumanProsthesisModel, q: np.ndarray) -> np.ndarray:
    """(m, 3, frames) world x [m], z [m], pitch [rad] of every named frame at each row of
    ``q`` (m, nq).  The compiled ``frames`` returns the one output array its next call
    overwrites (:mod:`hp_model.compiled`): each pose is copied into its row as it comes."""
    fr = model.numeric()["frames"]
    zero = np.zeros(model.nq)
    q = np.atleast_2d(np.asarray(q, float))
    out = np.empty((q.shape[0], 3, len(model.frame_names)))
    for k, qk in enumerate(q):
        out[k] = fr(qk, zero)[0]
    return out


@dataclass(frozen=True)
class WalkSeries:
    """The time series of a run the walker is drawn from: ``t`` (n,) s, ``q`` (n, 12),
    ``domain`` (n,) codes (0 = ps, 1 = pns), ``tau`` (n,), ``socket_force`` (n, 3) (F_x,
    F_z, M_y in the prosthesis top link's frame) or None (no arrow), ``fall``: the fall that
    ended the run at its last row, or None."""

    t: np.ndarray
    q: np.ndarray
    domain: np.ndarray
    tau: np.ndarray
    socket_force: np.ndarray | None = None
    fall: Fall | None = None  # how the run ended: shown on its last row's frames
    #: (n,) m/s: the walking speed commanded (a person walking a gait library along a speed
    #: profile), shown beside the hip's speed over the last second; None: not shown
    command: np.ndarray | None = None


class WalkerScene:
    """The artists of the walker's figure (ground and its marks, stick figure, head, force
    arrow and its label, the status line, the fall's banner) and how frame ``k`` of the GIF
    sets them; ``idx``: the log row of each frame."""

    def __init__(self, model: HumanProsthesisModel, walk: WalkSeries, t: np.ndarray,
                 idx: np.ndarray, ax: Axes, title: str) -> None:
        self.names = list(model.frame_names)
        self.pose = walker_poses(model, walk.q[idx])  # (m, 3, frames)
        self.ib, self.trunk = model.coord_names.index("th_B"), model.subject.lengths.trunk
        self.pitch_row = model.pitch_row("socket")
        # steps: entries into a domain that starts one (the paper's: every domain change;
        # the multi-contact graph: the heel strikes)
        dom = np.asarray(walk.domain)
        starts = np.isin(dom[1:], [d.code for d in model.graph.step_starts])
        self.steps = np.concatenate([[0], np.cumsum((np.diff(dom) != 0) & starts)])
        self.walk, self.t, self.idx, self.ax = walk, t, idx, ax
        ax.set_aspect("equal")
        ax.set_ylim(-0.12, 1.55)
        ax.set_yticks([])
        ax.axhline(0.0, color="#5a4a3a", lw=2)
        hip = self.pose[:, 0, self.names.index("hip")]
        marks = np.arange(np.floor(hip.min() - 1.5), hip.max() + 1.5, GROUND_MARK)
        ax.vlines(marks, -0.08, 0.0, color="#5a4a3a", lw=1.5)
        ax.set_xlabel("x (m)", fontsize=8)
        self.lines = []
        for colour, chains in (HUMAN, IWALK, PROSTHESIS):
            for _ in chains:
                (ln,) = ax.plot([], [], "-o", color=colour, lw=3, ms=3)
                self.lines.append(ln)
        (self.head,) = ax.plot([], [], "-o", color=HUMAN[0], lw=4, ms=3)
        # annotation_clip=False: an annotation whose point leaves the axes is not drawn at all
        self.arrow = ax.annotate("", xy=(0, 0), xytext=(0, 0), annotation_clip=False,
                                 arrowprops={"arrowstyle": "-|>", "color": ARROW_COLOUR,
                                             "lw": 2.5, "mutation_scale": 14})
        self.force_label = ax.text(0, 0, "", color=ARROW_COLOUR, fontsize=9, ha="left",
                                   va="bottom")
        self.label = ax.text(0.01, 0.97, "", transform=ax.transAxes, va="top", fontsize=10)
        self.banner = ax.text(0.5, 0.82, "", transform=ax.transAxes, ha="center", va="top",
                              color=FALL_COLOUR, fontsize=9, fontweight="bold",
                              bbox={"facecolor": "white", "edgecolor": FALL_COLOUR})
        self.banner.set_visible(False)
        ax.set_title(title, fontsize=10)

    def draw(self, k: int) -> tuple[Artist, ...]:
        """Set every artist to frame ``k``; the artists."""
        p, i = self.pose[k], self.idx[k]
        xy = {n: (p[0, j], p[1, j]) for j, n in enumerate(self.names)}
        li = 0
        for _, chains in (HUMAN, IWALK, PROSTHESIS):
            for chain in chains:
                self.lines[li].set_data([xy[n][0] for n in chain], [xy[n][1] for n in chain])
                li += 1
        qi = self.walk.q[i]
        hx, hz = xy["hip"]
        th = qi[self.ib]
        self.head.set_data([hx, hx + self.trunk * math.sin(th)],
                           [hz, hz + self.trunk * math.cos(th)])
        if self.walk.socket_force is not None:
            self._draw_force(self.walk.socket_force[i], qi, xy["socket"])
        self.ax.set_xlim(hx - 1.0, hx + 1.0)
        d = Domain.from_code(self.walk.domain[i])
        speed = ""
        if self.walk.command is not None:
            speed = (f"\nspeed {self._walked(i):.2f} m/s over the last {SPEED_WINDOW:g} s, "
                     f"commanded {self.walk.command[i]:.2f}")
        self.label.set_text(f"t {self.t[i]:.2f} s  {d}  tau {self.walk.tau[i]:.2f}  "
                            f"step {int(self.steps[i])}{speed}")
        self._draw_fall(i)
        return (*self.lines, self.head, self.arrow, self.force_label, self.label,
                self.banner)

    def _walked(self, i: int) -> float:
        """The hip's mean forward speed (m/s) over the :data:`SPEED_WINDOW` before row ``i``
        (less at the run's start; NaN on its first row)."""
        t = self.walk.t
        j = int(np.searchsorted(t, t[i] - SPEED_WINDOW))
        if j >= i:
            return math.nan
        x = self.walk.q[:, 0]
        return float((x[i] - x[j]) / (t[i] - t[j]))

    def _draw_fall(self, i: int) -> None:
        """The fall's banner on the frames of the last row of a run that fell."""
        fall = self.walk.fall
        shown = fall is not None and i == self.t.size - 1
        self.banner.set_visible(shown)
        if fall is not None and shown:
            self.banner.set_text(f"FELL at t = {fall.t:.3f} s ({fall.domain}, tau = "
                                 f"{fall.tau:.2f}):\n" + textwrap.fill(fall.detail(), 40))

    def _draw_force(self, force: np.ndarray, qi: np.ndarray, socket: tuple[float, float]
                    ) -> None:
        """The socket force (F_x, F_z in the top link's frame, N) as an arrow in the world
        frame, its tail ``ARROW_OFFSET`` m in front of the socket, its magnitude beside it."""
        fx, fz = force[0], force[1]
        a = float(self.pitch_row @ qi)  # top link's world pitch
        wx = math.cos(a) * fx + math.sin(a) * fz  # rotation about +y
        wz = -math.sin(a) * fx + math.cos(a) * fz
        sx, sz = socket
        sx += ARROW_OFFSET
        dx, dz = arrow_vector(wx, wz)
        self.arrow.xy = (sx + dx, sz + dz)
        self.arrow.set_position((sx, sz))
        self.force_label.set_position((sx + 0.02, sz))
        self.force_label.set_text(f"F_s {math.hypot(fx, fz):.0f} N")


def walker_scene(model: HumanProsthesisModel, walk: WalkSeries, *, title: str = "",
                 fps: float = 25.0, max_seconds: float | None = None,
                 size: tuple[float, float] = (6.0, 4.0), dpi: int = 100
                 ) -> tuple[Figure, WalkerScene]:
    """The figure and scene of :func:`walker_gif` (frame ``k`` drawn by ``scene.draw(k)``,
    log row ``scene.idx[k]``): a frame every ``1 / fps`` s of the first ``max_seconds`` s,
    then, if the run fell, its last row for ``FALL_HOLD`` s with the fall's banner."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    t = np.asarray(walk.t, float)
    if t.size == 0:
        raise ValueError("an empty run has nothing to animate")
    end = t[-1] if max_seconds is None else min(t[-1], t[0] + max_seconds)
    times = np.arange(t[0], end + 1e-9, 1.0 / fps)
    idx = np.minimum(np.searchsorted(t, times), t.size - 1)
    if walk.fall is not None:  # the fall's pose held (after the window if it ends sooner)
        idx = np.r_[idx, np.full(max(1, round(FALL_HOLD * fps)), t.size - 1)]
    fig, ax = plt.subplots(figsize=size, dpi=dpi)
    return fig, WalkerScene(model, walk, t, idx, ax, title)


def walker_gif(model: HumanProsthesisModel, walk: WalkSeries, *, title: str = "",
               fps: float = 25.0, max_seconds: float | None = None,
               size: tuple[float, float] = (6.0, 4.0), dpi: int = 100) -> bytes:
    """GIF bytes of the run ``walk`` (module docstring): a frame every ``1 / fps`` s of its
    first ``max_seconds`` s (None: all of it), ``size`` in inches at ``dpi``."""
    from matplotlib import animation
    from matplotlib import pyplot as plt

    fig, scene = walker_scene(model, walk, title=title, fps=fps, max_seconds=max_seconds,
                              size=size, dpi=dpi)
    anim = animation.FuncAnimation(fig, scene.draw, frames=len(scene.idx), blit=False)
    with tempfile.TemporaryDirectory() as tmp:  # Pillow's writer wants a file name
        path = Path(tmp) / "walker.gif"
        # matplotlib's stub types fps as int; the writer only computes 1000 / fps (ms per
        # frame), and a fractional --fps must keep its frame duration
        writer = animation.PillowWriter(fps=fps)  # type: ignore[arg-type]
        anim.save(str(path), writer=writer)
        data = path.read_bytes()
    plt.close(fig)
    return data


def walker_strip(model: HumanProsthesisModel, walk: WalkSeries, rows: np.ndarray, *,
                 title: str = "", size: tuple[float, float] = (3.0, 3.2)) -> bytes:
    """PNG bytes of the walker at the log ``rows`` of ``walk``, side by side (the frames of
    :func:`walker_gif`, each ``size`` inches): several frames across a stride show the motion
    one frame cannot."""
    import io

    from matplotlib.figure import Figure
    from PIL import Image

    from hp_model.figures import figure_bytes

    rows = np.asarray(rows, int)
    if rows.size == 0:
        raise ValueError("no rows to draw")
    fig = Figure(figsize=size)  # not pyplot's: drawn and written once per frame
    scene = WalkerScene(model, walk, np.asarray(walk.t, float), rows, fig.subplots(), title)
    frames = []
    for k in range(rows.size):
        scene.draw(k)
        frames.append(Image.open(io.BytesIO(figure_bytes(fig))).convert("RGB"))
    strip = Image.new("RGB", (sum(f.width for f in frames), max(f.height for f in frames)),
                      "white")
    x = 0
    for f in frames:
        strip.paste(f, (x, 0))
        x += f.width
    out = io.BytesIO()
    strip.save(out, format="PNG")
    return out.getvalue()


def recording_gif(path: str | Path, model: HumanProsthesisModel, *, fps: float = 25.0,
                  max_seconds: float | None = None) -> bytes:
    """GIF of a co-simulation recording's walk, from its ``/ground_truth`` channel (q, domain,
    tau, socket force every tick).  A recording without it is a
    :class:`~orchestrator.cosim.recording.RecordingError`."""
    from bus_schemas.recording.reader import read_messages
    from orchestrator.cosim.recording import RecordingError, read_recording

    rec = read_recording(path, messages=False)
    rows = [o for _, _, o in read_messages(path, ["/ground_truth"])]
    if len(rows) < 2:
        raise RecordingError(f"{path}: {len(rows)} /ground_truth messages: nothing to animate")
    t = np.array([o["t"] for o in rows], float)
    q = np.array([o["q"] for o in rows], float)
    if q.shape[1] != model.nq:
        raise RecordingError(f"{path}: /ground_truth q has {q.shape[1]} coordinates, the "
                             f"model {model.nq}")
    dom = np.array([Domain(o["domain"]).code for o in rows])
    tau = np.array([o["tau"] for o in rows], float)
    fs = np.array([[o["socket_force"][k] for k in ("Fx", "Fz", "My")] for o in rows], float)
    ctrl = rec.config.get("controller", "")
    fall = _recorded_fall(rec.metadata.get("summary", {}), t[-1], dom[-1], tau[-1])
    return walker_gif(model, WalkSeries(t, q, dom, tau, fs, fall, _recorded_command(rec, t)),
                      fps=fps,
                      max_seconds=max_seconds,
                      title=f"{Path(path).name}" + (f" ({ctrl})" if ctrl else ""))


def _recorded_command(rec: Any, t: np.ndarray) -> np.ndarray | None:
    """The speed commanded at times ``t`` (s) of a recording of a person walking a gait
    library, None for any other run."""
    from orchestrator.cosim.recording import recorded_profile

    profile = recorded_profile(rec)
    return None if profile is None else np.array([profile.at(float(s)) for s in t])


def _recorded_fall(summary: Mapping[str, str], t: float, domain: int, tau: float
                   ) -> Fall | None:
    """The fall of a recording's ``summary`` metadata (``fell``, ``fall_code``; JSON
    strings) at its last /ground_truth row (t s, domain code, tau), None without one (or
    with a code :class:`~hp_model.falls.FallReason` does not know)."""
    if summary.get("fell") != "true":
        return None
    try:
        reason = FallReason(int(summary.get("fall_code", "0")))
    except ValueError:
        return None
    return Fall(reason, float(t), Domain.from_code(int(domain)), float(tau))


__all__ = ["ARROW_COLOUR", "MAX_ARROW", "WalkSeries", "WalkerScene", "arrow_vector",
           "recording_gif", "walker_gif", "walker_poses", "walker_scene", "walker_strip"]
