"""``hpcosim experiments`` of a multi-contact gait (issue 37): the person's gait in closed
loop with the prosthesis on each of its controllers, and under the perturbation families.

- **Nominal walks** (in the in-process plant: AMPRO3's sensors, the torque held 1 ms within
  the motors, the human on its feedback linearization): the held oracle (full-state, the
  reference), ``clfqp`` (the product's controller), ``contact-pd`` (the phase PD) and the
  paper's baselines on this graph, ``pd`` and ``passive`` (the paper's joint PD and robust
  passivity-based law in stance, contact-pd's swing), each for ``steps`` steps. Per
  controller: the steps, the stride and speed (median, from the human foot's heel strikes),
  the prosthesis knee's and ankle's RMS deviation over the last stride from the fitted cycle
  at the same stride fraction (deg), the peak motor torques and the ticks that fell back.
- **Perturbation families** (:mod:`orchestrator.experiments.contact_perturbations`, each at
  its :data:`AMPLITUDE`): the same draws for every controller; per family the walks of
  ``FAMILY_STEPS`` steps out of ``draws`` with the 95 % Wilson interval.
- ``metrics.json``, ``person.png`` (the last stride's knee, ankle and prosthesis foot load
  against the fitted cycle), ``walker.gif`` and ``walker_stride.png`` (``clfqp``'s walk: its
  first 3 s, and 9 poses across its last stride) and ``report.md`` in the output folder.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import binomtest

from characterization.gait.contact_gait import GAINS, ContactWalk, held_oracle, start_state
from characterization.gait.multicontact import GRAPH
from characterization.tube.contact_playback import share_inside
from hp_model.atomic_io import atomic_write_bytes, atomic_write_text
from hp_model.domains import PROSTHESIS, Domain
from hp_model.figures import figure_bytes
from hp_model.force_tube import ForceTube, ModelErrorBound
from hp_model.json_io import dumps
from hp_model.simulator import SimResult
from orchestrator.cosim.contact_controllers import (
    ContactRun,
    LoopSetup,
    held_walk,
    load_contact_run,
    loop_simulator,
)
from orchestrator.experiments.animation import WalkSeries, walker_gif, walker_strip
from orchestrator.experiments.contact_perturbations import (
    CONTROLLERS,
    FAMILIES,
    family_walks,
    perturbed_controllers,
)
from orchestrator.experiments.contact_walk import contact_walk_of, controller_run
from orchestrator.loop.plant import wrench_rows

#: steps of each perturbed walk
FAMILY_STEPS = 10
#: each family's amplitude (:mod:`orchestrator.experiments.contact_perturbations`): 1, but the
#: human's posture at 0.3 (its joints' curves offset by N(0, 0.3 deg): docs/gait-design.md's
#: table; at 1 deg the full-state oracle itself walked 1 draw of 10 on both takes, the
#: simulated person's fragility, issue 38, not the prosthesis's)
AMPLITUDE = {"posture": 0.3}
#: the order the walks are reported in
NAMES = CONTROLLERS
#: the fitted cycle from the human foot's heel strike: the domains in that order
FROM_HEEL_STRIKE = (Domain.DS_H, Domain.PNS, Domain.PNS_TOE, Domain.DS_P, Domain.PS,
                    Domain.PS_TOE)


@dataclass(frozen=True)
class ControllerWalk:
    """One controller's nominal walk and what it measured (module docstring)."""

    name: str
    walk: ContactWalk
    knee_rms: float  # deg, last stride against the fitted cycle
    ankle_rms: float
    peak_torque: tuple[float, float]  # motor N m (knee, ankle)
    fallbacks: int

    def to_json(self) -> dict[str, Any]:
        return {"walk": self.walk.to_json(), "knee_rms_deg": self.knee_rms,
                "ankle_rms_deg": self.ankle_rms, "peak_torque": list(self.peak_torque),
                "fallbacks": self.fallbacks}


def fitted_stride(run: ContactRun) -> tuple[np.ndarray, np.ndarray]:
    """The fitted cycle from the human foot's heel strike: stride fraction (n,) and the
    prosthesis (knee, ankle) angles (n, 2), rad."""
    idx = [run.model.coord_names.index(c) for c in PROSTHESIS]
    t0, ts, qs = 0.0, [], []
    for d in FROM_HEEL_STRIKE:
        tr = run.trajectory[d]
        t = np.asarray(tr["t"], float)
        ts.append(t0 + t)
        qs.append(np.asarray(tr["q"], float)[idx].T)
        t0 += float(t[-1])
    s = np.concatenate(ts) / t0
    return s, np.concatenate(qs)


def last_stride(res: SimResult) -> slice | None:
    """The samples of the run's last complete stride (heel strike to heel strike of the
    human foot), None without one."""
    strikes = [i.t for i in res.impacts if i.into == Domain.DS_H]
    if len(strikes) < 2:
        return None
    k0, k1 = np.searchsorted(res.t, strikes[-2]), np.searchsorted(res.t, strikes[-1])
    return slice(int(k0), int(k1))


def stride_rms(res: SimResult, run: ContactRun) -> tuple[float, float]:
    """The prosthesis knee's and ankle's RMS deviation (deg) over the last stride from the
    fitted cycle at the same stride fraction (NaN without a complete stride)."""
    span = last_stride(res)
    if span is None:
        return float("nan"), float("nan")
    idx = [run.model.coord_names.index(c) for c in PROSTHESIS]
    t = res.t[span]
    s = (t - t[0]) / (res.t[span.stop] - t[0])
    s_fit, q_fit = fitted_stride(run)
    ref = np.column_stack([np.interp(s, s_fit, q_fit[:, j]) for j in range(2)])
    err = np.degrees(res.q[span][:, idx] - ref)
    return float(np.sqrt(np.mean(err[:, 0] ** 2))), float(np.sqrt(np.mean(err[:, 1] ** 2)))


def nominal_walks(run: ContactRun, steps: int, model_error: ModelErrorBound | None = None
                  ) -> tuple[dict[str, ControllerWalk], dict[str, SimResult], dict[str, Any]]:
    """The controllers' nominal walks (module docstring), their logs and the
    controllers (ValueError if the held oracle falls in the stride the tables read);
    ``model_error``: ``clfqp``'s robust term (the tube's bound)."""
    sim = loop_simulator(run.model, run.gait, GAINS)
    setup = LoopSetup(sim, held_walk(sim, run.trajectory))
    ctls = perturbed_controllers(run.model, run.gait, run.trajectory, setup, model_error)
    logs: dict[str, SimResult] = {}
    walks: dict[str, ControllerWalk] = {}
    for name in NAMES:
        if name == "oracle":
            q0, qd0 = start_state(run.trajectory)
            res = sim.run(q0, qd0, GRAPH.domains[0], steps=steps, duration=2.0 * steps,
                          policy=held_oracle(sim.cl, run.gait.thetas(), sim.gains))
            fallbacks = 0
        else:
            ctls[name].reset()
            res = controller_run(sim, run.trajectory, ctls[name], steps)
            fallbacks = int(ctls[name].fallbacks)
        logs[name] = res
        knee, ankle = stride_rms(res, run)
        peak = np.abs(res.u[:, 4:6]).max(axis=0) if res.u.size else np.zeros(2)
        walks[name] = ControllerWalk(name, contact_walk_of(res, steps, name), knee, ankle,
                                     (float(peak[0]), float(peak[1])), fallbacks)
    return walks, logs, ctls


def wilson(k: int, n: int) -> tuple[float, float]:
    """The 95 % Wilson score interval of k successes in n."""
    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    return float(ci.low), float(ci.high)


def family_table(run: ContactRun, controllers: Mapping[str, Any], draws: int,
                 progress: Callable[[str], None] | None = None) -> dict[str, dict[str, int]]:
    """Per family (:data:`FAMILIES`, at its :data:`AMPLITUDE`), the walks of
    :data:`FAMILY_STEPS` steps out of ``draws`` per controller (``controllers``:
    :func:`nominal_walks`'), on the same draws."""
    durations = {d: float(np.asarray(run.trajectory[d]["t"])[-1]) for d in GRAPH.domains}
    table = {}
    for family in FAMILIES:
        if progress is not None:
            progress(f"perturbation family {family}: {draws} draws")
        table[family] = family_walks(run.model, run.trajectory, durations, family,
                                     AMPLITUDE.get(family, 1.0), draws, FAMILY_STEPS,
                                     controllers=controllers)
    return table


def figure(run: ContactRun, logs: Mapping[str, SimResult]) -> bytes:
    """``person.png``: the last stride's prosthesis knee and ankle against the fitted cycle,
    and the prosthesis foot's normal force, per controller."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s_fit, q_fit = fitted_stride(run)
    idx = [run.model.coord_names.index(c) for c in PROSTHESIS]
    rows = wrench_rows(run.model)
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
    ax[0].plot(100 * s_fit, np.degrees(q_fit[:, 0]), "k", lw=2.5, label="fitted gait")
    ax[1].plot(100 * s_fit, np.degrees(q_fit[:, 1]), "k", lw=2.5, label="fitted gait")
    for name, res in logs.items():
        span = last_stride(res)
        if span is None:
            continue
        t = res.t[span]
        s = 100 * (t - t[0]) / (res.t[span.stop] - t[0])
        for j in range(2):
            ax[j].plot(s, np.degrees(res.q[span][:, idx[j]]), label=name)
        load = [res.lam[k, r.load] if (r := rows[Domain.from_code(int(c))]).load is not None
                else 0.0 for k, c in zip(range(span.start, span.stop), res.domain[span],
                                         strict=True)]
        ax[2].plot(s, np.asarray(load) / (run.model.tree.total_mass * run.model.tree.gravity),
                   label=name)
    for a, title in zip(ax, ("prosthesis knee (deg)", "prosthesis ankle (deg)",
                             "prosthesis foot normal force (body weights)"), strict=True):
        a.set_title(title)
        a.set_xlabel("stride (% from the human heel strike)")
        a.grid(alpha=0.3)
    ax[0].legend()
    fig.tight_layout()
    return figure_bytes(fig)


def walk_series(run: ContactRun, res: SimResult) -> WalkSeries:
    """The walker's series of a run (the socket force from each domain's wrench rows)."""
    rows = wrench_rows(run.model)
    fs = np.array([res.lam[k, rows[Domain.from_code(int(c))].socket]
                   for k, c in enumerate(res.domain)])
    return WalkSeries(res.t, res.q, res.domain, res.tau, fs, res.fall)


def walker_files(run: ContactRun, res: SimResult, out: Path, frames: int = 9) -> None:
    """``walker.gif`` (the first 3 s of ``res``) and ``walker_stride.png`` (``frames`` poses
    evenly across its last stride, side by side) in ``out``."""
    walk = walk_series(run, res)
    atomic_write_bytes(out / "walker.gif", walker_gif(run.model, walk, title="clfqp",
                                                      max_seconds=3.0))
    span = last_stride(res)
    if span is not None:
        rows = np.linspace(span.start, span.stop - 1, frames).round().astype(int)
        atomic_write_bytes(out / "walker_stride.png", walker_strip(run.model, walk, rows))


def report(metrics: Mapping[str, Any]) -> str:
    """``report.md`` of the metrics."""
    lines = [f"# The person's gait in closed loop: {metrics['gait']}", "",
             f"Nominal walks, {metrics['steps']} steps asked (in-process plant: AMPRO3's "
             "sensors, the torque held 1 ms within the motors, the human on its feedback "
             "linearization). Knee and ankle: RMS over the last stride against the fitted "
             "cycle at the same stride fraction.", "",
             "| controller | steps | stride (s) | speed (m/s) | knee RMS (deg) | ankle RMS "
             "(deg) | peak motor torque knee / ankle (N m) | fallbacks | how it ended |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    fit = metrics["fitted"]
    for name in NAMES:
        w = metrics["nominal"][name]
        walk = w["walk"]
        stride = np.median(walk["strides"]) if len(walk["strides"]) else None
        speed = np.median(walk["speeds"]) if len(walk["speeds"]) else None
        lines.append(f"| {name} | {walk['steps']} | {table_cell(stride, 3)} | "
                     f"{table_cell(speed, 3)} | {table_cell(w['knee_rms_deg'], 2)} | "
                     f"{table_cell(w['ankle_rms_deg'], 2)} | "
                     f"{w['peak_torque'][0]:.2f} / {w['peak_torque'][1]:.2f} | "
                     f"{w['fallbacks']} | {walk['fall'] or 'walked'} |")
    lines += ["", f"The fitted gait: stride {fit['stride_time']:.3f} s, "
              f"{fit['speed']:.3f} m/s.", ""]
    tube = metrics.get("tube")
    if tube is not None:
        shares = ", ".join(f"{n} " + ("-" if (v := tube["inside"][n]) is None else
                                      f"{100 * v:.0f} %") for n in NAMES)
        lines += [f"Socket force inside the force tube (`tube fit`, stance phase "
                  f"{tube['tau'][0]:.3f}-{tube['tau'][1]:.3f}), share of the flat single "
                  f"support's periods: {shares}. "
                  + ("`clfqp`'s CLF row carries the tube's bound of its model's error (its "
                     "robust term, in the tube's phase range of the flat single support)"
                     if tube.get("robust_term") else
                     "The tube carries no bound of `clfqp`'s model error, so `clfqp` has no "
                     "robust term")
                  + "; the share says how far the nominal walks' socket force stays within "
                  "what the recorded steps spanned.", ""]
    lines += [ "![the last stride](person.png)", "",
              "`clfqp`'s walk: `walker.gif` (its first 3 s) and its last stride in 9 poses:",
              "", "![clfqp's last stride](walker_stride.png)", "",
              f"Perturbation families ({metrics['draws']} draws each, the same draws for "
              f"every controller, {FAMILY_STEPS} steps asked; "
              "`orchestrator/experiments/contact_perturbations.py` defines them; the oracle "
              "reads the plant's state, so the sensor families do not perturb it). Walks, "
              "and the 95 % Wilson interval of the rate:", "",
              "| family (amplitude) | " + " | ".join(NAMES) + " |",
              "|---|" + "---:|" * len(NAMES)]
    for family, row in metrics["families"].items():
        cells = []
        for name in NAMES:
            k = row[name]
            lo, hi = wilson(k, metrics["draws"])
            cells.append(f"{k}/{metrics['draws']} ({100 * lo:.0f}-{100 * hi:.0f} %)")
        lines.append(f"| {family} ({AMPLITUDE.get(family, 1.0):g}) | " + " | ".join(cells)
                     + " |")
    return "\n".join(lines) + "\n"


def table_cell(v: float | None, digits: int) -> str:
    """A table cell of a number, "-" where there is none (no complete stride)."""
    return "-" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


def run_person_experiments(gait_path: str | os.PathLike[str], out: Path, steps: int = 20,
                           draws: int = 10, progress: Callable[[str], None] | None = None,
                           tube: ForceTube | None = None) -> dict[str, Any]:
    """The experiments of the module docstring on the multi-contact gait file, written to
    ``out`` (created); the metrics.  With the gait's ``tube`` (``tube fit``), each nominal
    walk's share of flat single-support periods with the socket force inside it, and
    ``clfqp``'s robust term from its model-error bound when it carries one."""
    say = progress or (lambda _m: None)
    say("reading the gait")
    run = load_contact_run(gait_path)
    say(f"nominal walks: {', '.join(NAMES)}, {steps} steps")
    model_error = tube.model_error if tube is not None else None
    walks, logs, ctls = nominal_walks(run, steps, model_error)
    families = family_table(run, ctls, draws, say) if draws > 0 else {}
    stride_time = sum(float(np.asarray(run.trajectory[d]["t"])[-1]) for d in GRAPH.domains)
    metrics = {"gait": Path(gait_path).name, "steps": steps, "draws": draws,
               "fitted": {"stride_time": stride_time, "speed": _cycle_speed(run, stride_time)},
               "nominal": {n: w.to_json() for n, w in walks.items()},
               "families": families,
               "amplitudes": {f: AMPLITUDE.get(f, 1.0) for f in families}}
    if tube is not None:
        metrics["tube"] = {"gait_hash": tube.gait_hash, "tau": [tube.tau_lo, tube.tau_hi],
                           "robust_term": model_error is not None,
                           "inside": {n: share_inside(tube, run.model, logs[n])
                                      for n in NAMES}}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / "person.png", figure(run, logs))
    say("the walker: walker.gif, walker_stride.png")
    walker_files(run, logs["clfqp"], out)
    atomic_write_text(out / "metrics.json", dumps(metrics, indent=1) + "\n")
    atomic_write_text(out / "report.md", report(metrics))
    return metrics


def _cycle_speed(run: ContactRun, stride_time: float) -> float:
    """The fitted cycle's speed (m/s): the base's travel over the stride."""
    x0 = float(np.asarray(run.trajectory[GRAPH.domains[0]]["q"])[0, 0])
    x1 = float(np.asarray(run.trajectory[GRAPH.domains[-1]]["q"])[0, -1])
    return (x1 - x0) / stride_time
