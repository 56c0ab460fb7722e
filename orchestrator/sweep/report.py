"""The report of a sweep folder: ``report.md``, ``report.json`` and figures.

Per controller x family: success rate (a run succeeds when it completes the spec's steps
without a fall) with its Wilson score 95 % interval, knee tracking error (RMS of th_pk -
B_pk(tau) over the run's ps samples, rad) distribution, steps and time walked, failure
reasons, the worst cases with the command that reproduces each; paired comparisons of the
first controller with each other (the controllers meet the same draws: exact McNemar test on
the discordant draws); throughput (runs per minute and workers, per session).

With the walkability label (the ``oracle`` runs,
``orchestrator.experiments.scenarios.ORACLE``) a draw is *walkable* when the oracle walks
it, and every rate, interval and paired test is also given among the walkable draws: a draw
no controller could walk says nothing about a controller.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from hp_model.atomic_io import atomic_write_bytes, atomic_write_text
from hp_model.figures import figure_bytes
from hp_model.json_io import write_json
from orchestrator.sweep.draws import ORACLE, Draw
from orchestrator.sweep.store import ResultStore, read_results

Z95 = 1.959963984540054  # standard normal quantile 0.975
N_WORST = 3
KIND = "hpcosim-sweep-report"


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion k/n (n = 0: (0, 1))."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    lo = 0.0 if k == 0 else max(0.0, centre - half)  # exact ends (no rounding past k/n)
    hi = 1.0 if k == n else min(1.0, centre + half)
    return lo, hi


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar p-value for b and c discordant pairs (binomial, p = 1/2)."""
    n = b + c
    if n == 0:
        return 1.0
    k = min(b, c)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2.0**n
    return min(1.0, 2 * tail)


#: the fall reason of a failed run stored without one (a sweep from before the label)
UNLABELLED = "unlabelled"


def fall_label(row: Mapping[str, Any]) -> str:
    """The kind of a failed run's fall: the :class:`hp_model.falls.FallReason` label stored
    with it (``friction-cone``)."""
    return row.get("fall_reason") or UNLABELLED


def _q(a: list[float], p: float) -> float | None:
    return float(np.percentile(a, p)) if a else None


def replay_command(out: Path, key: str) -> str:
    return f"hpcosim sweep replay {out} {key}"


def cosim_command(out: Path, row: dict[str, Any]) -> str | None:
    """The single co-simulation run of a draw that only perturbs the human's Bezier
    coefficients (the FMU's own generator); None for other draws."""
    from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind
    from prosthesis_controller.gait_tables import LAWS

    d = draw_of(row)
    if not d.is_bezier_only or row["controller"] == ORACLE:
        return None
    gait = out / "artifacts" / "gait.json"
    person = artifact_kind(gait) == MULTICONTACT_KIND  # its co-simulation runs LAWS
    if person and row["controller"] not in LAWS:
        return None
    pert = f" --perturb human:{d.bezier_amplitude!r}:{d.bezier_seed}" \
        if d.bezier_amplitude > 0 else ""
    tube = "" if person else f" --tube {out}/artifacts/tube.json"
    return (f"hpcosim run --controller {row['controller']} --gait {gait}{tube} "
            f"--steps {row['steps_requested']}{pert}")


def draw_of(row: dict[str, Any]) -> Draw:
    """The draw stored in a results row."""
    return Draw.from_columns(row["family"], int(row["draw"]), row)


def _worst_order(r: dict[str, Any]) -> tuple:
    rms = r["knee_rms_ps_rad"]
    return (bool(r["success"]), r["steps_completed"] or 0, r["duration_s"] or 0.0,
            -(rms if rms is not None else math.inf))


def _row_axes(spec: dict[str, Any], rows: list[dict[str, Any]]) -> tuple[list[str], list[str]]:
    """The report's controllers and families: the spec's, then those only in the results
    (they still count), the oracle first when its labels are stored."""
    controllers = list(spec["controllers"])
    families = list(spec["families"])
    for r in rows:  # results of controllers/families no longer in the spec still count
        if r["controller"] not in controllers:
            controllers.append(r["controller"])
        if r["family"] not in families:
            families.append(r["family"])
    if any(r["controller"] == ORACLE for r in rows) and ORACLE not in controllers:
        controllers.insert(0, ORACLE)
    return controllers, families


def _cell(out: Path, c: str, f: str, rs: list[dict[str, Any]],
          walkable: dict[tuple[str, int], bool]) -> dict[str, Any]:
    """The summary of controller ``c`` on family ``f`` (its rows ``rs``): success with Wilson
    intervals (all runs, and the runs the oracle walks), knee RMS, failures, the worst runs."""
    ok = [r for r in rs if r["error"] is None]
    k = sum(bool(r["success"]) for r in ok)
    lo, hi = wilson_interval(k, len(ok))
    rms = [r["knee_rms_ps_rad"] for r in ok if r["knee_rms_ps_rad"] is not None]
    dur = [r["duration_s"] for r in ok]
    worst = sorted(ok, key=_worst_order)[:N_WORST]
    wk = [r for r in ok if walkable.get((f, r["draw"]))]
    kw = sum(bool(r["success"]) for r in wk)
    wlo, whi = wilson_interval(kw, len(wk))
    return {
        "walkable_runs": len(wk), "walkable_successes": kw,
        "walkable_rate": kw / len(wk) if wk else None,
        "walkable_wilson95": [wlo, whi] if wk else None,
        "controller": c, "family": f, "runs": len(rs), "errors": len(rs) - len(ok),
        "error_examples": sorted({r["error"] for r in rs if r["error"]})[:3],
        "successes": k, "success_rate": k / len(ok) if ok else None,
        "wilson95": [lo, hi] if ok else None,
        "steps_completed_mean": (float(np.mean([r["steps_completed"] for r in ok]))
                                 if ok else None),
        "duration_s_median": _q(dur, 50),
        "knee_rms_ps_rad": {"n": len(rms), "median": _q(rms, 50), "p10": _q(rms, 10),
                            "p90": _q(rms, 90),
                            "max": float(max(rms)) if rms else None},
        "torque_finite_all": all(bool(r["torque_finite"]) for r in ok),
        "failure_reasons": dict(Counter(fall_label(r) for r in ok
                                        if r["failed"]).most_common()),
        "worst": [{"key": r["key"], "success": r["success"],
                   "steps_completed": r["steps_completed"],
                   "duration_s": r["duration_s"],
                   "knee_rms_ps_rad": r["knee_rms_ps_rad"], "reason": r["reason"],
                   "draw": {k2: v for k2, v in r.items() if k2.startswith("draw_")},
                   "replay": replay_command(out, r["key"]),
                   "cosim": cosim_command(out, r)} for r in worst]}


def _pair(f: str, a: str, b: str, by_cell: dict[tuple[str, str], list[dict[str, Any]]],
          walkable: dict[tuple[str, int], bool]) -> dict[str, Any]:
    """Controllers ``a`` and ``b`` on the draws of family ``f`` both ran without error:
    the draws only one of them walks, McNemar's exact test (and on the walkable draws)."""
    sa = {r["draw"]: bool(r["success"]) for r in by_cell.get((a, f), [])
          if r["error"] is None}
    sb = {r["draw"]: bool(r["success"]) for r in by_cell.get((b, f), [])
          if r["error"] is None}
    common = sorted(set(sa) & set(sb))
    a_only = sum(sa[i] and not sb[i] for i in common)
    b_only = sum(sb[i] and not sa[i] for i in common)
    entry = {"family": f, "a": a, "b": b, "pairs": len(common),
             "a_only": a_only, "b_only": b_only,
             "mcnemar_p": mcnemar_exact(a_only, b_only)}
    if walkable:
        cw = [i for i in common if walkable.get((f, i))]
        wa = sum(sa[i] and not sb[i] for i in cw)
        wb = sum(sb[i] and not sa[i] for i in cw)
        entry.update(walkable_pairs=len(cw), walkable_a_only=wa,
                     walkable_b_only=wb,
                     walkable_mcnemar_p=mcnemar_exact(wa, wb))
    return entry


def summarize(out: str | Path) -> dict[str, Any]:
    """Everything the report says, as a JSON-able dict."""
    out = Path(out)
    store = ResultStore(out)
    man = store.manifest()
    if man is None:
        raise FileNotFoundError(f"{out}: no sweep here (sweep.json missing)")
    spec = man["spec"]
    rows = read_results(out).to_pylist()
    controllers, families = _row_axes(spec, rows)
    by_cell: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in rows:
        by_cell.setdefault((r["controller"], r["family"]), []).append(r)
    walkable = {(r["family"], r["draw"]): bool(r["success"]) for r in rows
                if r["controller"] == ORACLE and r["error"] is None}
    cells = [_cell(out, c, f, by_cell.get((c, f), []), walkable)
             for f in families for c in controllers]
    ctrl_only = [c for c in controllers if c != ORACLE]
    paired = ([_pair(f, ctrl_only[0], b, by_cell, walkable)
               for f in families for b in ctrl_only[1:]] if len(ctrl_only) > 1 else [])
    sessions = man.get("sessions", [])
    total_done = sum(s.get("runs_done", 0) for s in sessions)
    total_wall = sum(s.get("wall_s", 0.0) for s in sessions)
    n_ctrl = len(spec["controllers"]) + (1 if spec.get("label_walkable", False) else 0)
    expected = n_ctrl * len(spec["families"]) * spec["draws"]
    return {"kind": KIND, "schema_version": 1, "out": str(out), "spec": spec,
            "artifact_hashes": man["artifact_hashes"], "runs_expected": expected,
            "runs_stored": len(rows), "complete": len(rows) >= expected,
            "walkability_labelled": bool(walkable), "cells": cells, "paired": paired,
            "throughput": {"sessions": sessions, "runs_done": total_done,
                           "wall_s": total_wall,
                           "runs_per_min": 60 * total_done / total_wall if total_wall else None}}


# ------------------------------------------------------------------ figures

def figures(summary: dict[str, Any], rows: list[dict[str, Any]]) -> dict[str, bytes]:
    """fig_success.png (rates with Wilson intervals), fig_knee_rms.png (distributions),
    fig_survival.png (fraction of runs still walking over time)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cells = summary["cells"]
    ctrls = list(dict.fromkeys(c["controller"] for c in cells))
    fams = list(dict.fromkeys(c["family"] for c in cells))
    cell = {(c["controller"], c["family"]): c for c in cells}
    out: dict[str, bytes] = {}
    w = 0.8 / max(1, len(ctrls))
    fig, ax = plt.subplots(figsize=(max(5, 1.6 * len(fams) + 2), 3.6))
    for i, c in enumerate(ctrls):
        x = np.arange(len(fams)) + (i - (len(ctrls) - 1) / 2) * w
        rate = [cell[c, f]["success_rate"] or 0.0 for f in fams]
        ci = [cell[c, f]["wilson95"] or [0.0, 0.0] for f in fams]
        err = np.array([[r - lo for r, (lo, _) in zip(rate, ci, strict=True)],
                        [hi - r for r, (_, hi) in zip(rate, ci, strict=True)]])
        ax.bar(x, rate, w, yerr=err, capsize=3, label=c)
    ax.set_xticks(np.arange(len(fams)), fams)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("success rate (Wilson 95 %)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    out["fig_success.png"] = figure_bytes(fig)

    fig, ax = plt.subplots(figsize=(max(5, 1.6 * len(fams) + 2), 3.6))
    data, pos, labels = [], [], []
    for j, f in enumerate(fams):
        for i, c in enumerate(ctrls):
            v = [r["knee_rms_ps_rad"] for r in rows if r["controller"] == c and
                 r["family"] == f and r["knee_rms_ps_rad"] is not None]
            data.append(np.degrees(v) if v else [np.nan])
            pos.append(j + (i - (len(ctrls) - 1) / 2) * w)
            labels.append(c)
    bp = ax.boxplot(data, positions=pos, widths=0.9 * w, patch_artist=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, b in enumerate(bp["boxes"]):
        b.set_facecolor(colors[k % len(ctrls) % len(colors)])
    ax.set_xticks(np.arange(len(fams)), fams)
    ax.set_ylabel("knee RMS error in ps (deg)")
    ax.legend([bp["boxes"][i] for i in range(len(ctrls))], ctrls, fontsize=8)
    fig.tight_layout()
    out["fig_knee_rms.png"] = figure_bytes(fig)

    fig, axs = plt.subplots(1, len(fams), figsize=(3.2 * len(fams) + 1, 3.2), squeeze=False,
                            sharey=True)
    for j, f in enumerate(fams):
        ax = axs[0, j]
        for c in ctrls:
            rs = [r for r in rows if r["controller"] == c and r["family"] == f
                  and r["error"] is None]
            if not rs:
                continue
            tmax = max(r["duration_s"] for r in rs)
            t = np.linspace(0, tmax, 200)
            alive = [np.mean([(r["success"] or r["duration_s"] >= ti) for r in rs])
                     for ti in t]
            ax.plot(t, alive, label=c)
        ax.set_title(f, fontsize=9)
        ax.set_xlabel("time (s)")
        ax.set_ylim(0, 1.05)
    axs[0, 0].set_ylabel("fraction not fallen")
    axs[0, -1].legend(fontsize=8)
    fig.tight_layout()
    out["fig_survival.png"] = figure_bytes(fig)
    return out


# ------------------------------------------------------------------ markdown

def _f(v: Any, fmt: str = ".3g") -> str:
    return "-" if v is None else format(v, fmt)


def _knee_rms_words(out: Path) -> str:
    """What the knee RMS columns measure, for the sweep's gait (its stored artifact)."""
    from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind

    if artifact_kind(out / "artifacts" / "gait.json") == MULTICONTACT_KIND:
        return ("the prosthesis knee against the fitted cycle at the same stride fraction, "
                "over the run's last complete stride (none without one)")
    return "th_pk - B_pk(tau) over the run's ps samples, until the run ended (a fall shortens it)"


def markdown(s: dict[str, Any], figs: list[str]) -> str:
    spec = s["spec"]
    L = [f"# Sweep report: {spec['name']}", ""]
    L.append(f"{s['runs_stored']} of {s['runs_expected']} runs stored"
             + ("" if s["complete"] else " (**incomplete**: rerun the sweep to resume)")
             + f"; controllers {', '.join(spec['controllers'])}; {spec['draws']} draws per "
             f"family; seed {spec['seed']}; {spec['steps']} steps per run; backend "
             f"{spec['backend']}.")
    L += ["", "Artifacts (sha256): " + ", ".join(f"{k} `{v[:12]}`" for k, v in
                                                 s["artifact_hashes"].items() if v), ""]
    L += ["## Families", ""]
    for f, fam in spec["families"].items():
        q = [f"{g}.{k} = {_dist(v)}" for g, grp in fam.items() for k, v in grp.items()
             if v is not None]
        L.append(f"- **{f}**: " + ("; ".join(q) if q else "nominal (no perturbation)"))
    L += ["", "## Success rate and tracking", "",
          "A run succeeds when it completes the requested steps without a fall. Interval: "
          "Wilson score, 95 %. Knee RMS: " + _knee_rms_words(Path(s["out"]))
          + ". Walkable: the draws the `oracle` (full-state feedback linearization of the "
          "prosthesis with perfect knowledge and sensing) "
          "walks; the oracle's own row is the fraction of walkable draws.", "",
          "| family | controller | runs | errors | success | rate | 95 % interval | "
          "walkable: success / runs | rate | 95 % interval | steps (mean) | time walked "
          "median (s) | knee RMS median / p90 / max (deg) |",
          "|---|---|---:|---:|---:|---:|---|---:|---:|---|---:|---:|---|"]
    for c in s["cells"]:
        k = c["knee_rms_ps_rad"]
        deg = [None if k[x] is None else math.degrees(k[x]) for x in ("median", "p90", "max")]
        ci, wci = c["wilson95"], c["walkable_wilson95"]
        L.append(f"| {c['family']} | {c['controller']} | {c['runs']} | {c['errors']} | "
                 f"{c['successes']} | {_f(c['success_rate'], '.3f')} | "
                 + (f"[{ci[0]:.3f}, {ci[1]:.3f}]" if ci else "-")
                 + f" | {c['walkable_successes']} / {c['walkable_runs']} | "
                 f"{_f(c['walkable_rate'], '.3f')} | "
                 + (f"[{wci[0]:.3f}, {wci[1]:.3f}]" if wci else "-")
                 + f" | {_f(c['steps_completed_mean'], '.2f')} | "
                 f"{_f(c['duration_s_median'], '.3f')} | "
                 + " / ".join(_f(d, ".2f") for d in deg) + " |")
    if s["paired"]:
        L += ["", "## Paired comparison (same draws)", "",
              "All draws, then (W) the walkable draws only.", "",
              "| family | A | B | pairs | A succeeds, B falls | B succeeds, A falls | exact "
              "McNemar p | W pairs | W: A only | W: B only | W: p |",
              "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for p in s["paired"]:
            w = (f"{p['walkable_pairs']} | {p['walkable_a_only']} | {p['walkable_b_only']} | "
                 f"{p['walkable_mcnemar_p']:.3g}") if "walkable_pairs" in p else "- | - | - | -"
            L.append(f"| {p['family']} | {p['a']} | {p['b']} | {p['pairs']} | {p['a_only']} "
                     f"| {p['b_only']} | {p['mcnemar_p']:.3g} | {w} |")
    L += ["", "## Failure reasons", ""]
    for c in s["cells"]:
        if c["failure_reasons"]:
            L.append(f"- {c['controller']} / {c['family']}: " + "; ".join(
                f"{n} x {r}" for r, n in c["failure_reasons"].items()))
        if c["errors"]:
            L.append(f"- {c['controller']} / {c['family']}: {c['errors']} run errors, e.g. "
                     + "; ".join(f"`{e}`" for e in c["error_examples"]))
    L += ["", "## Worst cases", "",
          "Ordered by: not completed, fewest steps, earliest end, largest knee RMS. "
          "`hpcosim sweep replay` reruns the run in process and compares it with the stored "
          "row; the `hpcosim run` line (draws that only perturb the human's Bezier "
          "coefficients) is the same human in the co-simulation, whose bus quantizes the "
          "measurements (close, not bit-identical).", ""]
    for c in s["cells"]:
        L.append(f"**{c['controller']} / {c['family']}**")
        L.append("")
        for w in c["worst"]:
            rms = w["knee_rms_ps_rad"]
            L.append(f"- `{w['key']}`: {w['steps_completed']} steps, "
                     f"{_f(w['duration_s'], '.3f')} s, knee RMS "
                     f"{_f(None if rms is None else math.degrees(rms), '.2f')} deg; "
                     f"{w['reason'] or 'completed'}")
            L.append(f"  - `{w['replay']}`")
            if w["cosim"]:
                L.append(f"  - `{w['cosim']}`")
        L.append("")
    tp = s["throughput"]
    L += ["## Throughput", "",
          "| session | status | workers | runs | wall (s) | runs/min | setup (s) |",
          "|---|---|---:|---:|---:|---:|---:|"]
    for se in tp["sessions"]:
        L.append(f"| {se['session']} | {se.get('status', '?')} | {se.get('workers', '-')} | "
                 f"{se.get('runs_done', 0)} | {_f(se.get('wall_s'), '.1f')} | "
                 f"{_f(se.get('runs_per_min'), '.1f')} | {_f(se.get('setup_s'), '.1f')} |")
    L += ["", f"All sessions: {tp['runs_done']} runs in {tp['wall_s']:.1f} s"
          + (f", {tp['runs_per_min']:.1f} runs/min." if tp["runs_per_min"] else "."), ""]
    L += ["## Figures", ""] + [f"![{f}]({f})" for f in figs] + [""]
    return "\n".join(L)


def _dist(v: dict[str, Any]) -> str:
    d = v.get("dist")
    if d == "fixed":
        return f"{v['value']:g}"
    if d == "uniform":
        return f"U({v['low']:g}, {v['high']:g})"
    if d == "normal":
        return f"N({v['mean']:g}, {v['std']:g}^2)"
    return "{" + ", ".join(f"{x:g}" for x in v["values"]) + "}"


def write_report(out: str | Path) -> dict[str, Any]:
    """Write report.md, report.json and the figures into the sweep folder ``out``
    (atomically, file by file); returns the summary."""
    out = Path(out)
    s = summarize(out)
    rows = read_results(out).to_pylist()
    figs = figures(s, rows) if rows else {}
    for name, data in figs.items():
        atomic_write_bytes(out / name, data)
    write_json(out / "report.json", s)
    atomic_write_text(out / "report.md", markdown(s, list(figs)))
    return s
