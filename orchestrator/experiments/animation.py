"""The walker, animated (issue 21): a stick figure of a closed-loop run as a GIF.

From the run's full configuration q (n, 12) and the model's frames (:meth:`hp_model.
HumanProsthesisModel.numeric` ``frames``: x, z of every joint and sole point): the human
(trunk, left leg, the thigh in the iWalk) in blue, the prosthesis (socket to foot) in
orange, the ground, the socket force on the prosthesis as an arrow at the socket (world
frame; 1 m per ``FORCE_SCALE`` N, at most ``MAX_ARROW`` m long, drawn ``ARROW_OFFSET`` m in front
of the socket so that it does not hide the shank, with its magnitude written at its tail), and the
time, domain, phase and step count.  The view follows the hip.  Frames are taken every
``1 / fps`` s of the 1 kHz log and written with matplotlib's Pillow writer (no other
dependency).
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from hp_model.human_prosthesis import HumanProsthesisModel
from orchestrator.loop.walker_figure import FORCE_SCALE, HUMAN, IWALK, PROSTHESIS

MAX_ARROW = 0.45  # m: longer arrows are shortened (direction kept) to stay in the frame
ARROW_OFFSET = 0.15  # m along x: the tail in front of the socket, clear of the shank and of
#: the swing leg (behind the prosthesis while the load peaks, early in stance)
ARROW_COLOUR = "#b00020"


def arrow_vector(fx: float, fz: float) -> tuple[float, float]:
    """The arrow (m) of a world-frame force (N): ``FORCE_SCALE`` N per metre, shortened to
    ``MAX_ARROW`` m with its direction kept."""
    n = math.hypot(fx, fz) / FORCE_SCALE
    k = 1.0 / FORCE_SCALE if n <= MAX_ARROW else MAX_ARROW / n / FORCE_SCALE
    return fx * k, fz * k


def walker_gif(model: HumanProsthesisModel, t: np.ndarray, q: np.ndarray, domain: np.ndarray,
               tau: np.ndarray, socket_force: np.ndarray | None = None, *,
               title: str = "", fps: float = 25.0, max_seconds: float | None = None,
               size: tuple[float, float] = (6.0, 4.0), dpi: int = 100) -> bytes:
    """GIF bytes of the run (module docstring).  ``t`` (n,) s, ``q`` (n, 12), ``domain``
    (n,) 0 = ps / 1 = pns, ``tau`` (n,), ``socket_force`` (n, 3) (F_x, F_z, M_y in the
    prosthesis top link's frame) or None."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import animation
    from matplotlib import pyplot as plt

    t = np.asarray(t, float)
    if t.size == 0:
        raise ValueError("an empty run has nothing to animate")
    end = t[-1] if max_seconds is None else min(t[-1], t[0] + max_seconds)
    times = np.arange(t[0], end + 1e-9, 1.0 / fps)
    idx = np.minimum(np.searchsorted(t, times), t.size - 1)
    fr = model.numeric()["frames"]
    names = list(model.frame_names)
    zero = np.zeros(model.nq)
    pose = np.stack([np.asarray(fr(q[i], zero)[0]) for i in idx])  # (m, 3, frames)
    ib, trunk = model.coord_names.index("th_B"), model.subject.lengths.trunk
    pitch_row = model.pitch_row("socket")
    steps = np.concatenate([[0], np.cumsum(np.diff(np.asarray(domain)) != 0)])

    fig, ax = plt.subplots(figsize=size, dpi=dpi)
    ax.set_aspect("equal")
    ax.set_ylim(-0.05, 1.55)
    ax.set_yticks([])
    ax.axhline(0.0, color="#5a4a3a", lw=2)
    lines = []
    for colour, chains in (HUMAN, IWALK, PROSTHESIS):
        for _ in chains:
            (ln,) = ax.plot([], [], "-o", color=colour, lw=3, ms=3)
            lines.append(ln)
    (head,) = ax.plot([], [], "-o", color=HUMAN[0], lw=4, ms=3)
    # annotation_clip=False: an annotation whose point leaves the axes is not drawn at all
    arrow = ax.annotate("", xy=(0, 0), xytext=(0, 0), annotation_clip=False,
                        arrowprops={"arrowstyle": "-|>", "color": ARROW_COLOUR, "lw": 2.5,
                                    "mutation_scale": 14})
    force_label = ax.text(0, 0, "", color=ARROW_COLOUR, fontsize=9, ha="left", va="bottom")
    label = ax.text(0.01, 0.97, "", transform=ax.transAxes, va="top", fontsize=10)
    ax.set_title(title, fontsize=10)

    def draw(k: int) -> Sequence[object]:
        p = pose[k]
        xy = {n: (p[0, j], p[1, j]) for j, n in enumerate(names)}
        li = 0
        for _, chains in (HUMAN, IWALK, PROSTHESIS):
            for chain in chains:
                lines[li].set_data([xy[n][0] for n in chain], [xy[n][1] for n in chain])
                li += 1
        qi = q[idx[k]]
        hx, hz = xy["hip"]
        th = qi[ib]
        head.set_data([hx, hx + trunk * math.sin(th)], [hz, hz + trunk * math.cos(th)])
        if socket_force is not None:
            fx, fz = socket_force[idx[k], 0], socket_force[idx[k], 1]
            a = float(pitch_row @ qi)  # top link's world pitch
            wx = math.cos(a) * fx + math.sin(a) * fz  # rotation about +y
            wz = -math.sin(a) * fx + math.cos(a) * fz
            sx, sz = xy["socket"]
            sx += ARROW_OFFSET
            dx, dz = arrow_vector(wx, wz)
            arrow.xy = (sx + dx, sz + dz)
            arrow.set_position((sx, sz))
            force_label.set_position((sx + 0.02, sz))
            force_label.set_text(f"F_s {math.hypot(fx, fz):.0f} N")
        ax.set_xlim(hx - 1.0, hx + 1.0)
        d = "ps" if domain[idx[k]] == 0 else "pns"
        label.set_text(f"t {t[idx[k]]:.2f} s  {d}  tau {tau[idx[k]]:.2f}  "
                       f"step {int(steps[idx[k]])}")
        return (*lines, head, arrow, force_label, label)

    anim = animation.FuncAnimation(fig, draw, frames=len(idx), blit=False)
    with tempfile.TemporaryDirectory() as tmp:  # Pillow's writer wants a file name
        path = Path(tmp) / "walker.gif"
        anim.save(str(path), writer=animation.PillowWriter(fps=fps))
        data = path.read_bytes()
    plt.close(fig)
    return data


def recording_gif(path: str | Path, model: HumanProsthesisModel, *, fps: float = 25.0,
                  max_seconds: float | None = None) -> bytes:
    """GIF of a co-simulation recording's walk, from its ``/ground_truth`` channel (q, domain,
    tau, socket force every tick).  A recording without it is a
    :class:`~orchestrator.cosim.recording.RecordingError`."""
    from bus_schemas.mcap_schemas import read_messages
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
    dom = np.array([0 if o["domain"] == "ps" else 1 for o in rows])
    tau = np.array([o["tau"] for o in rows], float)
    fs = np.array([[o["socket_force"][k] for k in ("Fx", "Fz", "My")] for o in rows], float)
    ctrl = rec.config.get("controller", "")
    return walker_gif(model, t, q, dom, tau, fs, fps=fps, max_seconds=max_seconds,
                      title=f"{Path(path).name}" + (f" ({ctrl})" if ctrl else ""))


__all__ = ["ARROW_COLOUR", "MAX_ARROW", "arrow_vector", "recording_gif", "walker_gif"]
