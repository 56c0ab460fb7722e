"""``hpcosim gait ...``: gait design (paper Sec. IV-A)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from hp_model.domains import PAPER_DOMAINS, DomainGraph
from orchestrator.cli.options import DeviceOpt, SubjectOpt
from orchestrator.cli.outcome import conclude, gait_verdict

gait_app = typer.Typer(help="Gait design: Bezier regression and PHZD optimization.",
                       no_args_is_help=True)


#: ``gait fit``'s options of the paper's PHZD fit only (refused with --domains multicontact)
PAPER_ONLY = ("degree", "segments", "offset_weight", "touchdown_slip", "track_kp", "track_kd",
              "verify", "allow_unstable")
#: and those of the multi-contact fit only
MULTICONTACT_ONLY = ("allow_mismatch", "motor_margin", "max_joint_speed")


def _given(ctx: typer.Context, names: tuple[str, ...]) -> list[str]:
    """The options among ``names`` the command line set (as ``--option-name``; the source
    compared by name: typer carries its own copy of click's ``ParameterSource``)."""
    return [f"--{n.replace('_', '-')}" for n in names
            if getattr(ctx.get_parameter_source(n), "name", None) == "COMMANDLINE"]


@gait_app.command("fit")
def fit(
    ctx: typer.Context,
    steps: Annotated[Path, typer.Argument(help="Steps file from `hpcosim mocap process`.",
                                          dir_okay=False)],
    out: Annotated[Path, typer.Option("--out", help="Gait file to write (.json); the Fig. 4 "
                                      "figure goes next to it.", dir_okay=False)],
    subject: SubjectOpt = None,
    device: DeviceOpt = None,
    degree: Annotated[int, typer.Option(help="paper: Bezier degree of the joint outputs.",
                                        min=1, max=9)] = 5,
    nodes: Annotated[int | None, typer.Option(
        help="Collocation nodes per domain (default: 21 paper, 9 multicontact).",
        min=3, max=101)] = None,
    max_iter: Annotated[int, typer.Option(help="IPOPT iteration limit.", min=1)] = 1000,
    segments: Annotated[str, typer.Option(
        help="paper: portions of the take regressed per domain: 'touchdown' (the model's domains, "
        "touchdown to touchdown) or 'paper' (delta_p_hip rising = ps, falling = pns).")
    ] = "touchdown",
    offset_weight: Annotated[float, typer.Option(
        help="paper: weight of the squared offsets delta_alpha in the cost (0 = the paper's cost).",
        min=0.0)] = 0.1,
    touchdown_slip: Annotated[float | None, typer.Option(
        help="paper: largest forward/backward speed of the swing sole at touchdown, m/s (default: "
        "not bounded).", min=0.0)] = None,
    track_kp: Annotated[float, typer.Option(
        help="paper: stiffness (1/s^2) of the human's output tracking stored with the gait (the "
        "simulated human, the FMU); the orbit does not depend on it, its stability does.",
        min=0.0)] = 1600.0,
    track_kd: Annotated[float, typer.Option(help="paper: damping (1/s) of that tracking.",
                                            min=0.0)] = 80.0,
    verify: Annotated[bool, typer.Option(help="paper: closed-loop verification (20 steps, "
                                         "return map); a gait that fails it is not written.")
                      ] = True,
    allow_unstable: Annotated[bool, typer.Option(
        help="paper: write the gait even when it falls or its return map is not contracting "
        "(marked walks: false in its verification).")] = False,
    figure: Annotated[bool, typer.Option(help="Write the Fig. 4 figure.")] = True,
    domains: Annotated[DomainGraph, typer.Option(
        help="The walk's cycle of domains: 'multicontact' (heel strike, foot flat, heel off, "
        "toe off, double supports: the person's gait, compared with the take; "
        "docs/gait-design.md) or 'paper' (ps -> pns, flat feet: the paper's PHZD gait, for "
        "its claims and for takes without double support).")] = DomainGraph.MULTICONTACT,
    allow_mismatch: Annotated[bool, typer.Option(
        help="multicontact: write the gait even when it is not the person's (marked "
        "mismatch_allowed).")] = False,
    motor_margin: Annotated[float, typer.Option(
        help="multicontact: the prosthesis's motor torques stay within (1 - margin) of the "
        "device's limits (feedback needs the rest; docs/gait-design.md).",
        min=0.0, max=0.9)] = 0.15,
    max_joint_speed: Annotated[float | None, typer.Option(
        help="multicontact: a bound on every joint's rate, rad/s (default: none; the takes' "
        "fastest joint moves at 5.4-7 rad/s).", min=0.1)] = None,
) -> None:
    """Fit the person's multi-contact gait and compare it with the take (or, with --domains
    paper, regress the recorded steps, optimize a periodic PHZD gait on the paper's two
    domains, verify it, write it)."""
    import hp_model
    from characterization.gait.figures import save_gait_figure
    from characterization.gait.fit import check_subject_fits_steps, fit_gait, fit_segments
    from characterization.gait.phzd import PHZDOptions
    from characterization.mocap.steps_artifact import load_steps
    from hp_model.artifacts import save_json
    from hp_model.config import SUBJECT_KEY, subject_record
    from hp_model.gait_artifact import to_document
    from orchestrator.cli.options import check_output_file
    from orchestrator.cli.subject import subject_note, subject_source

    wrong = _given(ctx, PAPER_ONLY if domains == DomainGraph.MULTICONTACT else
                   MULTICONTACT_ONLY)
    if wrong:
        other = "paper" if domains == DomainGraph.MULTICONTACT else "multicontact"
        raise typer.BadParameter(f"{', '.join(wrong)}: an option of the {other} fit, not of "
                                 f"the {domains} one (--domains {other})",
                                 param_hint="--domains")
    if domains == DomainGraph.MULTICONTACT:
        from orchestrator.cli.gait_multicontact import fit_multicontact_gait

        fit_multicontact_gait(steps, out, subject, device, nodes or 9, max_iter,
                              allow_mismatch, figure, motor_margin=motor_margin,
                              max_joint_speed=max_joint_speed)
        return
    console = Console(stderr=True)
    portions = fit_segments(segments)
    check_output_file(out)
    data = load_steps(steps)
    # the subject (--subject, else the steps') checked before any optimization starts
    model = hp_model.load_model(subject_source(subject, steps),
                                str(device) if device else None)
    Console().print(subject_note(subject, steps), soft_wrap=True, highlight=False)
    for w in check_subject_fits_steps(model, data, str(steps)):
        console.print(f"[yellow]warning:[/] {w}", soft_wrap=True, highlight=False)
    opt = PHZDOptions(degree=degree, nodes=nodes or 21, max_iter=max_iter,
                      w_offset=offset_weight,
                      touchdown_slip=np.inf if touchdown_slip is None else touchdown_slip,
                      track_kp=track_kp, track_kd=track_kd)
    with console.status("gait fit") as status:
        gait = fit_gait(model, data, opt, src=str(steps), verify=verify,
                        progress=lambda m: status.update(m), segments=portions,
                        allow_unstable=allow_unstable)
    provenance = ({"*": f"--subject {subject}"} if subject is not None else
                  dict(data.subject.get("provenance", {})) if data.subject else
                  {"*": "the shipped example subject"})
    save_json(out, {**to_document(gait), SUBJECT_KEY: subject_record(model.subject, provenance)})
    if figure:
        save_gait_figure(out.with_suffix(".png"), gait, data)
    _summary(Console(), gait, out)
    conclude(gait_verdict(gait.verification))


def _summary(console: Console, gait, out: Path) -> None:

    s = gait.solver
    console.print(f"[bold]gait[/bold] {out}  (hash {gait.hash()})")
    console.print(f"IPOPT: {s['status']} in {s['iterations']} iterations, "
                  f"{s['seconds']:.1f} s; cost {s['cost']:.4g}")
    t = Table("domain", "v_hip m/s", "step m", "duration s", "fit RMS deg (data)",
              "RMS deg (optimized vs data+offset)")
    v = gait.verification
    for d in PAPER_DOMAINS:
        p = gait.params[d]
        fitq = gait.fit_quality.get(d, {})
        rms = v.get("output_rms_deg", {}).get(d)
        t.add_row(d, f"{p.v_hip:.3f}", f"{p.step_length:.3f}",
                  f"{gait.durations[d]:.3f}",
                  " ".join(f"{x:.1f}" for x in np.degrees(fitq.get("rms", []))),
                  " ".join(f"{x:.1f}" for x in rms) if rms is not None else "-")
    console.print(t)
    if v:
        verdict = "walks" if v.get("walks") else "does NOT walk: written by --allow-unstable"
        console.print(f"closed loop: {v['steps_simulated']} steps simulated"
                      f"{' (FAILED: ' + v['failure'] + ')' if v['simulation_failed'] else ''}; "
                      f"return-map spectral radius {v['spectral_radius']:.3g} ({verdict})")
    else:
        console.print("closed loop: not verified (--no-verify)")


@gait_app.command("library")
def library(
    steps: Annotated[Path, typer.Argument(help="Steps file of the take the gait was fitted "
                                          "from (`hpcosim mocap process`).", dir_okay=False)],
    gait: Annotated[Path, typer.Option("--gait", help="The person's multi-contact gait "
                                       "(`hpcosim gait fit`).", dir_okay=False)],
    out: Annotated[Path, typer.Option("--out", help="Library file to write (.json).",
                                      dir_okay=False)],
    speeds: Annotated[str, typer.Option(
        help="Walking speeds to fit, m/s, comma-separated (the gait's own is in the library "
        "already).")] = "0.6,0.8,1.0,1.2,1.4",
) -> None:
    """Fit the person's gait again at other walking speeds, each fit continued from its
    neighbour's, and write the gaits as one library (docs/gait-design.md); each is walked
    with the held oracle."""
    from orchestrator.cli.gait_library import make_gait_library, parse_speeds

    try:
        wanted = parse_speeds(speeds)
    except ValueError as e:
        raise typer.BadParameter(str(e), param_hint="--speeds") from None
    make_gait_library(steps, gait, out, wanted)
