"""``hpcosim tube ...``: socket-force playback of the recorded steps and the force tube."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from hp_model.force_tube import ForceTube, TubePhase
from orchestrator.cli.options import DeviceOpt, SubjectOpt, check_output_file
from orchestrator.cli.outcome import HOLDS, combine, conclude, coverage_verdict

tube_app = typer.Typer(help="The socket-force tube: playback of the recorded steps (paper "
                       "Sec. IV-B).", no_args_is_help=True)


@tube_app.command("fit")
def fit(
    steps: Annotated[Path, typer.Argument(help="Steps file (.npz or .json) from `hpcosim mocap "
                                          "process`.", dir_okay=False)],
    gait: Annotated[Path, typer.Option("--gait", help="Gait file (from `hpcosim gait fit`); "
                                       "F* is its nominal socket force.", dir_okay=False)],
    out: Annotated[Path, typer.Option("--out", help="Tube file to write (.json); the Fig. 5 "
                                      "figure (<stem>_fig5.png) and the report (<stem>.md) go "
                                      "next to it.", dir_okay=False)],
    degree: Annotated[int | None, typer.Option(
        "--degree", min=0, max=20, help="Bezier degree of the tube's bounds (default 3; on a "
        "multi-contact gait the highest its strides support, at most 3).")] = None,
    n_steps: Annotated[int | None, typer.Option(
        "--steps", min=1, help="Play back the first N prosthesis-stance steps (default: "
        "all; the paper used 20).")] = None,
    fit_margin: Annotated[float, typer.Option(
        "--fit-margin", min=0.0, max=1.0,
        help="Fit each step's Bezier curves on its single support (foot-marker rule) widened "
        "by this much tau on each side, and play back over that window.")] = 0.1,
    whole_step_fit: Annotated[bool, typer.Option(
        "--whole-step-fit", help="The paper's variant: fit every frame of the step and play "
        "back from tau = 0 to 1 (overrides --fit-margin).")] = False,
    stop_at_touchdown: Annotated[bool, typer.Option(
        help="End each playback at the human foot's touchdown too.")] = False,
    allowance: Annotated[float, typer.Option(
        "--allowance", min=0.0, max=0.99,
        help="Widen the certified bounds by this fraction of each component's peak |F_s| "
        "for the playback's estimation error (0: the paper's bare tube).")] = 0.01,
    phase: Annotated[TubePhase, typer.Option(
        "--phase", help="The tube's tau: 'gait' = the gait's phase of each sample (the phase "
        "the controllers compute; default), 'step' = each step's own phase (the paper's "
        "per-step normalization).")] = TubePhase.GAIT,
    model_error: Annotated[bool, typer.Option(
        "--model-error/--no-model-error",
        help="Also characterise what clfqp's nominal-human model does not explain along the "
        "playbacks and store its mid-stance bound in the tube (model_error).")] = True,
    error_degree: Annotated[int, typer.Option(
        "--error-degree", min=0, max=20, help="Bezier degree of the model-error bound.")] = 3,
    exclude_ms: Annotated[float, typer.Option(
        "--exclude-ms", min=0.0, max=255.0,
        help="Time after the prosthesis's touchdown left out of the model-error bound (ms); "
        "the impact transient is left to the CLF relaxation.")] = 30.0,
    min_coverage: Annotated[float | None, typer.Option(
        "--min-coverage", min=0.0, max=1.0,
        help="Exit 1 when the tube's (or the model-error bound's) leave-one-out coverage is "
        "below this (default: its a posteriori guarantee 1 - eps; coverage 0 always); the "
        "files are written all the same.")] = None,
    subject: SubjectOpt = None,
    device: DeviceOpt = None,
) -> None:
    """Play back every prosthesis-stance step on the full model, estimate the socket force,
    and fit the certified force tube around its deviation from the gait's nominal F*; with
    it (default) the mid-stance bound of clfqp's model error along the same playbacks.  A
    multi-contact gait: every flat prosthesis single support played back on its domain, the
    tube over the prosthesis controllers' stance phase, and the bound of its clfqp's model
    error along the same playbacks."""
    import hp_model
    from characterization.mocap.steps_artifact import load_steps
    from characterization.tube.playback import (
        PlaybackError,
        PlaybackOptions,
        TubeOptions,
        fit_force_tube,
        write_outputs,
    )
    from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind, load_gait
    from orchestrator.cli.subject import subject_source

    console = Console()
    if out.suffix != ".json":
        raise PlaybackError(f"{out}: the tube file must end in .json")
    check_output_file(out)
    if artifact_kind(gait) == MULTICONTACT_KIND:
        given = {"--subject": subject is not None, "--device": device is not None,
                 "--steps": n_steps is not None, "--whole-step-fit": whole_step_fit,
                 "--stop-at-touchdown": stop_at_touchdown, "--phase step": phase != TubePhase.GAIT}
        _contact_tube(console, steps, gait, out, degree, allowance, min_coverage,
                      [k for k, v in given.items() if v])
        return
    degree = 3 if degree is None else degree
    with console.status("loading the model (compiled once, then cached)"):
        model = hp_model.load_model(subject_source(subject, gait),
                                    str(device) if device else None)
        g = load_gait(gait, model.parameter_hash())
        s = load_steps(steps)
    with Progress(TextColumn("{task.description}"), BarColumn(),
                  TextColumn("{task.completed}/{task.total}"), TimeElapsedColumn(),
                  console=console, transient=True) as prog:
        task = prog.add_task("playback", total=None)

        def progress(what: str, done: int, total: int) -> None:
            prog.update(task, description=what, completed=done, total=total)

        res = fit_force_tube(model, g, s,
                             TubeOptions(degree=degree, allowance=allowance,
                                         model_error=model_error, error_degree=error_degree,
                                         exclude_after_touchdown=exclude_ms * 1e-3),
                             n_steps=n_steps,
                             options=PlaybackOptions(
                                 stop_at_touchdown=stop_at_touchdown,
                                 fit_margin=None if whole_step_fit else fit_margin,
                                 tube_phase=phase),
                             progress=progress, src=str(steps))
    paths = write_outputs(out, res, str(steps), str(gait))
    t, cred = res.tube, res.tube.credibility
    console.print(f"[bold]{steps}[/]: {len(res.playback.steps)} ps steps played back in "
                  f"{res.seconds['playback']:.2f} s, {len(res.used)} in the tube; tau in "
                  f"[{t.tau_lo:.3f}, {t.tau_hi:.3f}] (single support, foot-marker rule; "
                  f"{res.phase} phase)")
    for i, why in res.playback.skipped:
        console.print(f"  [yellow]skipped[/] step {i}: {why}")
    _print_tube(console, t)
    me = t.model_error
    if me is not None:
        mc = me.credibility
        loo = mc["leave_one_out"]["step_coverage"]
        console.print(f"model error: tau in [{me.tau_lo:.3f}, {me.tau_hi:.3f}], first "
                      f"{me.exclude_after_touchdown * 1e3:.0f} ms after touchdown excluded; "
                      f"max |d| = {me.source['max_abs'][0]:.3g} m/s^2 (dy1), "
                      f"{me.source['max_abs'][1]:.3g} rad/s^2 (d2y2); a posteriori k = "
                      f"{mc['a_posteriori']['k']}, eps = {mc['a_posteriori']['epsilon']:.3f}; "
                      "leave-one-out coverage "
                      + ("-" if loo is None else f"{loo:.2f}"))
    elif model_error:
        console.print(f"[yellow]model error[/]: {t.source.get('model_error', 'not fitted')}")
    console.print(f"wrote {paths['tube']}, {paths['figure'].name}, {paths['report'].name}")
    conclude(combine(coverage_verdict("force tube", cred, min_coverage),
                     coverage_verdict("model-error bound", me.credibility, min_coverage)
                     if me is not None else HOLDS))


def _contact_tube(console: Console, steps: Path, gait: Path, out: Path, degree: int | None,
                  allowance: float, min_coverage: float | None, refused: list[str]) -> None:
    """``tube fit`` on a multi-contact gait (:mod:`characterization.tube.contact_playback`)."""
    from characterization.gait.multicontact_artifact import load_contact_cycle
    from characterization.mocap.steps_artifact import load_steps
    from characterization.tube.contact_playback import fit_contact_tube, write_outputs
    from orchestrator.cosim.contact_controllers import load_contact_run, tube_with_model_error

    if refused:
        raise typer.BadParameter(
            f"{gait} is a multi-contact gait: it carries its subject and device, and its tube "
            f"plays back every flat single support in the controllers' phase; drop "
            f"{', '.join(refused)}", param_hint="--gait")
    with console.status("loading the multi-contact gait and the steps"):
        g = load_contact_cycle(gait)
        s = load_steps(steps)
    with Progress(TextColumn("{task.description}"), BarColumn(),
                  TextColumn("{task.completed}/{task.total}"), TimeElapsedColumn(),
                  console=console, transient=True) as prog:
        task = prog.add_task("walking the gait for F*", total=None)

        def progress(what: str, done: int, total: int) -> None:
            prog.update(task, description=what, completed=done, total=total)

        res = fit_contact_tube(g, s, degree, allowance, progress, src=str(steps),
                               gait_src=str(gait))
    with console.status("clfqp's model error along the playbacks (the gait walked once)"):
        try:
            res = tube_with_model_error(res, load_contact_run(gait))
        except ValueError as e:  # the held oracle fell: no controller to characterise
            res = replace(res, tube=replace(res.tube, source={
                **res.tube.source, "model_error": f"not fitted: {e}"}))
    paths = write_outputs(out, res, str(steps), str(gait))
    t, cred = res.tube, res.tube.credibility
    console.print(f"[bold]{steps}[/]: {len(res.playbacks)} flat prosthesis single supports "
                  f"played back in {res.seconds['playback']:.2f} s; stance phase in "
                  f"[{t.tau_lo:.3f}, {t.tau_hi:.3f}] (the controllers' phase, multi-contact "
                  "graph)")
    for k, why in res.skipped:
        console.print(f"  [yellow]skipped[/] single support {k}: {why}")
    _print_tube(console, t)
    me = t.model_error
    if me is not None:
        lo, hi = me.bounds(np.linspace(me.tau_lo, me.tau_hi, 201))
        console.print(f"model error of clfqp's model: stance phase [{me.tau_lo:.3f}, "
                      f"{me.tau_hi:.3f}], knee {lo[:, 0].min():.1f} .. {hi[:, 0].max():.1f}, "
                      f"ankle {lo[:, 1].min():.1f} .. {hi[:, 1].max():.1f} rad/s^2 (its "
                      f"robust term when the tube is given to experiments, run or sweep)")
    else:
        console.print(f"[yellow]model error[/]: {t.source.get('model_error', 'not fitted')}")
    console.print(f"wrote {paths['tube']}, {paths['figure'].name}, {paths['report'].name}")
    eps = cred["a_posteriori"]["epsilon_tube"]
    if eps >= 1.0:
        console.print(f"{len(res.playbacks)} single supports certify nothing (a posteriori "
                      f"eps {eps:.2f}): a tube a controller can lean on needs more strides; "
                      "pool walkway trials with `hpcosim mocap process A B C --out steps.npz`")
    conclude(coverage_verdict("force tube", cred, min_coverage))


def _print_tube(console: Console, t: ForceTube) -> None:
    """The tube's bounds per component and its certificate and credibility, printed."""
    cred = t.credibility
    table = Table(title=f"force tube (degree {t.degree}) around F* of gait {t.gait_hash}")
    for head in ("component", "lower min", "upper max", "mean width"):
        table.add_column(head, justify="right")
    lo, hi = t.delta_bounds(np.linspace(t.tau_lo, t.tau_hi, 201))
    for c, (name, unit) in enumerate(zip(("F_x", "F_z", "M_y"), ("N", "N", "N m"),
                                         strict=True)):
        table.add_row(f"{name} ({unit})", f"{lo[:, c].min():.1f}", f"{hi[:, c].max():.1f}",
                      f"{np.mean(hi[:, c] - lo[:, c]):.1f}")
    console.print(table)
    post = cred["a_posteriori"]
    console.print(f"certificate: inside {cred['certificate']['inside']}, optimal "
                  f"{cred['certificate']['optimal']}; a posteriori k = {post['k_tube']}, "
                  f"eps = {post['epsilon_tube']:.3f} at {cred['confidence']:.0%}; leave-one-out "
                  f"coverage {cred['leave_one_out']['coverage']:.2f}")
