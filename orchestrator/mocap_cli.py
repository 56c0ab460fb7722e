"""``hpcosim mocap ...``: motion-capture processing and the synthetic subject."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from orchestrator.cli_options import DeviceOpt, SubjectOpt

mocap_app = typer.Typer(help="Motion capture: takes to per-step joint trajectories.",
                        no_args_is_help=True)


@mocap_app.command("process")
def process(
    take: Annotated[Path, typer.Argument(help="Motive CSV (.csv) or C3D (.c3d) take.",
                                         dir_okay=False)],
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
    """Limb pitches, joint centres, joint angles and steps (ps/pns, tau) of one take."""
    from characterization.mocap_files import process_file

    console = Console()
    with console.status(f"processing {take}"):
        r = process_file(take, out, subject=str(subject) if subject else None,
                         device=str(device) if device else None, mapping=mapping,
                         with_figures=figures)
    p = r.processed
    n_ps = sum(s.domain == "ps" for s in p.steps)
    console.print(f"[bold]{take}[/]: {len(p.time)} frames at {p.frame_rate:g} Hz; steps "
                  f"{n_ps} ps + {len(p.steps) - n_ps} pns kept, {len(p.dropped)} dropped")
    t = Table(title="joint centres")
    for c in ("joint", "residual (mm)", "rotation SD (deg)", "well posed"):
        t.add_column(c)
    for j, f in p.joints.items():
        t.add_row(j, f"{f.residual_rms * 1000:.2f}", f"{f.rotation_sd * 57.29578:.1f}",
                  "yes" if f.well_posed else "[red]NO[/]")
    console.print(t)
    for d in p.dropped:
        console.print(f"  dropped {d.domain} step, frames {d.start}-{d.end}: {d.reason}")
    console.print(f"wrote {r.steps_path} and " + ", ".join(x.name for x in r.report_paths))


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
        "consistent); 'template': a kinematic template with double support.")] = "model",
    gait: Annotated[Path | None, typer.Option(
        "--gait", help="Reference gait of --source model (default: the packaged gait of the "
        "default subject and device).", dir_okay=False)] = None,
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
    from characterization.synthetic_subject import SynthOptions, synthesize, write_synthetic

    console = Console()
    opts = SynthOptions(n_strides=steps, seed=seed, noise_mm=noise_mm,
                        dropout_rate=dropout_rate, dropout_max_frames=dropout_frames,
                        rate=rate, source=source, gait_file=str(gait) if gait else None,
                        sigma=variability, sigma_v_hip=speed_variability)
    with console.status("generating the synthetic take"):
        model = hp_model.load_model(str(subject) if subject else None,
                                    str(device) if device else None)
        s = synthesize(model, opts)
        paths = write_synthetic(out, s, opts)
    console.print(f"{steps} step cycles ({source}), {s.take.n_frames} frames at {rate:g} Hz, "
                  f"{len(s.truth['step_domain'])} complete steps in the truth")
    for k, v in paths.items():
        console.print(f"  {k}: {v}")
