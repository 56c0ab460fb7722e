"""report.md of a demo/experiments run: the figures and the paper's claims, each marked
reproduced or NOT reproduced with its numbers, and every deviation from the paper."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

from hp_model.atomic_io import atomic_write_bytes
from hp_model.domains import Domain
from orchestrator.experiments.animation import FALL_HOLD, GROUND_MARK
from orchestrator.loop.walker_figure import FORCE_SCALE

DEVIATIONS = (
    "The socket-force tube comes from playback of the recorded steps (paper Sec. IV-B) with "
    "each step's Bezier fit taken over its single support +/- 0.1 in tau (the paper fits the "
    "whole step; on a model-generated subject that made M_y 8-11 % wrong, "
    "docs/force-tube.md); playback holds each step's hip velocity "
    "constant.",
    "AMPRO3 masses, lengths and inertias are estimates (hp_model/configs/device_ampro3.toml); "
    "the estimated top-link inertia is tiny (0.0017 kg m^2 about the knee), which makes the "
    "reduced-model CLF-QP loop stiff (prosthesis_controller/README.md).",
    "The robust-passive baseline is Spong's robust passivity-based law, a documented "
    "stand-in for Azimi et al. 2017, which could not be retrieved.",
    "PD and robust-passive use a time-based stance phase; the swing controller (all "
    "controllers) is PD + gravity on a time-based phase instead of the paper's feedback "
    "linearization in pns, which needs the human's state the prosthesis cannot sense.",
    "The controller sees only prosthesis measurements (joint encoders, foot load = ground "
    "normal force, contact); the paper's simulation does not state what its controller saw.",
    "Perturbed human gaits: every Bezier coefficient of the human's outputs moved by the "
    "deterministic SplitMix64 generator of human_fmu/perturbation.py (amplitude in the "
    "Robustness section); seeds are the first whose perturbed gait walks under full feedback "
    "linearization. The paper does not say how its 3 gaits were perturbed.",
    "The same default controller gains are used in every case (no per-case tuning); the "
    "paper tuned the robust-passive ankle gains.",
    "Rigid impacts with the landing foot rotated flat (simulator); falls are detected by "
    "the simulator (friction cone, hip height, phase running backward, no touchdown, phase "
    "stalled).",
    "Swing landing (all controllers): from tau_hat = 0.8 the swing target lowers the sole by "
    "up to 1 cm (2 cm if the touchdown is late) and turns the foot flat at the nominal socket "
    "pitch. The optimized gait's swing foot skims the ground over the last part of pns and "
    "lands tangentially; the paper's pns feedback linearization sees the human's phase, a "
    "prosthesis-only swing controller does not, and without reaching for the ground it "
    "misses the touchdown.",
    "The time-based stance references of PD and robust-passive keep running past their "
    "nominal duration (continued linearly) instead of stopping when the human touches down "
    "late.",
    "The prosthesis initial offset of the robustness cases moves the knee output y2 by "
    "0.02 rad at the nominal start phase (ankle moved so tau is unchanged), the human on its "
    "own outputs; the paper does not give its offset.",
)


INTRO = (
    "The walking experiments of the paper's Sec. V repeated in simulation: a human model "
    "(trunk, left leg, right thigh) walks on a powered knee-ankle prosthesis (AMPRO3, worn "
    "on the right through an iWalk adapter), the human side tracking the gait fitted to the "
    "motion capture, the prosthesis driven at 1 kHz by a controller that sees only the "
    "prosthesis's own sensors. Each claim of the paper is checked against these runs and "
    "marked reproduced or NOT reproduced, with its numbers and, when not reproduced, why. "
    "Words and symbols are explained under [Terms](#terms) at the end.")


WALKER_TEXT = (
    "Stick figure of the model's joints, the view following the hip (the x axis in m and "
    f"the ground's marks every {GROUND_MARK:g} m move back as it walks); the red arrow is the "
    f"socket force on the prosthesis (1 m per {FORCE_SCALE:g} N); the line at the top gives "
    "time, domain, phase tau and the steps so far. A run that fell ends on its last pose, "
    f"held {FALL_HOLD:g} s under a banner naming the fall.")


def render(metrics: Mapping[str, Any], stages: Sequence[Mapping[str, Any]] = (),
           extra_deviations: Sequence[str] = ()) -> str:
    """report.md of the experiments' ``metrics`` (:func:`~orchestrator.experiments.paper.
    run_experiments`), the pipeline's ``stages`` (demo) and deviations beyond
    :data:`DEVIATIONS`."""
    m = metrics
    lines = ["# hpcosim: closed-loop results (paper Sec. V)", "", INTRO, "", _units(m), ""]
    if stages:
        lines += ["## Pipeline", "", "| stage | seconds | output |", "|---|---:|---|"]
        lines += [f"| {s['stage']} | {s['seconds']:.1f} | {s.get('output', '')} |"
                  for s in stages]
        lines.append("")
    lines += _claims(m)
    t = m["tube"]
    w = t["half_width_mid_stance"]
    lines += [f"Force tube: {t['n_steps']} recorded steps played back, tau in "
              f"[{t['tau_lo']:.2f}, {t['tau_hi']:.2f}], half-width at tau = 0.5: F_x "
              f"{w['F_x_N']:.1f} N, F_z {w['F_z_N']:.1f} N, M_y {w['M_y_Nm']:.2f} N m; the "
              f"gait's own nominal F* lies in it on {_pct(t.get('nominal_inside_fraction'))} "
              "of [tau_lo, tau_hi].", ""]
    lines += _robustness(m)
    lines += ["", *_diagnosis(m)]
    lines += ["", "## Figures", ""]
    captions = _captions(m)
    for k, f in m["figures"].items():
        lines += [f"![{k}]({f})", "", captions.get(k, ""), ""]
    if m.get("animations"):
        lines += ["## The walker (human blue, prosthesis orange, socket force red)", "",
                  WALKER_TEXT, ""]
        lines += [f"![walker, {k}]({f})" for k, f in m["animations"].items()]
    lines += ["", "## Deviations from the paper", ""]
    lines += [f"- {d}" for d in (*DEVIATIONS, *extra_deviations)]
    lines += ["", *_terms(m), ""]
    return "\n".join(lines)


def _units(m: Mapping[str, Any]) -> str:
    """The units paragraph: SI, and torques on the motor side with the device's ratios."""
    dev = m.get("device")
    if dev:
        g, lim = dev["gear_ratio"], dev["torque_limit_motor_Nm"]
        drives = (f"gear ratio knee {g['knee']:g}, ankle {g['ankle']:g}; motor torque limit "
                  f"knee {lim['knee']:g} N m, ankle {lim['ankle']:g} N m (device config "
                  f"`{dev['name']}`)")
    else:
        drives = "the gear ratios are the device config's (hp_model/configs/device_*.toml)"
    return ("Units: SI (s, m, rad, N, N m). **Torques are prosthesis motor torques** in N m "
            "on the motor side of the gear, unless called joint torques: joint torque = gear "
            f"ratio x motor torque; {drives}.")


def _claims(m: Mapping[str, Any]) -> list[str]:
    """The claims table: each reproduced, or NOT reproduced with its reason."""
    out = ["## The paper's claims", "", "| claim | result | numbers |", "|---|---|---|"]
    for c in m["claims"]:
        res = ("reproduced" if c["reproduced"] else
               "**NOT reproduced**: " + (c.get("why_not") or "no reason recorded"))
        out.append(f"| {c['claim']} | {res} | {c['numbers']} |")
    out += ["", "A baseline run that never completed a step (it fell before its first "
            "touchdown, e.g. at t = 0.004 s) is NOT COMPARED on tracking: its knee RMS covers "
            "a few milliseconds of one stance, not a walk.", ""]
    return out


def _run_cells(s: Mapping[str, Any]) -> tuple[str, str, str]:
    """(steps, knee RMS, result) cells of a robustness run summary; a run that never
    completed a step is marked in both."""
    steps = f"{s['steps_completed']}/{s['steps_requested']}"
    rms = _num(s["knee_rms_ps_rad"], 4)
    if s["success"]:
        return steps, rms, "ok"
    if s["steps_completed"] == 0:
        return (steps, f"{rms} (over {_num(s['duration_s'])} s: no step)",
                f"**never completed a step**: fell at {s['reason']}")
    return steps, rms, f"fell after {s['steps_completed']} steps at {s['reason']}"


def _robustness(m: Mapping[str, Any]) -> list[str]:
    rb = m["robustness"]
    ref = rb.get("reference_controller")
    out = ["## Robustness (Fig. 8)", "",
           f"Every controller on {len(rb['cases'])} perturbed human gaits (amplitude "
           f"{rb['amplitude_rad']} rad on every Bezier coefficient of the human's outputs), the "
           f"prosthesis started off nominal (knee output offset "
           f"{rb.get('knee_output_offset_rad')} rad: joint offsets "
           f"{_fmt_list(rb['initial_offset_rad'])} rad, knee and ankle), the same default gains "
           "everywhere."
           + (f" `{ref}` is the reference controller, not one of the paper's." if ref else ""),
           "", "| case | controller | steps | knee RMS in ps (rad) | F_s in tube | result |",
           "|---|---|---:|---:|---:|---|"]
    for case, cc in rb["cases"].items():
        for c, s in cc.items():
            steps, rms, res = _run_cells(s)
            out.append(f"| {case} | {c} | {steps} | {rms} | "
                       f"{_pct(s.get('socket_force_in_tube'))} | {res} |")
    return out


def _captions(m: Mapping[str, Any]) -> dict[str, str]:
    """What each figure shows, with its units."""
    n = m["exact_vs_relaxed"]["clfqp"]["run"]["steps_requested"]
    return {
        "fig6": (f"Fig. 6: the prosthesis torques of the exact and the relaxed robust CLF-QP "
                 f"over {n} nominal steps, prosthesis stance only: left axes motor torque "
                 "(N m, motor side), right axes the joint torque (N m) it makes through the "
                 "gear ratio. The exact law's torque flips (chatter); the relaxed law's is "
                 "smooth."),
        "fig7": ("Fig. 7: phase portraits of the prosthesis knee and ankle (angle in rad "
                 "against velocity in rad/s) of the nominal runs, stance and swing in two "
                 "colours, the gait's nominal orbit dashed: a closed loop settled on a "
                 "periodic orbit draws one closed curve."),
        "fig8": ("Fig. 8: the prosthesis knee angle th_pk (rad) in prosthesis stance of every "
                 "controller in each perturbed case, over time (s), the desired B_pk(tau) "
                 "underneath; a dotted line marks a fall and the legend says how each run "
                 "ended ('no step': it never completed one)."),
    }


def _terms(m: Mapping[str, Any]) -> list[str]:
    """The glossary: every word and symbol of the report in a lab's terms."""
    dev = m.get("device") or {}
    g = dev.get("gear_ratio", {})
    ratio = (f" (here knee {g['knee']:g}, ankle {g['ankle']:g})" if g else "")
    rows = [
        (str(Domain.PS), "prosthesis stance: the domain (phase of the gait) with the "
         "prosthetic foot on the ground and the human's left foot swinging"),
        (str(Domain.PNS), "prosthesis non-stance: the prosthesis swings, the human's left "
         "foot is on the ground"),
        ("step", "one domain from touchdown to the next touchdown (an impact); two steps "
         "make a stride"),
        ("tau", "the phase of a step: the hip's progress over the stance foot, 0 at the "
         "touchdown and 1 at the nominal next one (in prosthesis stance the controller "
         "computes it from the prosthesis's knee and ankle angles); the gait's curves are "
         "functions of tau"),
        ("y1, y2", "the controlled outputs: y1 the hip velocity error (m/s), y2 the joint "
         "angles' deviations from the gait's curves B(tau) (rad)"),
        ("CLF, V", "control Lyapunov function: V measures how far the prosthesis's outputs "
         "are from the gait (0 on it); the controller keeps V decreasing at a set rate"),
        ("CLF-QP", "the paper's controller: each millisecond a small quadratic program "
         "(QP) picks the motor torques closest to nominal that make V decrease"),
        ("`clfqp`, `clfqp-exact`", "the robust CLF-QP: the CLF-QP made to hold for every "
         "socket force inside the force tube; the relaxed one (`clfqp`) lets the decrease "
         "condition slip by rho at a cost, the exact one (`clfqp-exact`) does not"),
        ("rho", "the relaxation of the relaxed CLF-QP (how much the V-decrease condition is "
         "violated at that tick; 0 when it holds)"),
        ("`clfqp-paper`", "the paper's literal formulation (the prosthesis model alone, the "
         "socket force an input in the tube)"),
        ("`passive`, `pd`", "the paper's baselines: a robust passivity-based law and a PD "
         "law on the joint angles, both on a time-based phase"),
        ("`phase-pd`", "a reference controller of this project, not the paper's (PD plus the "
         "gait's nominal torque, on the state-based phase)"),
        ("oracle", "the walker under full feedback linearization with perfect knowledge: "
         "the rule that decides a perturbed gait is walkable at all"),
        ("F_s, socket force", "the force (F_x, F_z in N) and moment (M_y in N m) between "
         "the residual limb's socket and the prosthesis, in the prosthesis top link's frame"),
        ("force tube", "the band of socket forces, a function of tau, that the recorded steps "
         "stayed in (fitted by playing them back); 'F_s in tube' is the share of a run's "
         "stance samples inside it"),
        ("knee RMS", "root mean square of the prosthesis knee's deviation from the gait's "
         "knee curve B_pk(tau) over a run's prosthesis-stance samples (rad); of a run that "
         "fell, over the part before the fall"),
        ("motor torque, gear ratio", "the torques the controller commands are motor-side "
         f"(N m); joint torque = gear ratio x motor torque{ratio}"),
        ("chatter", "total variation of the motor torque (the sum of its absolute changes "
         "from tick to tick) per second of prosthesis stance (N m/s)"),
        ("fell, fall", "the simulator ended the run: the stance foot left the friction cone "
         "(slipping or pulling on the ground), the hip dropped below 0.55 m, the phase ran "
         "backward or stalled, no touchdown came, a foot landed on heel or toe"),
        ("never completed a step", "the run fell before its first touchdown"),
        ("fallback ticks", "ticks where the controller had no usable torque (the QP failed "
         "or a measurement was faulty) and moved its previous torque, rate-limited, toward a "
         "safe one instead"),
        ("contraction per cycle, orbit band", "stability evidence: how much a perturbation "
         "of the start shrinks per stride (< 1 contracts), against the stride-to-stride "
         "spread of the unperturbed run"),
        ("return-map spectral radius", "the largest eigenvalue magnitude of the stride-to-"
         "stride map by finite differences (< 1 stable), at three step sizes: a number only "
         "where they agree"),
        ("input authority A_m, A", "how much one motor N m changes the outputs' "
         "accelerations (dy1, d2y2): A_m in the reduced model the CLF-QP uses, A in the full "
         "loop"),
        ("perturbation (seed)", "the human's gait with every Bezier coefficient moved by up "
         "to the amplitude (rad), drawn from the seed"),
    ]
    return ["## Terms", "", "| term | meaning |", "|---|---|",
            *(f"| {t} | {d} |" for t, d in rows)]


def _num(x: Any, digits: int = 3) -> str:
    return "n/a" if x is None else f"{x:.{digits}g}" if digits < 4 else f"{x:.{digits}f}"


def _pct(x: Any) -> str:
    return "n/a" if x is None else f"{100 * x:.0f} %"


def _fmt_list(v: Sequence[float]) -> str:
    return "(" + ", ".join(f"{x:.4f}" for x in v) + ")"


def _diagnosis(m: Mapping[str, Any]) -> list[str]:
    """The reference run and the input-authority comparison (docs/experiments.md)."""
    out = ["## Diagnosis", ""]
    ref = m.get("reference")
    n = m["nominal"]
    if ref:
        from orchestrator.experiments.claims import stability_text

        run = ref["run"]
        out += [f"Reference controller `{ref['controller']}` (not in the paper: nominal stance "
                "torque of the gait as feedforward, knee PD on the CLF-QP's state-based "
                "phase, hip-velocity feedback through the ankle with the sign of the full "
                "loop), nominal human: "
                f"{run['steps_completed']}/{run['steps_requested']} steps"
                + (f", fell: {run['reason']}" if run["failed"] else "")
                + f"; {stability_text(ref['stability'])}"
                + f"; knee RMS in ps {_num(run['knee_rms_ps_rad'], 4)} rad.", ""]
    out += ["Socket force inside the tube (the premise of the robust CLF condition), share of "
            f"the ps samples in [tau_lo, tau_hi]: robust CLF-QP nominal run "
            f"{_pct(n['run'].get('socket_force_in_tube'))}"
            + (f", reference nominal run {_pct(ref['run'].get('socket_force_in_tube'))}"
               if ref else "") + ".", ""]
    auth = m.get("diagnosis", {}).get("input_authority")
    if auth:
        out += ["Input authority of the prosthesis motor torque on the outputs (dy1, d2y2) "
                "per motor N m: the reduced model the CLF-QP uses (socket force held "
                "fixed) against the full loop (the human tracking its outputs, so the socket "
                "force answers the torque):", "",
                "| tau | reduced A_m | full loop A | norm ratio | signs agree (row y1; row y2) |",
                "|---:|---|---|---:|---|"]
        for a in auth:
            out.append(f"| {a['tau']:.2f} | {_mat(a['reduced_Am_per_motor_Nm'])} | "
                       f"{_mat(a['full_A_per_motor_Nm'])} | "
                       f"{a['norm_ratio_reduced_over_full']:.0f} | "
                       f"{_signs(a['sign_agreement'])} |")
        out.append("")
    return out


def _mat(a: Sequence[Sequence[float]]) -> str:
    return "[" + "; ".join(", ".join(f"{v:.3g}" for v in row) for row in a) + "]"


def _signs(a: Sequence[Sequence[bool]]) -> str:
    return "; ".join(", ".join("yes" if v else "NO" for v in row) for row in a)


def write_report(out: str | os.PathLike[str], metrics: Mapping[str, Any],
                 stages: Sequence[Mapping[str, Any]] = (),
                 extra_deviations: Sequence[str] = ()) -> str:
    path = os.path.join(os.fspath(out), "report.md")
    atomic_write_bytes(path, render(metrics, stages, extra_deviations).encode())
    return path
