"""The ``hpcosim`` command line.

Every verb is a thin layer over a plain Python function.  Exit status
(:mod:`orchestrator.cli.outcome`): 0 done and the result holds; 1 done and the result is
negative (one line ``hpcosim: check failed: ...``); 2 errors a user can cause (bad files,
bad values: one line ``hpcosim: error: ...``); 3 an internal error (one line; the traceback
with ``HPCOSIM_DEBUG=1``).  Every path option is taken from the user's working folder
(:mod:`orchestrator.cli.paths`).
"""

from __future__ import annotations

import contextlib
import os
import sys
import traceback
from pathlib import Path
from typing import Annotated, Protocol

import typer
from rich.console import Console
from rich.table import Table

import hp_model
from characterization.gait.bezier_fit import FitError
from characterization.mocap.take import MocapError
from hp_model.artifacts import ArtifactError
from hp_model.compiled import CompileBackend, CompileError
from hp_model.config import ConfigError
from hp_model.tree import ModelError
from orchestrator.cli import experiments as experiments_cli
from orchestrator.cli.cosim import register as register_cosim
from orchestrator.cli.export import register as register_export
from orchestrator.cli.fmu import fmu_app
from orchestrator.cli.gait import gait_app
from orchestrator.cli.mocap import mocap_app
from orchestrator.cli.outcome import BAD_INPUT, INTERNAL, NEGATIVE, conclude, model_check_verdict
from orchestrator.cli.paths import absolutize
from orchestrator.cli.sweep import sweep_app
from orchestrator.cli.tube import tube_app

app = typer.Typer(
    name="hpcosim",
    help="Motion capture to a model-based powered-prosthesis controller, proven in a "
    "human-prosthesis co-simulation (Gehlhar, Chen, Ames, IROS 2020).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
model_app = typer.Typer(help="The human-prosthesis model.", no_args_is_help=True)
app.add_typer(model_app, name="model")
app.add_typer(mocap_app, name="mocap")
app.add_typer(gait_app, name="gait")
app.add_typer(tube_app, name="tube")
app.add_typer(fmu_app, name="fmu")
app.add_typer(sweep_app, name="sweep")
app.command("experiments")(experiments_cli.experiments)
app.command("demo")(experiments_cli.demo)
register_cosim(app)
register_export()  # `gait export`, `recording export`

#: exceptions that are the user's input, reported in one line (FitError covers
#: characterization.tube.playback.PlaybackError and tube.fit.TubeFitError without importing
#: scipy at start-up; ArtifactError: gait and tube files)
USER_ERRORS: tuple[type[BaseException], ...] = (ConfigError, ModelError, CompileError,
                                               FileNotFoundError, MocapError, FitError,
                                               ArtifactError)

SubjectOpt = Annotated[Path | None, typer.Option(
    "--subject", help="Subject TOML (default: the shipped example subject).",
    dir_okay=False)]
DeviceOpt = Annotated[Path | None, typer.Option(
    "--device", help="Device TOML (default: the shipped AMPRO3 + iWalk estimates).",
    dir_okay=False)]


def _version(value: bool) -> None:
    if value:
        typer.echo(f"hpcosim {hp_model.__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                          help="Print the version and exit.")] = False,
) -> None:
    """hpcosim: from motion capture to a prosthesis controller you can trust."""


@model_app.command("check")
def model_check(
    subject: SubjectOpt = None,
    device: DeviceOpt = None,
    backend: Annotated[CompileBackend, typer.Option(
        help="auto (compiled C when a compiler exists), c, or sx (CasADi interpreter).")
    ] = CompileBackend.AUTO,
) -> None:
    """Build the 12-DOF model and the 5-DOF prosthesis subsystem, evaluate them, and check
    physics that fixes the answers (static balance, impact, subsystem consistency)."""
    from orchestrator.cli.model_check import run_checks

    console = Console()
    with console.status("building and compiling the models (cached after the first run)"):
        model = hp_model.load_model(
            str(subject) if subject else None, str(device) if device else None)
        rows, timing = run_checks(model, backend=backend)
    s, d = model.subject, model.device
    console.print(f"[bold]{model.name}[/]: subject '{s.name}' ({s.body_mass:g} kg, {s.sex}), "
                  f"device '{d.name}'")
    console.print(f"  {model.nq} coordinates: {', '.join(model.coord_names)}")
    console.print(f"  total mass {model.tree.total_mass:.3f} kg (prosthesis "
                  f"{model.prosthesis_mass:.3f} kg); domains "
                  + ", ".join(f"{n} ({dm.n_constraints} constraints)"
                              for n, dm in model.domains.items())
                  + f"; backend {model.numeric(backend).backend}")
    table = Table(title="model self-check")
    table.add_column("check")
    table.add_column("value", justify="right")
    table.add_column("expected", justify="right")
    table.add_column("ok", justify="center")
    for r in rows:
        table.add_row(r.name, r.value, r.expected, "[green]yes[/]" if r.ok else "[red]NO[/]")
    table.add_row("D, H, J, Jdot qd (12 DOF) per call (us)", f"{timing['terms_ps_us']:.2f}", "",
                  "")
    table.add_row("constrained dynamics (qdd, lam) per call (us)",
                  f"{timing['dyn_ps_us']:.2f}", "", "")
    table.add_row("prosthesis 4-state form f_p, g_m, g_s per call (us)",
                  f"{timing['sub_reduced_us']:.2f}", "", "")
    console.print(table)
    conclude(model_check_verdict(rows))


class _ClickError(Protocol):
    """What the CLI reads of a click usage error (``click.ClickException``)."""

    def format_message(self) -> str: ...


def _click_exceptions() -> tuple[type[_ClickError], ...]:
    """Usage-error classes of every click a CLI may raise: typer >= 0.16 vendors its own
    (``typer._click``) beside an installed click."""
    out: list[type[_ClickError]] = []
    for mod in ("typer._click.exceptions", "click.exceptions"):
        with contextlib.suppress(ImportError):
            out.append(__import__(mod, fromlist=["ClickException"]).ClickException)
    return tuple(out)


#: user errors of modules the CLI loads only when a verb needs them: (module, class)
#: (the gait optimizer and the FMU build are not loaded by the verbs that do not use them)
LAZY_USER_ERRORS = (("orchestrator.cosim.recording", "RecordingError"),
                    ("orchestrator.cosim.config", "CosimError"),
                    ("bus_schemas.transport.bus_config", "BusConfigError"),
                    ("characterization.gait.phzd", "GaitOptimizationError"),
                    ("characterization.gait.multicontact", "MultiContactError"),
                    ("human_fmu.build", "FmuBuildError"))
#: a check that ran and failed (exit 1): (module, class), as :data:`LAZY_USER_ERRORS`
LAZY_CHECK_FAILURES = (("characterization.gait.phzd", "GaitVerificationError"),)


def _loaded_user_errors(
        which: tuple[tuple[str, str], ...] = LAZY_USER_ERRORS) -> tuple[type[BaseException], ...]:
    """The classes of ``which`` whose module is loaded (an exception of one can only come
    from a loaded module)."""
    out = []
    for mod, name in which:
        m = sys.modules.get(mod)
        if m is not None:
            out.append(getattr(m, name))
    return tuple(out)


def _os_error(e: OSError) -> str:
    """``FILE: reason`` of an operating-system error (the file it names, if any)."""
    what = e.strerror or str(e)
    return _one_line(f"{e.filename}: {what}" if e.filename else what)


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _internal_error(e: Exception) -> int:
    """A bug: one line (the traceback with ``HPCOSIM_DEBUG=1``), exit 3 (never 1, which
    means a negative result)."""
    if os.environ.get("HPCOSIM_DEBUG"):
        traceback.print_exception(e)
    print(f"hpcosim: internal error: {type(e).__name__}: {_one_line(str(e))} (a bug; "
          "HPCOSIM_DEBUG=1 prints the traceback)", file=sys.stderr)
    return INTERNAL


def main(argv: list[str] | None = None) -> int:
    """Console entry point: run the app, turning user errors into one-line messages."""
    absolutize(app)  # every command, those registered after this module too
    try:
        # without standalone mode click returns (not raises) a command's typer.Exit code
        rc = app(args=argv, standalone_mode=False)
    except typer.Exit as e:
        return e.exit_code
    except (typer.Abort, KeyboardInterrupt):  # Ctrl-C where a verb does not handle it
        print("hpcosim: aborted", file=sys.stderr)
        return 130
    except USER_ERRORS as e:
        print(f"hpcosim: error: {_one_line(str(e))}", file=sys.stderr)
        return BAD_INPUT
    except OSError as e:  # the environment: a full disk, a read-only folder, a size limit
        print(f"hpcosim: error: {_os_error(e)}", file=sys.stderr)
        return BAD_INPUT
    except Exception as e:  # click usage errors carry their own exit code
        if isinstance(e, _loaded_user_errors(LAZY_CHECK_FAILURES)):
            print(f"hpcosim: check failed: {_one_line(str(e))}", file=sys.stderr)
            return NEGATIVE
        if isinstance(e, _loaded_user_errors()):
            print(f"hpcosim: error: {_one_line(str(e))}", file=sys.stderr)
            return BAD_INPUT
        if isinstance(e, _click_exceptions()):
            print(f"hpcosim: error: {_one_line(e.format_message())}", file=sys.stderr)
            return int(getattr(e, "exit_code", BAD_INPUT))
        return _internal_error(e)
    return rc if isinstance(rc, int) else 0


absolutize(app)  # the verbs above: paths from the user's working folder

if __name__ == "__main__":
    sys.exit(main())
