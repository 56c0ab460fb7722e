"""The paper's Sec. V claims checked against the experiments' metrics
(:func:`orchestrator.experiments.paper.run_experiments`): each reproduced or not, with its
numbers, a headline for the terminal and, when not reproduced, the reason in one sentence;
the device's drives the torques are in."""

from __future__ import annotations

from typing import Any

from hp_model.human_prosthesis import HumanProsthesisModel
from prosthesis_controller import ControllerName


def device_summary(model: HumanProsthesisModel) -> dict[str, Any]:
    """The prosthesis drives of the device config the torques are in: name, gear ratio
    (joint torque = ratio x motor torque) and motor-side torque limit (N m) per joint."""
    p = model.device.prosthesis
    return {"name": model.device.name,
            "gear_ratio": {"knee": p.knee.gear_ratio.value, "ankle": p.ankle.gear_ratio.value},
            "torque_limit_motor_Nm": {"knee": p.knee.torque_limit.value,
                                      "ankle": p.ankle.torque_limit.value}}


def claims(m: dict[str, Any]) -> list[dict[str, Any]]:
    """The paper's Sec. V claims, each with reproduced True/False, the numbers, a short
    headline and ``why_not`` (the reason, in one sentence, when not reproduced; else "")."""
    out = [_claim_nominal(m), _claim_relaxed(m), _claim_order(m), _claim_success(m)]
    if m.get("paper_literal") is not None:
        out.append(_claim_paper_literal(m))
    return out


def _claim_nominal(m: dict[str, Any]) -> dict[str, Any]:
    n = m["nominal"]
    run, st = n["run"], n["stability"]
    why = ("" if run["success"] and n["stable_orbit"] else
           f"the run {_ended(run)}" if not run["success"] else
           f"stability not computed: {st.get('why_not', '')}" if not st.get("computed") else
           f"the orbit does not contract: worst factor {_f(st.get('contraction_worst'))} "
           "per cycle (>= 1)")
    return {"id": "nominal_stable", "claim": f"nominal closed loop stable for {m['steps']} "
            "steps (robust CLF-QP relaxed in ps, swing controller in pns)",
            "reproduced": not why,
            "numbers": f"{run['steps_completed']}/{run['steps_requested']} steps"
            + (f"; fell: {run['reason']}" if run["failed"] else "")
            + f"; knee RMS in ps {_f(run['knee_rms_ps_rad'])} rad; " + stability_text(st)
            + f"; fallback ticks {run['fallback_count']}"
            + f"; F_s inside the tube {_pct(run['socket_force_in_tube'])} of the ps samples",
            "headline": f"{run['steps_completed']}/{run['steps_requested']} steps, knee RMS "
            f"{_f(run['knee_rms_ps_rad'])} rad, contraction "
            f"{_f(st.get('contraction_worst'))}/cycle", "why_not": why}


def _claim_relaxed(m: dict[str, Any]) -> dict[str, Any]:
    e = m["exact_vs_relaxed"]
    ratio = e["chatter_ratio_exact_over_relaxed"]
    relaxed = e["clfqp"]
    kr = relaxed["knee_rms_per_step_rad"]
    why = ("no chatter ratio (a run has no ps sample)" if ratio is None else
           f"the exact law's chatter is only {_f(ratio)}x the relaxed law's (< 5x)"
           if ratio < 5 else
           f"the relaxed run {_ended(relaxed['run'])}" if not relaxed["run"]["success"] else
           "the relaxed law's knee RMS per step has not settled (last two steps "
           + ", ".join(f"{x:.4f}" for x in kr[-2:]) + " rad, more than 10 % apart)"
           if not e["relaxed_tracking_converging"] else "")
    return {"id": "relaxed_smooth", "claim": "relaxed CLF-QP chatter >= 5x lower than exact, "
            "with its tracking settling onto the periodic orbit", "reproduced": not why,
            "numbers": (f"motor torque total variation per s of ps: exact "
                        f"{_f(e['clfqp-exact']['chatter_rate_Nm_per_s'])}, relaxed "
                        f"{_f(relaxed['chatter_rate_Nm_per_s'])} N m/s (ratio {_f(ratio)}); "
                        f"exact run: {_ended(e['clfqp-exact']['run'])}; relaxed run: "
                        f"{_ended(relaxed['run'])}; relaxed knee RMS per step (rad) "
                        + ", ".join(f"{x:.4f}" for x in kr)),
            "headline": f"chatter exact / relaxed {_f(ratio)}x", "why_not": why}


def _baseline(c: str, s: dict[str, Any]) -> tuple[str, bool]:
    """One baseline run of a robustness case in the order claim's numbers, and whether it
    is compared (it completed the case): a run that never completed a step says so."""
    if s["success"]:
        return f"{c} {_f(s['knee_rms_ps_rad'])} rad ({_ended(s)})", True
    if s["steps_completed"] == 0:
        return (f"{c} NOT COMPARED: never completed a step ({_ended(s)}, its knee RMS "
                f"{_f(s['knee_rms_ps_rad'])} rad is over {_f(s['duration_s'])} s)"), False
    return (f"{c} not compared: {_ended(s)} (knee RMS {_f(s['knee_rms_ps_rad'])} rad over "
            "them)"), False


def _claim_order(m: dict[str, Any]) -> dict[str, Any]:
    r = m["robustness"]
    rows, why, compared, total = [], [], 0, 0
    for (case, cc), below in zip(r["cases"].items(), r["clfqp_below_each_completed_baseline"],
                                 strict=True):
        base = [_baseline(c, cc[c]) for c in r["controllers"][1:]]
        n = sum(ok for _, ok in base)
        compared, total = compared + n, total + len(base)
        rows.append(f"{case}: clfqp {_f(cc['clfqp']['knee_rms_ps_rad'])} rad "
                    f"({_ended(cc['clfqp'])}), " + ", ".join(t for t, _ in base)
                    + ("" if n else " (no baseline completed: nothing to compare)"))
        if not below:
            why.append(f"{case}: clfqp " + ("did not complete" if not cc["clfqp"]["success"]
                                            else "is not below every completed baseline"))
    both = [x for x in r["passive_lt_pd_where_both_complete"] if x is not None]
    ok = r["clfqp_below_each_completed_baseline"]
    return {"id": "robust_order", "claim": "under perturbations clfqp's knee RMS is below each "
            "baseline's (passive, pd) in every case where that baseline completes",
            "reproduced": bool(all(ok)),
            "numbers": "; ".join(rows) + f"; {compared} of {total} baseline runs completed "
            f"their case and were compared; the paper's passive < pd found in {sum(both)} of "
            f"{len(both)} cases where both complete",
            "headline": f"below in {sum(ok)} of {len(ok)}; {compared} of {total} baseline runs "
            "compared", "why_not": "; ".join(why)}


def _claim_success(m: dict[str, Any]) -> dict[str, Any]:
    r = m["robustness"]
    failed = [f"{case}: {_ended(cc['clfqp'])}" for case, cc in r["cases"].items()
              if not cc["clfqp"]["success"]]
    return {"id": "robust_success", "claim": "clfqp succeeds in every perturbed case",
            "reproduced": bool(r["clfqp_succeeds_every_case"]),
            "numbers": "; ".join(f"{case}: {_ended(cc['clfqp'])}"
                                 for case, cc in r["cases"].items()),
            "headline": f"{sum(cc['clfqp']['success'] for cc in r['cases'].values())} of "
            f"{len(r['cases'])} cases", "why_not": "; ".join(failed)}


def _claim_paper_literal(m: dict[str, Any]) -> dict[str, Any]:
    r, pr = m["robustness"], m["paper_literal"]["run"]
    auth = m.get("diagnosis", {}).get("input_authority") or []
    ratios = [a["norm_ratio_reduced_over_full"] for a in auth]
    span = f"{min(ratios):.0f}-{max(ratios):.0f}x" if ratios else ""
    paper = ControllerName.CLFQP_PAPER  # the paper's literal formulation
    cases = {case: cc[paper] for case, cc in r["cases"].items() if paper in cc}
    fell = [c for c, s in cases.items() if not s["success"]]
    auth_text = (f"its reduced model's motor-torque authority on (dy1, d2y2) is {span} the "
                 "full loop's" if ratios else "")
    why = ("" if pr["success"] and not fell else
           ("the nominal run " + _ended(pr) + "; " if not pr["success"] else "")
           + f"it fails {len(fell)} of {len(cases)} perturbed cases"
           + (f"; {auth_text} (Diagnosis)" if ratios else ""))
    return {"id": "paper_literal", "claim": "the paper's literal formulation "
            "(clfqp-paper: subsystem model, socket force an input in the tube) walks "
            "the nominal loop and the perturbed cases", "reproduced": not why,
            "numbers": f"nominal: {_ended(pr)}; "
            + "; ".join(f"{case}: {_ended(s)}" for case, s in cases.items())
            + (f"; diagnosis: {auth_text} (its socket force held fixed while the human's "
               "answers the motor torque; input-authority table)" if ratios else ""),
            "headline": f"nominal: {_ended(pr)}" + (f"; authority {span} the loop's"
                                                    if ratios else ""),
            "why_not": why}


def stability_text(st: dict[str, Any]) -> str:
    """One line of :func:`orbit_stability`'s evidence."""
    if not st.get("computed"):
        return f"stability not computed: {st.get('why_not', '')}"
    text = (f"contraction per cycle from {st['contraction_starts']} perturbed starts over "
            f"{st['contraction_cycles']} cycles: worst {_f(st['contraction_worst'])} "
            f"({'contracting' if st['contracting'] else 'NOT contracting'}; the unperturbed "
            f"orbit's cycle-to-cycle band {_f(st['orbit_band'])} in the same units)")
    if st["fd_spectral_radius"]:
        fd = ", ".join(f"{_f(v)} (step {k})" for k, v in st["fd_spectral_radius"].items())
        agree = "agree" if st["fd_steps_agree"] else "do NOT agree: not a derivative here"
        text += f"; finite-difference return-map spectral radius {fd}: the steps {agree}"
    return text


def _f(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.3g}"


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100 * x:.0f} %"


def _ended(s: dict[str, Any]) -> str:
    """How a run ended, in words: ``ok, 20 steps``; ``fell at t = ... after 2 steps``;
    ``fell at t = ... before completing a step``."""
    n = s["steps_completed"]
    if s["success"]:
        return f"ok, {n} steps"
    if s["failed"]:
        return (f"fell at t = {_f(s['fail_t'])} s in {s['fail_domain']}, tau = "
                f"{_f(s['fail_tau'])}, " + (f"after {n} steps" if n else
                                             "before completing a step"))
    return f"stopped after {n} steps"
