"""``hpcosim mocap ...``: motion-capture processing and the synthetic subject."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.table import Table

from orchestrator.cli.options import DeviceOpt, SubjectOpt

if TYPE_CHECKING:
    from characterization.mocap.session import TakeOutcome
    from hp_model.config import SubjectConfig

mocap_app = typer.Typer(help="Motion capture: takes to per-step joint trajectories.",
                        no_args_is_help=True)


@mocap_app.command("process")
def process(
    takes: Annotated[list[Path], typer.Argument(
        help="Motive CSV (.csv), C3D (.c3d) or TRC (.trc) take; several takes of one session "
        "(walkway trials) are processed one by one and their steps pooled.", dir_okay=False)],
    out: Annotated[Path, typer.Option("--out", help="Steps file to write (.npz or .json); "
                                      "the QA report and figures go next to it.",
                                      dir_okay=False)],
    subject: SubjectOpt = None,
    device: DeviceOpt = None,
    mapping: Annotated[Path | None, typer.Option(
        "--mapping", help="Limb mapping TOML (default: the synthetic subject's naming).",
        dir_okay=False)] = None,
    figures: Annotated[bool, typer.Option(help="Write the figures.")] = True,
) -> None:
    """Limb pitches, joint centres, joint angles and steps (ps/pns, tau) of one take, or of
    a session's takes pooled (a take that gives no step is a warning)."""
    from characterization.mocap.session import process_session

    console = Console()
    with console.status(f"processing {len(takes)} take(s)"):
        r = process_session(takes, out, subject=str(subject) if subject else None,
                            device=str(device) if device else None, mapping=mapping,
                            with_figures=figures)
    for t in r.takes:
        p = t.processed
        if p is None:
            console.print(f"[yellow]{t.line()}[/]", soft_wrap=True, highlight=False)
            continue
        console.print(f"[bold]{t.path}[/]: {len(p.time)} frames at {p.frame_rate:g} Hz; "
                      + t.line().split(": ", 1)[1], soft_wrap=True, highlight=False)
        _print_take(console, t)
    for w in r.warnings:  # one line each, never wrapped
        console.print(f"[yellow]warning:[/] {w}", soft_wrap=True, highlight=False)
    if r.subject is not None:
        _print_subject(console, r.subject, r.provenance)
    console.print(f"wrote {r.steps_path} ({r.artifact.n_steps} steps) and "
                  + ", ".join(x.name for x in r.report_paths), soft_wrap=True)


def _print_subject(console: Console, s: SubjectConfig, provenance: dict[str, str]) -> None:
    """The subject stored with the steps, and where each value came from (one line each)."""
    L = s.lengths
    console.print(f"subject '{s.name}': {s.body_mass:g} kg, {s.sex}, height "
                  f"{provenance.get('height_m', '?')} m; thigh {L.thigh:.3f}, shank "
                  f"{L.shank:.3f}, ankle height {L.ankle_height:.3f}, foot {L.foot:.3f}, heel "
                  f"{L.heel:.3f}, trunk {L.trunk:.3f} m", soft_wrap=True, highlight=False)
    for k, v in provenance.items():
        if k != "height_m" and v:
            console.print(f"  {k}: {v}", soft_wrap=True, highlight=False)


def _print_take(console: Console, take: TakeOutcome) -> None:
    """A processed take's joint centres, strides and double supports, dropped steps and
    warnings."""
    from characterization.mocap.foot_contact import double_supports

    p = take.processed
    assert p is not None
    t = Table(title="joint centres")
    for c in ("joint", "residual (mm)", "rotation SD (deg)", "well posed"):
        t.add_column(c)
    for j, f in p.joints.items():
        t.add_row(j, f"{f.residual_rms * 1000:.2f}", f"{f.rotation_sd * 57.29578:.1f}",
                  "yes" if f.well_posed else "[red]NO[/]")
    console.print(t)
    ev = Table(title="strides (the prosthesis foot's) and double supports")
    for c in ("stride", "frames", "time (s)", "speed (m/s)", "DS human lands (ms)",
              "DS prosthesis lands (ms)"):
        ev.add_column(c, justify="right")
    for k, st in enumerate(take.strides):
        ev.add_row(str(k), f"{st.start}-{st.end}", f"{st.time:.3f}", f"{st.speed:.3f}",
                   *(f"{1000 * st.double_support.get(f, float('nan')):.0f}"
                     for f in ("human", "prosthesis")))
    console.print(ev)
    for foot, fc in p.contacts.items():
        console.print(f"  {foot} foot touchdowns {list(fc.touchdowns)}, lift-offs "
                      f"{list(fc.liftoffs)} (frames)")
    both = double_supports(p.contacts, p.frame_rate)
    if both:
        console.print("  double supports: " + ", ".join(
            f"{d.lands} lands {d.start}-{d.end} ({1000 * d.seconds:.0f} ms)" for d in both),
            soft_wrap=True)
    if p.plates is not None:
        console.print(f"  {p.plates.line()}", soft_wrap=True, highlight=False)
    for d in p.dropped:
        console.print(f"  dropped {d.domain} step, frames {d.start}-{d.end}: {d.reason}")
    for w in p.warnings:
        console.print(f"[yellow]warning:[/] {w}", soft_wrap=True, highlight=False)


@mocap_app.command("inspect")
def inspect(
    take: Annotated[Path, typer.Argument(help="Motive CSV (.csv), C3D (.c3d) or TRC (.trc) take.",
                                         dir_okay=False)],
    mapping_out: Annotated[Path | None, typer.Option(
        "--mapping-out", help="Write a mapping skeleton (TOML) to edit for this take's "
        "names.", dir_okay=False)] = None,
    static: Annotated[Path | None, typer.Option(
        "--static", help="The session's static trial (standing): the skeleton's "
        "[calibration], with its legs' landmarks where their names tell.",
        dir_okay=False)] = None,
) -> None:
    """What a take holds (markers, rigid bodies, rate, length, gaps, an axes guess), and
    optionally a mapping to start from."""
    import os

    from characterization.mocap.files import read_take
    from characterization.mocap.inspection import TREADMILL_TRAVEL, mapping_skeleton, summarize
    from hp_model.atomic_io import atomic_write_bytes
    from orchestrator.cli.options import check_output_file

    if mapping_out is not None:
        check_output_file(mapping_out, "--mapping-out")
    elif static is not None:
        raise typer.BadParameter("the static trial goes into a mapping skeleton: give "
                                 "--mapping-out too", param_hint="--static")
    t = read_take(take)
    s = summarize(t)
    console = Console()
    console.print(f"[bold]{take}[/]: {s.n_frames} frames at {s.frame_rate:g} Hz "
                  f"({s.duration:.2f} s); the file's up axis {s.format_up}")
    if s.up_axis:
        console.print(f"axes guess: up {s.up_axis} (the markers span {s.up_span:.2f} m along "
                      f"it per frame; {s.up_reason}), walking "
                      + (f"{s.walk_axis} ({s.walk_travel:.2f} m of travel)"
                         if s.walk_axis and s.walk_travel >= TREADMILL_TRAVEL
                         else f"unknown: the markers travel {s.walk_travel:.2f} m (a treadmill? "
                         "'forward = \"auto\"' then takes the feet's heel -> toe direction)"
                         if s.walk_axis else "unknown"))
    tab = Table(title="columns")
    for c in ("kind", "name", "valid %", "longest gap (frames)"):
        tab.add_column(c)
    for col in s.columns:
        tab.add_row(col.kind, col.name, f"{100 * col.valid:.1f}", str(col.longest_gap))
    console.print(tab)
    if s.model_outputs:
        console.print("the lab's model outputs (not markers): "
                      + ", ".join(f"{n} {k}" for k, n in s.model_outputs))
    if mapping_out is not None:
        trial = read_take(static) if static is not None else None
        where = (os.path.relpath(static.resolve(), mapping_out.resolve().parent)
                 if static is not None else "")
        atomic_write_bytes(mapping_out, mapping_skeleton(t, trial, where).encode())
        console.print(f"wrote {mapping_out}: edit every entry, then hpcosim mocap process "
                      f"{take} --mapping {mapping_out} --out steps.npz")


@mocap_app.command("synth")
def synth(
    out: Annotated[Path, typer.Option("--out", help="Output folder.", file_okay=False)],
    steps: Annotated[int, typer.Option("--steps", min=1, help="Step cycles (strides).")] = 37,
    seed: Annotated[int, typer.Option("--seed", help="Random seed.")] = 0,
    noise_mm: Annotated[float, typer.Option(min=0, help="Marker noise SD per coordinate, "
                                            "mm.")] = 0.5,
    dropout_rate: Annotated[float, typer.Option(min=0, help="Marker occlusions per marker "
                                                "per second.")] = 0.5,
    dropout_frames: Annotated[int, typer.Option(min=1, help="Longest occlusion, "
                                                "frames.")] = 10,
    rate: Annotated[float, typer.Option(min=1, help="Frame rate, Hz.")] = 120.0,
    source: Annotated[str, typer.Option(
        help="'model': the model walks a reference gait (hybrid simulator, dynamically "
        "consistent); 'template': a kinematic template with double support; 'person': the "
        "model of a multi-contact gait (--gait) walks it, with its double supports.")
    ] = "model",
    gait: Annotated[Path | None, typer.Option(
        "--gait", help="Reference gait of --source model (default: the packaged gait of the "
        "default subject and device); the multi-contact gait of --source person (default: "
        "the packaged synthetic person's).",
        dir_okay=False)] = None,
    variability: Annotated[float, typer.Option(
        min=0, help="--source model: SD of the interior Bezier coefficients per step, "
        "rad.")] = 0.03,
    speed_variability: Annotated[float, typer.Option(
        min=0, help="--source model: relative SD of the hip velocity per step.")] = 0.03,
    subject: SubjectOpt = None,
    device: DeviceOpt = None,
) -> None:
    """A synthetic subject on the prosthesis: Motive CSV, C3D and ground truth."""
    import hp_model
    from characterization.mocap.synthetic_subject import (
        SynthOptions,
        SynthSource,
        synthesize,
        write_synthetic,
    )
    from characterization.mocap.take import MocapError

    try:
        motion = SynthSource(source)
    except ValueError as e:  # as synthesize says it, before the model is loaded
        raise MocapError(f"synthetic subject: {e}") from None
    console = Console()
    opts = SynthOptions(n_strides=steps, seed=seed, noise_mm=noise_mm,
                        dropout_rate=dropout_rate, dropout_max_frames=dropout_frames,
                        rate=rate, source=motion, gait_file=str(gait) if gait else None,
                        sigma=variability, sigma_v_hip=speed_variability)
    if motion == SynthSource.PERSON:
        from characterization.gait.person_synth import synthesize_person, write_person
        from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind

        if gait is not None and artifact_kind(gait) != MULTICONTACT_KIND:
            raise typer.BadParameter("--source person walks a multi-contact gait file (gait "
                                     "fit --domains multicontact)", param_hint="--gait")
        if subject is not None or device is not None:
            raise typer.BadParameter("--source person walks the gait's own subject and "
                                     "device; drop --subject/--device", param_hint="--gait")
        with console.status("walking the gait's model"):
            s, person = synthesize_person(gait, opts)
            paths = write_person(out, s, person, opts)
    else:
        with console.status("generating the synthetic take"):
            model = hp_model.load_model(str(subject) if subject else None,
                                        str(device) if device else None)
            s = synthesize(model, opts)
            paths = write_synthetic(out, s, opts)
    console.print(f"{steps} step cycles ({source}), {s.take.n_frames} frames at {rate:g} Hz, "
                  f"{len(s.truth['step_domain'])} complete steps in the truth")
    for k, v in paths.items():
        console.print(f"  {k}: {v}")
    if motion == SynthSource.PERSON:
        console.print(f"process it as the person it is: hpcosim mocap process {paths['csv']} "
                      f"--subject {paths['subject']} --out steps.npz")
