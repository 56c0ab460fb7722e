"""QA report (Markdown + JSON) and figures of a processed take, written next to the steps file.

Report: steps found per domain, steps dropped and why, frames from each pitch source per
limb, gaps filled and left, joint-centre fits (residual, rotation, well-posedness), notes;
every number rounded to its meaning (:data:`DIGITS`), in the Markdown and the JSON alike.
Figures: joint angles of every step over tau (one panel per coordinate and domain) and phase
portraits (angle vs. angular velocity) of the prosthesis knee and ankle per step, drawn with
Pillow (``plot.py``: matplotlib took 1.2 s of the stage's 2 s budget).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from characterization.mocap.foot_contact import double_supports, strides
from characterization.mocap.limb_angles import SOURCE_NAMES, LimbPitch
from characterization.mocap.pipeline import ProcessedTake
from hp_model import COORDS
from hp_model.atomic_io import atomic_write_bytes
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.json_io import dumps

if TYPE_CHECKING:
    from characterization.mocap.session import TakeOutcome

ANGLES = ("th_B", "th_lh", "th_lk", "th_la", "th_rh", "th_pk", "th_pa")

#: decimals each kind of number is reported to, Markdown and JSON alike ("rounded to its
#: meaning"): angles 0.1 deg, lengths 0.1 mm (residuals in mm; the joint-centre offsets in
#: m, 4 decimals), times 1 ms, speeds 1 mm/s, lab directions 0.001, rates 0.001 Hz, forces
#: 0.1 N; frames are integers, or 0.1 frame where they are differences from the lab's events
DIGITS = {"deg": 1, "mm": 1, "m": 4, "s": 3, "m_s": 3, "unit": 3, "hz": 3, "n": 1}


def _r(x: float | None, kind: str) -> float | None:
    """``x`` rounded to its kind's decimals (:data:`DIGITS`); None if None or not finite."""
    if x is None or not np.isfinite(x):
        return None
    return round(float(x), DIGITS[kind])


def _rv(v: np.ndarray | list[float], kind: str) -> list[float | None]:
    return [_r(x, kind) for x in np.ravel(v)]


def _f(x: float | None, spec: str) -> str:
    """``x`` formatted with ``spec``; "-" for none."""
    return "-" if x is None else format(x, spec)


def _limb_summary(lp: LimbPitch, rate: float) -> dict[str, object]:
    filled = [g for g in lp.gaps if g.filled]
    left = [g for g in lp.gaps if not g.filled]
    return {
        "frames": lp.counts(),
        "marker_pair_offset_deg": _r(np.degrees(lp.pair_offset), "deg"),
        "gaps_filled": len(filled), "frames_filled": sum(g.length for g in filled),
        "gaps_unfilled": len(left), "frames_unfilled": sum(g.length for g in left),
        "longest_unfilled_s": _r(max((g.length for g in left), default=0) / rate, "s"),
    }


def gait_events(p: ProcessedTake) -> dict[str, list[dict[str, object]]]:
    """The take's strides (the prosthesis foot's, :func:`foot_contact.strides`: time,
    speed, its two double supports) and every double support (lands, frames, s): the
    targets a fitted gait must match."""
    st = strides(p.contacts, p.q[:, COORDS.index("x_B")], p.frame_rate)
    return {
        "strides": [{"foot": s.foot, "start": s.start, "end": s.end,
                     "stride_time_s": _r(s.time, "s"), "speed_m_s": _r(s.speed, "m_s"),
                     "double_support_s": {f: _r(v, "s") for f, v in s.double_support.items()}}
                    for s in st],
        "double_supports": [{"lands": d.lands, "start": d.start, "end": d.end,
                             "seconds": _r(d.seconds, "s")}
                            for d in double_supports(p.contacts, p.frame_rate)]}


def qa_summary(p: ProcessedTake) -> dict[str, object]:
    """The QA numbers as plain data (JSON-ready), each rounded to its meaning
    (:data:`DIGITS`)."""
    rate = p.frame_rate
    limbs = {k: _limb_summary(lp, rate) for k, lp in p.pitches.items()}
    joints = {j: {"residual_mm": _r(f.residual_rms * 1000, "mm"),
                  "rotation_sd_deg": _r(np.degrees(f.rotation_sd), "deg"), "frames": f.frames,
                  "well_posed": f.well_posed, "lambda_proximal_m": _rv(f.lam1, "m"),
                  "lambda_distal_m": _rv(f.lam2, "m"), "message": f.message}
              for j, f in p.joints.items()}
    return {
        "source": p.source, "frames": len(p.time), "frame_rate_hz": _r(rate, "hz"),
        "walking_direction_lab": _rv(p.frame.forward, "unit"),
        "up_lab": _rv(p.frame.up, "unit"),
        "steps": {d: sum(s.domain == d for s in p.steps) for d in PAPER_DOMAINS},
        "steps_without_single_support": sum(s.single_support is None for s in p.steps),
        "dropped": [{"domain": d.domain, "start": d.start, "end": d.end, "reason": d.reason}
                    for d in p.dropped],
        "limbs": limbs, "joints": joints, "warnings": list(p.warnings),
        "notes": list(p.notes),
        "force_plates": None if p.plates is None else {
            "source": p.plates.source,
            "full_stances": {f: s.count for f, s in p.plates.feet.items()},
            "weight_n": _r(p.plates.weight, "n"), "whole_strides": p.plates.strides},
        "segmentation": p.segmentation,
        "step_intervals": [{"domain": st.domain, "start": st.start, "end": st.end,
                            "t_start_s": _r(p.time[st.start], "s"),
                            "t_end_s": _r(p.time[st.end], "s")} for st in p.steps],
        "contacts": {f: {"touchdowns": list(c.touchdowns), "liftoffs": list(c.liftoffs),
                         "ground_speed_m_s": _r(c.ground_speed, "m_s"),
                         "stride_time_s": _r(c.stride_time, "s"), "source": c.source,
                         "liftoffs_moved_by_roll_frames": list(c.rolled)}
                     for f, c in p.contacts.items()},
        "lab_events": p.lab_events,
        **gait_events(p),
    }


def _vec(v: list[float]) -> str:
    return "[" + ", ".join(f"{x:.3f}" for x in v) + "]"


def _header(s: dict) -> list[str]:
    return [f"# Motion-capture QA: {Path(s['source']).name}", "",
            f"{s['frames']} frames at {s['frame_rate_hz']:g} Hz; walking direction (lab) "
            f"{_vec(s['walking_direction_lab'])}, up {_vec(s['up_lab'])}.", "",
            "Steps kept: " + ", ".join(f"{s['steps'][d]} {d}" for d in PAPER_DOMAINS) + " "
            f"({s['steps_without_single_support']} without a detected single-support part);"
            f" dropped: {len(s['dropped'])}.", ""]


def _tables(s: dict) -> list[str]:
    """The dropped steps, the limbs' pitch sources and the joint centres."""
    lines = []
    if s["dropped"]:
        lines += ["| dropped | frames | reason |", "|---|---|---|"]
        lines += [f"| {d['domain']} | {d['start']}-{d['end']} | {d['reason']} |"
                  for d in s["dropped"]]
        lines.append("")
    names = list(SOURCE_NAMES.values())
    lines += ["## Limb pitch sources (frames)", "",
              "| limb | " + " | ".join(names) + " | gaps filled (frames) | gaps left (frames) "
              "| pair offset (deg) |", "|---" * (len(names) + 4) + "|"]
    for k, v in s["limbs"].items():
        lines.append(f"| {k} | " + " | ".join(str(v["frames"][n]) for n in names)
                     + f" | {v['gaps_filled']} ({v['frames_filled']}) | {v['gaps_unfilled']} "
                     f"({v['frames_unfilled']}) | {_f(v['marker_pair_offset_deg'], '.1f')} |")
    lines += ["", "## Joint centres", "",
              "| joint | residual (mm RMS) | rotation SD (deg) | frames | well posed |",
              "|---|---|---|---|---|"]
    for j, v in s["joints"].items():
        lines.append(f"| {j} | {_f(v['residual_mm'], '.1f')} | {_f(v['rotation_sd_deg'], '.1f')} | "
                     f"{v['frames']} | {'yes' if v['well_posed'] else 'NO'} |")
    return lines


def _contact_line(foot: str, c: dict) -> str:
    stride = c["stride_time_s"]
    rolled = c["liftoffs_moved_by_roll_frames"]
    return (f"- {foot} ({c['source']}): touchdowns {c['touchdowns']}, lift-offs "
            f"{c['liftoffs']} (ground {_f(c['ground_speed_m_s'], '+.2f')} m/s, stride "
            + (f"{stride:.2f} s)" if stride is not None else "not found)")
            + (f"; lift-offs moved by the foot's roll over its toes: "
               f"{', '.join(f'+{k}' for k in rolled)} frames" if rolled else ""))


def _events(s: dict) -> list[str]:
    """The steps, the feet's contacts and the found events against the lab's."""
    lines = ["", f"## Steps (segmentation: {s['segmentation']})", "",
             "| step | domain | frames | time (s) |", "|---|---|---|---|"]
    lines += [f"| {k} | {v['domain']} | {v['start']}-{v['end']} | {_f(v['t_start_s'], '.3f')}-"
              f"{_f(v['t_end_s'], '.3f')} |" for k, v in enumerate(s["step_intervals"])]
    if s["contacts"]:
        lines += ["", "## Foot contact from the markers (touchdown / lift-off frames)", ""]
        lines += [_contact_line(f, c) for f, c in s["contacts"].items()]
    lines += _gait_lines(s)
    if s["lab_events"]:
        lines += ["", "## Found events against the lab's (frames, found - lab)", "",
                  "| foot | event | in the file | max abs | median abs |", "|---|---|---|---|---|"]
        for foot, kinds in s["lab_events"].items():
            for kind, v in kinds.items():
                lines.append(f"| {foot} | {kind} | {v['lab_events']} | "
                             f"{_f(v['max_abs_frames'], '.1f')} | "
                             f"{_f(v['median_abs_frames'], '.1f')} |")
    return lines


def _gait_lines(s: dict) -> list[str]:
    """The strides and double supports (ms) of the take, the gait's targets."""
    lines = ["", "## Strides and double supports (the gait's targets)", ""]
    if s["strides"]:
        feet = list(s["strides"][0]["double_support_s"])
        lines += ["| stride | frames | time (s) | speed (m/s) | "
                  + " | ".join(f"double support, {f} lands (ms)" for f in feet) + " |",
                  "|---" * (4 + len(feet)) + "|"]
        lines += [f"| {k} ({v['foot']}) | {v['start']}-{v['end']} | "
                  f"{_f(v['stride_time_s'], '.3f')} | {_f(v['speed_m_s'], '.2f')} | "
                  + " | ".join(_ms(v["double_support_s"][f]) for f in feet) + " |"
                  for k, v in enumerate(s["strides"])]
    else:
        lines.append("No full stride (two touchdowns of the prosthesis foot) in the take.")
    if s["double_supports"]:
        lines += ["", "Double supports: " + ", ".join(
            f"{d['lands']} lands {d['start']}-{d['end']} ({_ms(d['seconds'])} ms)"
            for d in s["double_supports"]) + "."]
    return lines


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{1000 * x:.0f}"


def qa_markdown(summary: dict) -> str:
    """The QA report in Markdown: every number to its meaning (:data:`DIGITS`)."""
    s = summary
    lines = _header(s) + _tables(s) + _events(s)
    if s["warnings"]:
        lines += ["", "## Warnings", ""] + [f"- {w}" for w in s["warnings"]]
    lines += ["", "## Notes", ""] + [f"- {n}" for n in s["notes"]]
    return "\n".join(lines) + "\n"


def figures(p: ProcessedTake) -> dict[str, bytes]:
    """PNG bytes of the joint-angle and phase-portrait figures."""
    from characterization.mocap import plot

    out = {}
    fig = plot.Figure(1260, 495, 2, len(ANGLES))
    for r, dom in enumerate(PAPER_DOMAINS):
        steps = [s for s in p.steps if s.domain == dom]
        for c, name in enumerate(ANGLES):
            col = COORDS.index(name)
            segs = [np.column_stack([s.tau, np.degrees(p.q[s.start:s.end + 1, col])])
                    for s in steps]
            fig.panel(r, c, segs, [plot.BLUE] * len(segs), f"{name} ({dom}), deg",
                      "tau" if r == 1 else "")
    out["joint_angles"] = fig.png()

    fig = plot.Figure(810, 360, 1, 2)
    for c, name in enumerate(("th_pk", "th_pa")):
        col = COORDS.index(name)
        segs, colors = [], []
        for dom, color in ((Domain.PS, plot.GREEN), (Domain.PNS, plot.PINK)):
            for s in (s for s in p.steps if s.domain == dom):
                th = p.q[s.start:s.end + 1, col]
                segs.append(np.column_stack([np.degrees(th),
                                             np.degrees(np.gradient(th) * p.frame_rate)]))
                colors.append(color)
        fig.panel(0, c, segs, colors, f"d{name}/dt (deg/s)", f"{name} (deg)",
                  legend=((Domain.PS, plot.GREEN), (Domain.PNS, plot.PINK)))
    out["phase_portraits"] = fig.png()
    return out


def render_report(steps_path: str | Path, p: ProcessedTake, with_figures: bool = True
                  ) -> dict[Path, bytes]:
    """Contents of ``<stem>.qa.md``, ``<stem>.qa.json`` and the figures, by output path
    (next to the steps file); nothing is written."""
    base = Path(steps_path).with_suffix("")
    summary = qa_summary(p)
    out = {base.with_name(base.name + ".qa.md"): qa_markdown(summary).encode(),
           base.with_name(base.name + ".qa.json"): dumps(summary, indent=2).encode()}
    if with_figures:
        for name, png in figures(p).items():
            out[base.with_name(f"{base.name}_{name}.png")] = png
    return out


def write_report(steps_path: str | Path, p: ProcessedTake, with_figures: bool = True
                 ) -> list[Path]:
    """Write the QA report and figures next to the steps file (each atomically)."""
    files = render_report(steps_path, p, with_figures)
    for path, data in files.items():
        atomic_write_bytes(path, data)
    return list(files)


def render_session_report(steps_path: str | Path, takes: Sequence[TakeOutcome],
                          warnings: Sequence[str], with_figures: bool = True
                          ) -> dict[Path, bytes]:
    """The QA report of a session (:mod:`characterization.mocap.session`), by output path.
    One take: that take's report (:func:`render_report`) with the session's warnings; more:
    ``<stem>.qa.md`` with a line per take and each take's report, ``<stem>.qa.json`` with
    ``session`` (per take its line or why it gave no step; the warnings) and ``takes``
    (each take's QA numbers), and each take's figures as ``<stem>_take<k>_<name>.png``."""
    from characterization.mocap.session import session_summary

    base = Path(steps_path).with_suffix("")
    session = session_summary(takes, warnings)
    done = [t for t in takes if t.processed is not None]
    if len(takes) == 1 and done:
        p = done[0].processed
        assert p is not None
        summary = {**qa_summary(p), "session": session}
        md = qa_markdown(summary)
        if warnings:
            md += "\n## Session\n\n" + "".join(f"- {w}\n" for w in warnings)
        out = {base.with_name(base.name + ".qa.md"): md.encode(),
               base.with_name(base.name + ".qa.json"): dumps(summary, indent=2).encode()}
        if with_figures:
            for name, png in figures(p).items():
                out[base.with_name(f"{base.name}_{name}.png")] = png
        return out
    summaries: list[dict] = []
    lines = [f"# Motion-capture QA: a session of {len(takes)} takes", ""]
    lines += [f"- {t.line()}" for t in takes]
    if warnings:
        lines += ["", "## Warnings", ""] + [f"- {w}" for w in warnings]
    figs: dict[Path, bytes] = {}
    for k, t in enumerate(takes):
        if t.processed is None:
            summaries.append({"source": str(t.path), "error": t.error})
            continue
        s = qa_summary(t.processed)
        summaries.append(s)
        lines += ["", "#" + qa_markdown(s)]
        if with_figures:
            for name, png in figures(t.processed).items():
                figs[base.with_name(f"{base.name}_take{k}_{name}.png")] = png
    return {base.with_name(base.name + ".qa.md"): ("\n".join(lines) + "\n").encode(),
            base.with_name(base.name + ".qa.json"): dumps(
                {"session": session, "takes": summaries}, indent=2).encode(), **figs}
