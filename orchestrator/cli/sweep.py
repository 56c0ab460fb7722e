"""``hpcosim sweep``: robustness sweeps on Dask (registered in :mod:`orchestrator.cli`).

    hpcosim sweep [run] SPEC.toml --out DIR [--workers N | --scheduler ADDRESS] [--gait G]
        [--tube T] [--draws N] [--steps N] [--backend simulator|fmu] [--no-report]
    hpcosim sweep report DIR
    hpcosim sweep replay DIR CONTROLLER/FAMILY/DRAW [--backend simulator|fmu]

(every option: docs/cli.md, generated from these verbs).  Exit 1 when runs have no result
(interrupted, infrastructure errors), or a replayed run differs or is not stored.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table
from typer.core import TyperGroup

from orchestrator.cli.outcome import HOLDS, Verdict, conclude, sweep_verdict
from orchestrator.modes import SweepBackend


class _DefaultRun(TyperGroup):
    """``hpcosim sweep SPEC ...`` means ``hpcosim sweep run SPEC ...``."""

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        if args and args[0] not in self.commands and not args[0].startswith("-"):
            args = ["run", *args]
        return super().parse_args(ctx, args)


sweep_app = typer.Typer(cls=_DefaultRun, no_args_is_help=True,
                        help="Robustness sweeps on Dask: run a spec, report, replay one run.")


def _fail(msg: str) -> typer.Exit:
    typer.echo(f"hpcosim: error: {msg}", err=True)
    return typer.Exit(2)


def _cells_table(s: dict[str, Any]) -> Table:
    t = Table(title=f"sweep {s['spec']['name']}: {s['runs_stored']}/{s['runs_expected']} runs")
    for c in ("family", "controller", "runs", "errors", "success rate", "Wilson 95 %",
              "knee RMS median (deg)"):
        t.add_column(c, justify="right" if c not in ("family", "controller") else "left")
    import math

    for c in s["cells"]:
        ci, med = c["wilson95"], c["knee_rms_ps_rad"]["median"]
        t.add_row(c["family"], c["controller"], str(c["runs"]), str(c["errors"]),
                  "-" if c["success_rate"] is None else f"{c['success_rate']:.3f}",
                  "-" if ci is None else f"[{ci[0]:.3f}, {ci[1]:.3f}]",
                  "-" if med is None else f"{math.degrees(med):.2f}")
    return t


def _print_report(console: Console, s: dict[str, Any], out: Path) -> None:
    """The cells table and, per cell, the worst run with the command reproducing it."""
    console.print(_cells_table(s))
    for c in s["cells"]:
        if c["worst"]:
            w = c["worst"][0]
            console.print(f"worst {c['controller']} / {c['family']}: "
                          f"{w['reason'] or 'completed'}\n  {w['replay']}"
                          + (f"\n  {w['cosim']}" if w["cosim"] else ""), highlight=False,
                          markup=False, soft_wrap=True)
    console.print(f"wrote {out}/report.md, report.json and figures")


def _completeness(out: Path, keys: set[str]) -> Verdict:
    """Whether every run of ``keys`` has a result to keep in ``out`` (an infrastructure
    error is retried by a resume, so it is not one)."""
    from orchestrator.sweep.store import done_keys

    return sweep_verdict(len(keys), len(keys & done_keys(out)))


def _manifest_keys(spec: dict[str, Any]) -> set[str]:
    """The run keys of a sweep folder's stored spec (as ``draws.run_keys`` makes them)."""
    from orchestrator.sweep.draws import ORACLE

    ctrls = ([ORACLE] if spec.get("label_walkable") else []) + list(spec["controllers"])
    return {f"{c}/{f}/{i}" for c in ctrls for f in spec["families"]
            for i in range(int(spec["draws"]))}


@sweep_app.command("run")
def run(
    spec: Annotated[Path, typer.Argument(help="Sweep spec (TOML).", dir_okay=False)],
    out: Annotated[Path, typer.Option("--out", help="Output folder (resumed if it holds "
                                      "this sweep).", file_okay=False)],
    scheduler: Annotated[str | None, typer.Option(help="Address of an existing Dask "
                                                  "scheduler (default: a local cluster).")
                         ] = None,
    workers: Annotated[int | None, typer.Option(min=1, help="Local cluster worker processes "
                                                "(default: the machine's cores).")] = None,
    gait: Annotated[Path | None, typer.Option(help="Override the spec's gait file.",
                                              dir_okay=False)] = None,
    tube: Annotated[Path | None, typer.Option(help="Override the spec's tube file.",
                                              dir_okay=False)] = None,
    draws: Annotated[int | None, typer.Option(min=1, help="Override the spec's draws.")
                     ] = None,
    steps: Annotated[int | None, typer.Option(min=1, help="Override the spec's steps per "
                                              "run.")] = None,
    backend: Annotated[SweepBackend | None, typer.Option(help="Override: simulator or fmu.")
                       ] = None,
    report: Annotated[bool, typer.Option(help="Write the report when the sweep ends.")
                      ] = True,
) -> None:
    """Run every (controller, family, draw) of SPEC on Dask, streaming results to
    OUT/results; an interrupted sweep resumes from OUT."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from orchestrator.cli.options import check_output_folder
    from orchestrator.sweep.engine import SweepError, run_sweep
    from orchestrator.sweep.report import write_report
    from orchestrator.sweep.spec import load_spec

    if scheduler is not None and workers is not None:
        raise _fail("--workers applies to the local cluster; not with --scheduler")
    over = {"gait": str(gait.resolve()) if gait else None,
            "tube": str(tube.resolve()) if tube else None, "draws": draws, "steps": steps,
            "backend": backend}
    sp = load_spec(spec, over)
    if out.exists() and not out.is_dir():
        raise _fail(f"--out {out}: not a folder")
    check_output_folder(out)  # a read-only place fails here, before any work
    console = Console()
    label = " (+ the walkability oracle)" if sp.label_walkable else ""
    console.print(f"sweep [bold]{sp.name}[/]: {len(sp.controllers)} controllers{label} x "
                  f"{len(sp.families)} families x {sp.draws} draws = {sp.n_runs} runs, "
                  f"{sp.steps} steps each, backend {sp.backend}")
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TextColumn("{task.fields[rate]:.0f} runs/min, {task.fields[errors]} "
                             "errors"), TimeElapsedColumn(), TimeRemainingColumn(),
                  console=console) as prog:
        task = prog.add_task("starting", total=None, rate=0.0, errors=0)

        def progress(done: int, total: int, errors: int, rate: float) -> None:
            prog.update(task, description="runs", completed=done, total=total, rate=rate,
                        errors=errors)

        try:
            o = run_sweep(sp, out, scheduler=scheduler, workers=workers, progress=progress,
                          say=lambda m: prog.update(task, description=m))
        except SweepError as e:
            prog.stop()
            raise _fail(str(e)) from None
        except KeyboardInterrupt:
            prog.stop()
            console.print(f"interrupted: finished runs are saved in {out}; run the same "
                          "command again to resume")
            raise typer.Exit(130) from None
    if o.done == 0 and o.skipped == o.total:
        console.print(f"all {o.total} runs are already in {out}")
    else:
        console.print(f"{o.done} runs in {o.wall_s:.1f} s on {o.workers} "
                      f"worker{'s' if o.workers != 1 else ''} "
                      f"({o.runs_per_min:.1f} runs/min, setup {o.setup_s:.1f} s); "
                      f"{o.skipped} already done; {o.errors} errors")
    if report:
        s = write_report(out)
        _print_report(console, s, out)
    from orchestrator.sweep.draws import run_keys

    conclude(_completeness(out, {k.text for k in run_keys(sp)}))


@sweep_app.command("report")
def report_cmd(
    out: Annotated[Path, typer.Argument(help="Sweep output folder.", file_okay=False)],
) -> None:
    """Write OUT/report.md, report.json and figures from the stored results."""
    from orchestrator.sweep.report import write_report

    s = write_report(out)
    _print_report(Console(), s, out)
    conclude(_completeness(out, _manifest_keys(s["spec"])))


@sweep_app.command("replay")
def replay_cmd(
    out: Annotated[Path, typer.Argument(help="Sweep output folder.", file_okay=False)],
    key: Annotated[str, typer.Argument(help="Run key CONTROLLER/FAMILY/DRAW, e.g. "
                                       "clfqp/human/17.")],
    backend: Annotated[SweepBackend | None, typer.Option(help="Run on this backend instead "
                                                         "(simulator or fmu).")] = None,
) -> None:
    """Rerun one run of a sweep in this process and compare it with its stored result
    (exit 1 if any column differs)."""
    from orchestrator.sweep.replay import replay_run

    try:
        r = replay_run(out, key, backend)
    except ValueError as e:
        raise _fail(str(e)) from None
    console = Console()
    t = Table(title=f"replay {r.key}")
    t.add_column("column")
    t.add_column("now")
    t.add_column("stored")
    for c in ("steps_completed", "success", "reason", "duration_s", "knee_rms_ps_rad",
              "max_torque_knee", "max_torque_ankle", "error"):
        t.add_row(c, str(r.row.get(c)), "-" if r.stored is None else str(r.stored.get(c)))
    console.print(t)
    if r.stored is None:
        console.print("not in the stored results (not run yet)")
    elif r.identical:
        console.print("identical to the stored result (every column)")
    else:
        console.print("DIFFERS from the stored result in: " + ", ".join(r.differences))
    conclude(Verdict(f"{r.key} is not in the stored results: nothing to compare")
             if r.stored is None else HOLDS if r.identical else
             Verdict(f"{r.key} differs from the stored result in: "
                     + ", ".join(r.differences)))
