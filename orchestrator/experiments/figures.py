"""The figures of the paper's Sec. V experiments (fig6, fig7, fig8 as PNG bytes) and the walker
animations of their runs (:func:`write_animations`); the runs are
:mod:`orchestrator.experiments.paper`'s."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from hp_model.atomic_io import atomic_write_bytes
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.figures import figure_bytes
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from orchestrator.experiments.scenarios import ScenarioResult
from prosthesis_controller import ControllerName

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn
    from matplotlib.figure import Figure

#: each controller's colour in the figures
COLOURS: dict[str, str] = {
    ControllerName.CLFQP: "tab:green", ControllerName.PASSIVE: "tab:orange",
    ControllerName.PD: "tab:red", ControllerName.PHASE_PD: "tab:gray",
    ControllerName.CLFQP_PAPER: "tab:purple"}
#: seconds of each run the animations show (the nominal run, each robustness case)
ANIMATION_SECONDS = {"nominal": 6.0, "case": 4.0}
_PS = Domain.PS.code  # ScenarioResult.domain holds domain codes


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def gear_ratios(model: HumanProsthesisModel) -> tuple[float, float]:
    """(knee, ankle) gear ratios of the device config: joint torque = ratio x motor torque."""
    p = model.device.prosthesis
    return float(p.knee.gear_ratio.value), float(p.ankle.gear_ratio.value)


def fig6(runs: dict[str, ScenarioResult], gear: tuple[float, float]) -> bytes:
    """PNG of :func:`fig6_figure`."""
    return figure_bytes(fig6_figure(runs, gear))


def fig6_figure(runs: dict[str, ScenarioResult], gear: tuple[float, float]) -> Figure:
    """Prosthesis motor torques in ps of the exact and the relaxed robust CLF-QP: motor N m
    on the left axis, the joint's (``gear`` ratio times, knee and ankle) on the right."""
    plt = _plt()
    fig, ax = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    for c, col in ((ControllerName.CLFQP_EXACT, "tab:blue"), (ControllerName.CLFQP, "tab:pink")):
        r = runs[c]
        for j in range(2):
            u = np.where(r.domain == _PS, r.torque[:, j], np.nan)
            ax[j].plot(r.t, u, color=col, lw=0.7,
                       label=("exact (eq. robust_CLF_QP)" if c == ControllerName.CLFQP_EXACT
                              else "relaxed (eq. robust_CLF_QP_relax)"))
    for j, name in enumerate(("knee", "ankle")):
        n = gear[j]
        ax[j].set_ylabel(f"{name} motor torque\n(N m, motor side)", fontsize=9)
        sec = ax[j].secondary_yaxis("right", functions=(lambda u, n=n: u * n,
                                                        lambda v, n=n: v / n))
        sec.set_ylabel(f"{name} joint torque (N m)\n= {n:g} x motor (gear ratio)", fontsize=9)
    ax[1].set_xlabel(f"t (s), {Domain.PS} (prosthesis stance) only")
    ax[0].legend(fontsize=7)
    fig.suptitle("Fig. 6: prosthesis torques, exact vs relaxed robust CLF-QP")
    fig.tight_layout()
    return fig


def fig7(runs: dict[str, ScenarioResult], gait: Gait) -> bytes:
    """Phase portraits of the prosthesis knee and ankle, one row per controller."""
    plt = _plt()
    fig, ax = plt.subplots(len(runs), 2, figsize=(10, 3.6 * len(runs)), squeeze=False)
    for row, (c, r) in enumerate(runs.items()):
        for j, name in enumerate(("knee th_pk", "ankle th_pa")):
            a = ax[row, j]
            for d, col, lab in ((Domain.PS, "tab:green", f"{Domain.PS} ({c})"),
                                (Domain.PNS, "tab:pink", f"{Domain.PNS} (swing controller)")):
                y = np.where(r.domain == d.code, r.q_p[:, j], np.nan)
                a.plot(y, np.where(r.domain == d.code, r.qd_p[:, j], np.nan), color=col,
                       lw=0.7, label=lab)
            for d in PAPER_DOMAINS:
                tr = gait.trajectory.get(d)
                if tr is not None:
                    k = 10 + j
                    a.plot(tr["q"][k], tr["qd"][k], "k--", lw=1,
                           label="nominal (gait)" if d is Domain.PS else None)
            a.set_xlabel(f"{name} (rad)")
            a.set_ylabel("velocity (rad/s)")
            state = "completed" if r.success else "FELL"
            a.set_title(f"{c}: prosthesis {name.split()[0]}, {r.steps} steps, {state}",
                        fontsize=9)
        ax[row, 0].legend(fontsize=7)
    fig.suptitle("Fig. 7: phase portraits, nominal human")
    fig.tight_layout()
    return figure_bytes(fig)


def fig8(runs: dict[str, dict[str, ScenarioResult]]) -> bytes:
    """The prosthesis knee in ps of every controller, one panel per perturbed case."""
    plt = _plt()
    fig, ax = plt.subplots(len(runs), 1, figsize=(9, 2.6 * len(runs)), squeeze=False)
    for i, (n, rr) in enumerate(runs.items()):
        a = ax[i, 0]
        longest = max(rr.values(), key=lambda r: r.t.size)  # desired B_pk(tau) along it
        m = longest.domain == _PS
        a.plot(longest.t, np.where(m, longest.knee_ref, np.nan), color="lightblue", lw=2.5,
               zorder=0, label=f"desired (along {longest.scenario.controller})")
        for c, r in rr.items():
            m = r.domain == _PS
            a.plot(r.t, np.where(m, r.q_p[:, 0], np.nan), color=COLOURS[c], lw=0.8,
                   label=f"{c} ({run_outcome(r)})")
            if r.failed and r.fail_t is not None:
                a.axvline(r.fail_t, color=COLOURS[c], ls=":", lw=1)
        a.set_title(n, fontsize=9)
        a.set_ylabel("th_pk (rad)")
        a.legend(fontsize=7, ncol=4)
    ax[-1, 0].set_xlabel(f"t (s), {Domain.PS} only")
    fig.suptitle("Fig. 8: prosthesis knee under perturbed human gaits")
    fig.tight_layout()
    return figure_bytes(fig)


def run_outcome(r: ScenarioResult) -> str:
    """A run's end for a legend: ``ok``, ``fell at 1.18 s, 2 steps``, ``fell at 0.004 s,
    no step`` (a run that never completed a step)."""
    if r.success or r.fail_t is None:
        return "ok" if r.success else f"{r.steps} steps"
    return f"fell at {r.fail_t:.3g} s, " + (f"{r.steps} steps" if r.steps else "no step")


def write_animations(model: HumanProsthesisModel, out: str, nominal: ScenarioResult,
                     cases: Mapping[str, Mapping[str, ScenarioResult]]) -> dict[str, str]:
    """GIFs of the walker (:mod:`orchestrator.experiments.animation`): the nominal `clfqp` run
    and `clfqp` in each robustness case, the first seconds of each; name -> file in ``out``."""
    from orchestrator.experiments.animation import WalkSeries, walker_gif

    runs = [("nominal", "walker_nominal.gif", nominal, "clfqp, nominal human",
             ANIMATION_SECONDS["nominal"])]
    for k, (case, rs) in enumerate(cases.items(), start=1):
        if ControllerName.CLFQP in rs:
            runs.append((case, f"walker_case{k}.gif", rs[ControllerName.CLFQP], f"clfqp, {case}",
                         ANIMATION_SECONDS["case"]))
    files = {}
    for name, fname, r, title, secs in runs:
        if r.q is None or r.t.size == 0:
            continue
        walk = WalkSeries(r.t, r.q, r.domain, r.tau, r.socket_force, r.fall)
        atomic_write_bytes(os.path.join(out, fname),
                           walker_gif(model, walk, title=title, max_seconds=secs))
        files[name] = fname
    return files
