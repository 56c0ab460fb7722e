"""``hpcosim controller serve``, ``hpcosim run``, ``hpcosim replay``, ``hpcosim tube refit``."""

from __future__ import annotations

import glob
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from orchestrator.cli.options import DeviceOpt, SubjectOpt, check_output_folder
from orchestrator.cli.outcome import (
    conclude,
    cosim_verdict,
    coverage_verdict,
    replay_verdict,
)
from orchestrator.cli.paths import absolute
from orchestrator.cli.tube import tube_app  # `tube refit` joins `tube fit`
from orchestrator.modes import CosimMode
from prosthesis_controller.interface import ControllerName
from prosthesis_controller.registry import describe

controller_app = typer.Typer(help="The prosthesis controller node.", no_args_is_help=True)
recording_app = typer.Typer(help="Co-simulation recordings (MCAP).", no_args_is_help=True)

#: the registry's controllers and what each is, as the help of every --controller option
CONTROLLER_HELP = describe("; ") + "."
ControllerOpt = Annotated[ControllerName, typer.Option("--controller", help=CONTROLLER_HELP)]
GaitOpt = Annotated[Path, typer.Option("--gait", help="Gait file.", dir_okay=False)]
TubeOpt = Annotated[Path, typer.Option("--tube", help="Force-tube file.", dir_okay=False)]


@controller_app.command("serve")
def serve(
    controller: ControllerOpt,
    gait: GaitOpt,
    tube: TubeOpt,
    bus: Annotated[Path | None, typer.Option("--bus", help="Bus config (TOML/JSON): "
                                             "interface zenoh/virtual/socketcan/...")] = None,
    interface: Annotated[str | None, typer.Option(help="Override: python-can interface.")
                         ] = None,
    run_id: Annotated[str | None, typer.Option(help="Override: zenoh run id.")] = None,
    channel: Annotated[str | None, typer.Option(help="Override: CAN channel (non-zenoh).")
                       ] = None,
    listen: Annotated[str | None, typer.Option(help="Override: zenoh listen endpoints.")
                      ] = None,
    connect: Annotated[str | None, typer.Option(help="Override: zenoh connect endpoints.")
                       ] = None,
    watchdog_ms: Annotated[float, typer.Option(min=0.1, help="Safe state after this long without "
                                               "measurements.")] = 50.0,
    key: Annotated[Path | None, typer.Option(
        "--key", dir_okay=False, help="zenoh: the key file (one line, a secret of 16+ "
        "characters, mode 0600) the plant authenticates with (its bus config's key_file); "
        "required over zenoh (docs/cosim.md, who may drive the controller).")] = None,
) -> None:
    """Serve a controller on a CAN bus until the plant leaves or SIGTERM/SIGINT."""
    from orchestrator.cli.subject import subject_source
    from prosthesis_controller.node import Artifacts, bus_config_from_args, run_node

    cfg = bus_config_from_args(str(bus) if bus else None, interface=interface, run_id=run_id,
                               channel=channel, listen=listen, connect=connect,
                               key_file=str(key) if key else None)
    s = run_node(controller, Artifacts(str(gait), str(tube), subject_source(None, gait)), cfg,
                 watchdog=watchdog_ms * 1e-3)  # the gait's own subject
    Console(stderr=True).print(f"controller node: {s}")


def run(
    controller: ControllerOpt,
    gait: Annotated[Path, typer.Option(
        "--gait", help="Gait file: the paper's graph (with --tube), or a multi-contact gait "
        "(gait fit --domains multicontact: its subject and device; clfqp, phase-pd, pd or "
        "passive).",
        dir_okay=False)],
    tube: Annotated[Path | None, typer.Option(
        "--tube", help="Force-tube file (tube fit): the paper's graph needs it; a "
        "multi-contact gait's gives clfqp its robust term (the tube's model-error bound).",
        dir_okay=False)] = None,
    library: Annotated[Path | None, typer.Option(
        "--library", help="A gait library of the multi-contact gait's person (gait library): "
        "the person walks it at --speed-profile and clfqp follows the person's speed over "
        "it (its controllers made once, about a minute, and cached).", dir_okay=False)] = None,
    speed_profile: Annotated[str | None, typer.Option(
        "--speed-profile", help="With --library: the walking speed commanded over time, "
        "t:v pairs (s:m/s) linear between, e.g. 0:0.8,20:1.2,40:0.8 (default: the gait's "
        "own speed).")] = None,
    steps: Annotated[int, typer.Option(min=1, help="Stop after this many impacts.")] = 20,
    perturb: Annotated[str, typer.Option(help="none, drop, delay, duplicate, "
                                         "corrupt-counter, corrupt-checksum, corrupt-length, "
                                         "kill, hang (CASE[:start[:every[:count]]]), "
                                         "stall[:START[:MS]] (the plant sleeps MS ms), "
                                         "human[:AMPLITUDE[:SEED]].")] = "none",
    mode: Annotated[CosimMode, typer.Option(help="lockstep or realtime.")
                    ] = CosimMode.LOCKSTEP,
    record: Annotated[Path | None, typer.Option(help="MCAP file to write.", dir_okay=False)
                      ] = None,
    fmu: Annotated[Path | None, typer.Option(help="Human FMU (default: built and cached "
                                             "for the gait).", dir_okay=False)] = None,
    max_time: Annotated[float, typer.Option(min=0.001, help="Simulation time limit [s].")
                        ] = 60.0,
    pin: Annotated[bool, typer.Option(help="Run the plant and the controller each on its "
                                      "own CPU.")] = True,
    subject: SubjectOpt = None,
    device: DeviceOpt = None,
) -> None:
    """Co-simulate the human FMU with the controller in its own process over zenoh.  A
    multi-contact gait's run builds (and caches) its FMU and its controller's tables from
    the gait file."""
    from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind
    from orchestrator.cosim.config import CosimConfig, CosimError
    from orchestrator.cosim.master import run_cosim

    console = Console()
    if record is not None:  # before the FMU build and the controller start
        check_output_folder(record.parent, "--record")
    from orchestrator.cli.subject import subject_source

    # --subject, else the gait's own (a multi-contact gait's model is its own)
    who = (str(subject) if subject else None) if artifact_kind(gait) == MULTICONTACT_KIND \
        else subject_source(subject, gait)
    cfg = CosimConfig(controller=controller, gait=gait, tube=tube,
                      subject=Path(who) if who else None,
                      device=device, library=library, speed_profile=speed_profile,
                      steps=steps, perturb=perturb, mode=mode, record=record,
                      fmu=fmu, max_time=max_time, pin_cpus=pin)

    with console.status("starting") as status:
        try:
            res = run_cosim(cfg, say=lambda m: status.update(m),
                            progress=lambda k, t, s: status.update(
                                f"t = {t:.2f} s, {s}/{steps} steps"),
                            install_signal_handlers=True)
        except (CosimError, ValueError) as e:
            print(f"hpcosim: error: {e}", file=sys.stderr)
            raise typer.Exit(2) from None
    if res.interrupted:
        import signal as _signal

        where = f"; recording complete: {record}" if record else ""
        print(f"hpcosim: interrupted by {res.interrupted} at t = {res.sim_time:.3f} s after "
              f"{res.steps} of {steps} steps{where}", file=sys.stderr)
        raise typer.Exit(128 + int(_signal.Signals[res.interrupted]))
    t = Table(title=f"co-simulation {res.run_id} ({mode})")
    t.add_column("item")
    t.add_column("value")
    end = ("FAULTED: " + res.fault_reason) if res.faulted else \
        (f"fell ({res.fall_reason}, code {res.fall_code})" if res.fell else "completed")
    t.add_row("result", end)
    if res.fault_verdict:
        t.add_row(f"who was late ({res.fault_cause})", res.fault_verdict)
    t.add_row("sim time / steps / ticks", f"{res.sim_time:.3f} s / {res.steps} / {res.ticks}")
    t.add_row("real-time factor", f"{res.real_time_factor:.2f}")
    t.add_row("frames tx / rx", f"{res.frames_tx} / {res.frames_rx}")
    t.add_row("missed / late replies", f"{res.missed} / {res.late}")
    if mode == CosimMode.REALTIME:
        t.add_row("plant overruns / slots skipped (max lag)",
                  f"{res.overruns} / {res.skipped_slots} ({res.max_lag_ms:.1f} ms)")
        t.add_row("late replies: host stalled / controller late",
                  f"{res.late_host} / {res.late_controller}")
        t.add_row("host stalls (largest: ms, tick, ms on CPU)",
                  f"{res.host_stalls} ({res.host_stall_ms:.1f}, {res.host_stall_tick}, "
                  f"{res.host_stall_cpu_ms:.1f})")
    t.add_row("latency us (median/p99/max)", ", ".join(f"{k} {v:.0f}"
                                                         for k, v in res.latency_us.items()))
    t.add_row("per tick us", ", ".join(f"{k} {v:.0f}" for k, v in res.timing_us.items()))
    nt = res.node.get("timing_us", {})
    if nt:
        t.add_row("controller node us (mean)", ", ".join(
            f"{k.replace('_', ' ')} {v.get('mean_us', 0):.0f}" for k, v in nt.items()))
    t.add_row("rejects plant / controller", f"{res.plant_rejects} / {res.ctrl_rejects}")
    t.add_row("torque commands clamped to the device limits", str(res.torque_clamped))
    t.add_row("injected", str(res.injected))
    if record:
        t.add_row("recording", str(record))
    console.print(t)
    conclude(cosim_verdict(res, steps))


def replay_cmd(
    recording: Annotated[Path, typer.Argument(help="MCAP recording.", dir_okay=False)],
    controller: Annotated[ControllerName | None, typer.Option(
        help=f"Controller (default: the recorded one). {CONTROLLER_HELP}")] = None,
    to_bus: Annotated[Path | None, typer.Option("--to-bus", help="Play the recorded frames "
                                                "onto this bus config instead.")] = None,
    speed: Annotated[float, typer.Option(min=0.0, help="Playback speed for --to-bus (0: fast).")
                     ] = 1.0,
    tolerance: Annotated[float, typer.Option(
        min=0.0, help="Largest torque difference (N m, motor side) that counts as the same "
        "(default: one step of the CAN torque command); above it, exit 1.")] = 1e-6,
) -> None:
    """Replay recorded measurements through a controller and report the largest torque
    difference (exit 1 above --tolerance), or play the recorded frames onto a CAN bus at
    recorded timing."""
    console = Console()
    if to_bus is not None:
        from bus_schemas.transport.bus_config import load_bus_config, make_bus
        from orchestrator.cosim.recording import play_to_bus

        bus = make_bus(load_bus_config(to_bus), "plant")
        try:
            n = play_to_bus(recording, bus, speed=speed)
        finally:
            bus.shutdown()
        console.print(f"{n} frames sent")
        return
    from orchestrator.cosim.recording import replay

    r = replay(recording, controller)
    console.print(f"{r.controller}: {r.cycles} cycles, largest torque difference "
                  f"{r.max_torque_diff:.3g} N m (motor)")
    conclude(replay_verdict(r.max_torque_diff, tolerance))


@tube_app.command("refit")
def refit(
    recordings: Annotated[list[str], typer.Argument(help="MCAP recordings (globs ok).")],
    gait: GaitOpt,
    out: Annotated[Path, typer.Option("--out", help="Tube file to write.", dir_okay=False)],
    old: Annotated[Path | None, typer.Option("--old", help="Tube to report coverage of "
                                             "(default: the first recording's).")] = None,
    model_error: Annotated[bool, typer.Option(
        "--model-error", help="Refit the model-error bound of clfqp's nominal-human model "
        "(the tube's model_error) from the controller's recorded online estimates "
        "(/controller/disturbance) instead of the socket-force tube; the socket-force tube is "
        "kept from --old (default: the first recording's).")] = False,
    degree: Annotated[int, typer.Option("--degree", min=0, max=20,
                                        help="Bezier degree of the refitted bounds.")] = 3,
    exclude_ms: Annotated[float | None, typer.Option(
        "--exclude-ms", min=0.0, max=255.0,
        help="--model-error: time after touchdown left out of the bound (ms; default: the "
        "old bound's, else 30).")] = None,
    min_coverage: Annotated[float | None, typer.Option(
        "--min-coverage", min=0.0, max=1.0,
        help="Exit 1 when the refitted tube's (or bound's) leave-one-out coverage is below "
        "this (default: its a posteriori guarantee 1 - eps); the file is written all the "
        "same.")] = None,
) -> None:
    """Refit the force tube from recorded ground-truth socket force (ps portions; of a
    multi-contact gait: its flat single supports, in the controllers' stance phase), or with
    --model-error the model-error bound from the controller's recorded estimates."""
    from hp_model.force_tube import load_tube
    from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind
    from orchestrator.cosim.tube_refit import refit_model_error, refit_tube

    if model_error and artifact_kind(gait) == MULTICONTACT_KIND:
        raise typer.BadParameter(f"{gait} is a multi-contact gait: its clfqp has no "
                                 "model-error bound to refit", param_hint="--model-error")

    paths = [str(absolute(p)) for r in recordings for p in (sorted(glob.glob(r)) or [r])]
    if model_error:
        rep = refit_model_error(paths, gait, out, old_tube=old, degree=degree,
                                exclude_after_touchdown=None if exclude_ms is None
                                else exclude_ms * 1e-3)
    else:
        rep = refit_tube(paths, gait, out, old_tube=old, degree=degree)
    Console().print(rep)
    t = load_tube(out)
    if model_error:
        me = t.model_error
        conclude(coverage_verdict(f"model-error bound {out}",
                                  me.credibility if me is not None else {}, min_coverage))
    else:
        conclude(coverage_verdict(f"force tube {out}", t.credibility, min_coverage))


@recording_app.command("recover")
def recover_cmd(
    part: Annotated[Path, typer.Argument(help="The .part file a killed run left.",
                                         dir_okay=False)],
    out: Annotated[Path | None, typer.Option("--out", help="Recording to write (default: the "
                                             "part's name without the leading dot and "
                                             ".part).", dir_okay=False)] = None,
) -> None:
    """Restore every completely written chunk of a killed run's recording into a complete
    MCAP file that replay and tube refit read."""
    from orchestrator.cosim.recovery import recover

    rep = recover(part, out)
    ended = "the whole recording" if rep["complete_input"] else \
        f"up to the first incomplete record ({rep['stopped_at']})"
    Console().print(f"recovered {rep['messages']} messages, {ended}: {rep['out']}")


def animate_cmd(
    source: Annotated[str, typer.Argument(
        metavar="RUN.mcap|SCENARIO",
        help="An MCAP recording (hpcosim run --record), or a scenario of the experiments run "
        "in process: CONTROLLER[/nominal|/human:AMPLITUDE[:SEED]][+offset], e.g. clfqp, "
        "pd/human:0.01:3+offset (needs --gait and --tube).")],
    out: Annotated[Path, typer.Option("--out", help="GIF to write.", dir_okay=False)],
    seconds: Annotated[float | None, typer.Option(
        "--seconds", min=0.04, help="Animate the first SECONDS of the run (default: all).")
    ] = None,
    fps: Annotated[float, typer.Option("--fps", min=1.0, max=100.0,
                                       help="Frames per second.")] = 25.0,
    gait: Annotated[Path | None, typer.Option("--gait", help="Scenario: gait file.",
                                              dir_okay=False)] = None,
    tube: Annotated[Path | None, typer.Option("--tube", help="Scenario: force-tube file.",
                                              dir_okay=False)] = None,
    steps: Annotated[int, typer.Option("--steps", min=1, max=100,
                                       help="Scenario: steps to walk.")] = 3,
    subject: SubjectOpt = None,
    device: DeviceOpt = None,
) -> None:
    """The walker of a recorded run or of a scenario run in process, animated (stick figure
    from the model's frames: human blue, prosthesis orange, socket force red) as a GIF."""
    import hp_model
    from hp_model.atomic_io import atomic_write_bytes
    from orchestrator.cli.options import check_output_file
    from orchestrator.experiments.animation import WalkSeries, recording_gif, walker_gif

    check_output_file(out)
    recording = source.endswith(".mcap") or Path(source).is_file()
    if recording:
        source = str(absolute(source))
    if not recording and (gait is None or tube is None):
        raise typer.BadParameter(f"scenario {source!r} needs --gait and --tube",
                                 param_hint="--gait/--tube")
    from orchestrator.cli.subject import subject_source

    model = hp_model.load_model(subject_source(subject, None if recording else gait),
                                str(device) if device else None)
    if recording:
        data = recording_gif(source, model, fps=fps, max_seconds=seconds)
    else:
        from hp_model.force_tube import load_tube
        from hp_model.gait_artifact import load_gait
        from orchestrator.experiments.paper import parse_scenario
        from orchestrator.experiments.scenarios import run_scenario

        try:
            sc = parse_scenario(model, source, steps)
        except ValueError as e:
            raise typer.BadParameter(str(e), param_hint="RUN.mcap|SCENARIO") from None
        assert gait is not None and tube is not None
        g = load_gait(gait, model.parameter_hash())
        r = run_scenario(model, g, load_tube(tube, g.hash()), sc)
        assert r.q is not None  # a scenario run keeps the configuration
        ended = f"{r.steps} steps" + (f", fell: {r.fall.reason.label}" if r.fall else "")
        walk = WalkSeries(r.t, r.q, r.domain, r.tau, r.socket_force, r.fall)
        data = walker_gif(model, walk, fps=fps, max_seconds=seconds,
                          title=f"{sc.label} ({ended})")
    atomic_write_bytes(out, data)
    Console().print(f"wrote {out} ({len(data) / 1024:.0f} KiB)")


def register(app: typer.Typer) -> None:
    """Add the co-simulation verbs to the ``hpcosim`` app."""
    app.add_typer(controller_app, name="controller")
    app.add_typer(recording_app, name="recording")
    app.command("run")(run)
    app.command("replay")(replay_cmd)
    app.command("animate")(animate_cmd)
