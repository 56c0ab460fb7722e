"""``hpcosim gait export`` and ``hpcosim recording export``: a gait or a run as CSV and
OpenSim ``.mot`` files (:mod:`characterization.gait.export`, :mod:`orchestrator.cosim.export`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from orchestrator.cli.options import DeviceOpt, SubjectOpt


def gait_export(
    gait: Annotated[Path, typer.Argument(help="Gait file (`hpcosim gait fit`).",
                                         dir_okay=False)],
    out: Annotated[Path, typer.Option("--out", help="Folder to write stride.csv, "
                                      "kinematics.mot and ground_reactions.mot into (made "
                                      "if missing).", file_okay=False)],
    subject: SubjectOpt = None,
    device: DeviceOpt = None,
) -> None:
    """One stride of the gait (ps then pns, time from 0) as CSV and OpenSim .mot files:
    joint angles, joint torques, ground reactions and socket force as CSV (SI units, angles
    in rad), the coordinates and the ground reactions as .mot (angles in degrees; OpenSim's
    axes, y up)."""
    import hp_model
    from characterization.gait.export import export_gait
    from hp_model.gait_artifact import load_gait
    from orchestrator.cli.options import check_output_folder

    check_output_folder(out)
    from orchestrator.cli.subject import subject_source

    model = hp_model.load_model(subject_source(subject, gait),
                                str(device) if device else None)
    g = load_gait(gait, model.parameter_hash())
    files = export_gait(g, model, out, src=str(gait))
    console = Console()
    for f in files:
        console.print(f"wrote {f}")
    if len(files) < 3:
        console.print(f"no ground reactions: {gait} stores no constraint wrenches "
                      "(trajectory lam)")


def recording_export(
    recording: Annotated[Path, typer.Argument(help="MCAP recording (`hpcosim run --record`).",
                                              dir_okay=False)],
    out: Annotated[Path, typer.Option("--out", help="CSV file to write.", dir_okay=False)],
    mot: Annotated[Path | None, typer.Option(
        "--mot", help="Also write the coordinates as an OpenSim .mot file (degrees).",
        dir_okay=False)] = None,
) -> None:
    """A run's main channels as CSV, one row per control period (time, domain, step, phase,
    the ground-truth coordinates and socket force, the applied torques, the controller's V
    and rho; units in the header), and with --mot its coordinates as an OpenSim .mot."""
    from orchestrator.cli.options import check_output_file
    from orchestrator.cosim.export import export_recording

    check_output_file(out)
    if mot is not None:
        check_output_file(mot, "--mot")
    r = export_recording(recording, out, mot)
    console = Console()
    console.print(f"wrote {out} ({r.t.size} rows, {r.t[-1] - r.t[0]:.3f} s)")
    if mot is not None:
        console.print(f"wrote {mot}")


def register() -> None:
    """Add ``export`` to the ``gait`` and ``recording`` groups."""
    from orchestrator.cli.cosim import recording_app
    from orchestrator.cli.gait import gait_app

    gait_app.command("export", short_help="One stride of the gait as CSV and OpenSim .mot "
                     "files.")(gait_export)
    recording_app.command("export", short_help="A run's main channels as CSV (and OpenSim "
                          ".mot).")(recording_export)
