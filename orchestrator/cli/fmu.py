"""``hpcosim fmu ...``: the human side as a standalone FMI 2.0 or 3.0 co-simulation FMU."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.table import Table

from orchestrator.cli.options import DeviceOpt, SubjectOpt
from orchestrator.cli.outcome import HOLDS, Verdict, conclude

if TYPE_CHECKING:
    from human_fmu import BuildInfo

fmu_app = typer.Typer(help="The human side (plant + human controller) as an FMU.",
                      no_args_is_help=True)


@fmu_app.command("build")
def build(
    gait: Annotated[Path, typer.Option("--gait", help="Gait file (hpcosim-gait JSON) the human "
                                       "tracks; its optimized ps start is the initial state.",
                                       dir_okay=False)],
    out: Annotated[Path, typer.Option("--out", help="FMU to write (.fmu).",
                                      dir_okay=False)] = Path("human.fmu"),
    subject: SubjectOpt = None,
    device: DeviceOpt = None,
    validate: Annotated[bool, typer.Option(help="Validate the result with fmpy.")] = True,
    fmi: Annotated[int, typer.Option("--fmi", min=2, max=3,
                                     help="FMI version: 2 (2.0) or 3 (3.0).")] = 2,
) -> None:
    """Generate C from the model, compile it into an FMI 2.0 (or, --fmi 3, FMI 3.0)
    co-simulation FMU (Linux x86-64 binary plus sources), and validate it.  The gait's
    graph is the FMU's: the paper's two domains, or a multi-contact gait (`gait fit
    --domains multicontact`, which carries its subject and device)."""
    from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind
    from human_fmu import build_fmu
    from orchestrator.cli.subject import subject_source

    console = Console()
    with console.status("building the FMU") as status:
        if artifact_kind(gait) == MULTICONTACT_KIND:
            info = _build_multicontact(gait, out, subject, device, fmi,
                                       lambda m: status.update(m))
        else:
            info = build_fmu(gait, out, subject_source(subject, gait), device,
                             progress=lambda m: status.update(m), fmi_version=fmi)
    t = Table(title=f"{info.path} ({info.size_bytes / 1024:.0f} KiB)")
    t.add_column("item")
    t.add_column("value")
    t.add_row("FMI version", f"{fmi}.0")
    t.add_row("GUID" if fmi == 2 else "instantiation token", info.guid)
    t.add_row("model hash / gait hash", f"{info.model_hash} / {info.gait_hash}")
    t.add_row("Bezier degree", str(info.degree))
    t.add_row("variables", ", ".join(f"{n} {k}" for k, n in info.variables.items()))
    t.add_row("build time (s)", ", ".join(f"{k} {v:.1f}" for k, v in info.seconds.items()))
    problems: list[str] = []
    if validate:
        from fmpy.validation import validate_fmu

        problems = validate_fmu(str(info.path))
        t.add_row("fmpy validate", "ok" if not problems else f"[red]{len(problems)} problems[/]")
    console.print(t)
    for p in problems:
        console.print(f"  [red]{p}[/]")
    conclude(Verdict(f"fmpy's validation of {info.path} found {len(problems)} problems: "
                     f"{problems[0]}") if problems else HOLDS)


def _build_multicontact(gait: Path, out: Path, subject: Path | None, device: Path | None,
                        fmi: int, say: Callable[[str], None]) -> BuildInfo:
    """The FMU of a multi-contact gait file, with the subject and device it carries."""
    from human_fmu import build_fmu
    from orchestrator.cosim.contact_controllers import load_tracked_gait

    if subject is not None or device is not None:
        raise typer.BadParameter(f"{gait} is a multi-contact gait: it carries its subject and "
                                 "device; drop --subject/--device", param_hint="--gait")
    say("reading the multi-contact gait")
    model, tracked = load_tracked_gait(gait)
    return build_fmu(tracked, out, model=model, progress=say, fmi_version=fmi)

