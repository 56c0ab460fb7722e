"""The paper's Fig. 4: the data's Bezier fit against the optimized gait's outputs."""

from __future__ import annotations

import os

import numpy as np

from characterization.gait.person_check import WalkSummary
from characterization.mocap.steps_artifact import StepsArtifact
from hp_model import bezier
from hp_model.atomic_io import atomic_write_bytes
from hp_model.domains import PAPER_DOMAINS
from hp_model.figures import figure_bytes
from hp_model.gait_artifact import Gait

LABELS = {"th_lh": "human hip", "th_lk": "human knee", "th_la": "human ankle",
          "th_rh": "prosthesis-side hip", "th_pk": "prosthesis knee",
          "th_pa": "prosthesis ankle"}


def gait_figure_bytes(gait: Gait, steps: StepsArtifact | None = None, fmt: str = "png") -> bytes:
    """One panel per output (rows) and domain (columns): recorded samples (grey), the
    regression B(alpha_mc) (blue), the regression plus offsets (dashed) and the optimized
    B(alpha*) (red), in degrees against tau."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8.5, 10))
    fig.subplots_adjust(left=0.1, right=0.98, top=0.95, bottom=0.05, hspace=0.35, wspace=0.25)
    axes = fig.subplots(5, 2, sharex=True)
    s = np.linspace(0, 1, 201)
    for col, d in enumerate(PAPER_DOMAINS):
        names = d.y2_coords
        if steps is not None:
            cn = list(steps.coord_names)
            for i in range(steps.n_steps):
                if steps.step_domain[i] != d:
                    continue
                q, tau = steps.step_q(i), steps.step_tau(i)
                for r, n in enumerate(names):
                    axes[r, col].plot(tau, np.degrees(q[:, cn.index(n)]), color="0.8", lw=0.5)
        data = gait.data_params.get(d)
        opt = np.degrees(bezier.evaluate(gait.params[d].alpha, s))
        for r, n in enumerate(names):
            ax = axes[r, col]
            if data is not None:
                fit = np.degrees(bezier.evaluate(data.alpha, s))
                ax.plot(s, fit[:, r], color="tab:blue", lw=1.5, label="data fit")
                off = np.degrees(gait.offsets[d][r]) if d in gait.offsets else 0.0
                ax.plot(s, fit[:, r] + off, color="tab:blue", lw=1, ls="--",
                        label="data fit + offset")
            ax.plot(s, opt[:, r], color="tab:red", lw=1.5, label="optimized")
            ax.set_title(f"{d}: {LABELS[n]}", fontsize=9)
            ax.grid(alpha=0.3)
            if col == 0:
                ax.set_ylabel("deg")
        axes[-1, col].set_xlabel(r"$\tau$")
    axes[0, 0].legend(fontsize=7, loc="best")
    return figure_bytes(fig, fmt)


def save_gait_figure(path: str | os.PathLike[str], gait: Gait,
                     steps: StepsArtifact | None = None) -> None:
    fmt = os.fspath(path).rsplit(".", 1)[-1].lower()
    if fmt not in ("png", "pdf", "svg"):
        raise ValueError(f"{path}: figure format must be png, pdf or svg")
    atomic_write_bytes(path, gait_figure_bytes(gait, steps, fmt))


def person_figure_bytes(take: WalkSummary, gait: WalkSummary, fmt: str = "png") -> bytes:
    """The person's gait against the take (``gait fit --domains multicontact``): the trunk
    pitch and six joint angles over the cycle (take grey, gait red, deg), each foot's
    vertical ground reaction over its stance (in body weights; the take's where it has force
    plates), and the gait's centre of pressure along the sole."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    names = [n for n in take.joint_angles if n in gait.joint_angles]
    fig = Figure(figsize=(10, 9))
    fig.subplots_adjust(left=0.08, right=0.98, top=0.94, bottom=0.06, hspace=0.5, wspace=0.3)
    axes = fig.subplots(4, 3)
    fig.suptitle(f"{gait.source} against {take.source}: speed {gait.speed:.2f} vs "
                 f"{take.speed:.2f} m/s, stride {gait.stride_time:.2f} vs "
                 f"{take.stride_time:.2f} s", fontsize=10)
    for ax, n in zip(axes.flat, names, strict=False):
        s_t = np.linspace(0, 1, len(take.joint_angles[n]))
        s_g = np.linspace(0, 1, len(gait.joint_angles[n]))
        ax.plot(s_t, take.joint_angles[n], color="0.5", lw=2, label="take")
        ax.plot(s_g, gait.joint_angles[n], color="tab:red", lw=1.2, label="gait")
        ax.set_title(LABELS.get(n, "trunk pitch"), fontsize=9)
        ax.set_xlabel("cycle", fontsize=8)
        ax.set_ylabel("deg", fontsize=8)
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=7)
    for ax, foot in zip(axes.flat[len(names):], ("human", "prosthesis"), strict=False):
        g = gait.grf.get(foot)
        if g is not None:
            ax.plot(np.linspace(0, 1, len(g.fz)), g.fz / gait.body_weight, color="tab:red",
                    label="gait F_z")
        t = take.grf.get(foot)
        if t is not None:
            ax.plot(np.linspace(0, 1, len(t.fz)), t.fz / take.body_weight, color="0.5", lw=2,
                    label="force plate")
        ax.set_title(f"{foot} foot: vertical ground reaction", fontsize=9)
        ax.set_xlabel("stance", fontsize=8)
        ax.set_ylabel("body weights", fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    ax = axes.flat[len(names) + 2]
    for spare in axes.flat[len(names) + 3:]:
        spare.set_visible(False)
    for foot, color in (("human", "tab:blue"), ("prosthesis", "tab:red")):
        g = gait.grf.get(foot)
        if g is not None and g.cop_x is not None:
            ax.plot(np.linspace(0, 1, len(g.cop_x)), g.cop_x, color=color, label=foot)
            if g.sole is not None:
                ax.axhline(g.sole[0], color=color, ls=":", lw=0.8)
                ax.axhline(g.sole[1], color=color, ls=":", lw=0.8)
    ax.set_title("centre of pressure along the sole (dotted: heel, toe)", fontsize=9)
    ax.set_xlabel("stance", fontsize=8)
    ax.set_ylabel("m", fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return figure_bytes(fig, fmt)


def save_person_figure(path: str | os.PathLike[str], take: WalkSummary, gait: WalkSummary
                       ) -> None:
    """:func:`person_figure_bytes` written atomically (png, pdf or svg by the extension)."""
    fmt = os.fspath(path).rsplit(".", 1)[-1].lower()
    if fmt not in ("png", "pdf", "svg"):
        raise ValueError(f"{path}: figure format must be png, pdf or svg")
    atomic_write_bytes(path, person_figure_bytes(take, gait, fmt))
