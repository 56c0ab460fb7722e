"""``hpcosim experiments`` and ``hpcosim demo`` (registered in :mod:`orchestrator.cli`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console

from hp_model.domains import DomainGraph
from orchestrator.cli.options import DeviceOpt, SubjectOpt
from orchestrator.cli.outcome import HOLDS, Verdict, claims_verdict, conclude, uncounted_claims

STAGES = ("synthetic subject", "mocap processing", "gait fit", "tube fit", "experiments",
          "report")


def _line(console: Console, text: str) -> None:
    """One line, cut with an ellipsis at the console's width (never wrapped)."""
    console.print(text, overflow="ellipsis", no_wrap=True, crop=True)


def _stage_line(console: Console, stage: str, seconds: float, output: str, out: Path) -> None:
    """``done STAGE (T s): OUTPUT``, the output relative to the demo's folder."""
    rel = Path(output)
    rel = rel.relative_to(out) if rel.is_relative_to(out) else rel
    _line(console, f"[green]done[/] {stage:17s} {seconds:6.1f} s  {rel}")


def _claims_table(console: Console, metrics: dict[str, Any], *, judged: bool = True) -> None:
    """One line per claim: reproduced or not, the claim's id and its key number (the full
    numbers are in report.md); a claim that does not count against the result says why
    (:func:`~orchestrator.cli.outcome.uncounted_claims`: a documented negative result is
    "expected")."""
    console.print("[bold]paper Sec. V claims[/] (numbers in report.md):")
    notes = uncounted_claims(metrics, judged=judged)
    for c in metrics["claims"]:
        mark = ("[green]reproduced    [/]" if c["reproduced"] else
                "[yellow]NOT reproduced[/]" if c["id"] in notes else "[red]NOT reproduced[/]")
        note = f" ({notes[c['id']]})" if c["id"] in notes else ""
        _line(console, f"  {mark} {c['id']:15s}{note} {c.get('headline', '')}")


def experiments(
    gait: Annotated[Path, typer.Option("--gait", help="Gait file (gait fit; a multi-contact "
                                       "gait runs its own experiments, below).",
                                       dir_okay=False)],
    out: Annotated[Path, typer.Option("--out", help="Output folder.", file_okay=False)],
    tube: Annotated[Path | None, typer.Option("--tube", help="Tube file (tube fit; the "
                                              "paper's graph needs it; a multi-contact gait: "
                                              "the socket force's share inside it, and "
                                              "clfqp's robust term from its model-error "
                                              "bound).", dir_okay=False)] = None,
    steps: Annotated[int, typer.Option("--steps", min=1, help="Steps per run.")] = 20,
    eigen: Annotated[bool, typer.Option(help="Closed-loop return-map eigenvalues (finite "
                                        "differences, 24 extra runs).")] = True,
    draws: Annotated[int, typer.Option("--draws", min=0, help="A multi-contact gait: draws "
                                       "per perturbation family (0: none).")] = 10,
    subject: SubjectOpt = None,
    device: DeviceOpt = None,
) -> None:
    """Paper Sec. V on the full closed loop: nominal walking (Fig. 7), exact vs relaxed
    CLF-QP (Fig. 6), robustness to perturbed human gaits (Fig. 8); metrics.json + report.md.
    A multi-contact gait: its prosthesis controllers' nominal walks (held oracle, clfqp,
    contact-pd, the paper's pd and passive) and the perturbation families on the same draws;
    with its --tube (tube fit),
    each walk's socket force against it."""
    import hp_model
    from hp_model.force_tube import load_tube
    from hp_model.gait_artifact import MULTICONTACT_KIND, artifact_kind, load_gait
    from orchestrator.cli.subject import subject_source
    from orchestrator.experiments.paper import run_experiments
    from orchestrator.experiments.report import write_report

    if artifact_kind(gait) == MULTICONTACT_KIND:
        _person_experiments(gait, out, steps, draws, tube, subject, device)
        return
    if tube is None:
        raise typer.BadParameter("a gait of the paper's graph runs with its force tube",
                                 param_hint="--tube")
    console = Console()
    model = hp_model.load_model(subject_source(subject, gait),
                                str(device) if device else None)
    g = load_gait(gait, model.parameter_hash())
    tb = load_tube(tube, g.hash())
    with console.status("experiments") as st:
        m = run_experiments(model, g, tb, out, steps, eigen=eigen,
                            progress=lambda s: st.update(s))
        write_report(out, m)
    _claims_table(console, m)
    console.print(f"wrote {out}/metrics.json, report.md and figures")
    conclude(claims_verdict(m))


def demo(
    out: Annotated[Path, typer.Option("--out", help="Output folder.",
                                      file_okay=False)] = Path("out/demo-experiments"),
    quick: Annotated[bool, typer.Option("--quick", help="Fewer strides and steps, no gait "
                                        "verification (CI).")] = False,
    steps: Annotated[int | None, typer.Option("--steps", min=1, help="Steps per closed-loop "
                                              "run (default 20, --quick 3).")] = None,
    take: Annotated[Path | None, typer.Option(
        "--take", help="A lab's take (C3D, TRC, Motive CSV): the pipeline on the person's "
        "multi-contact gait instead of the synthetic person.", dir_okay=False)] = None,
    mapping: Annotated[Path | None, typer.Option(
        "--mapping", help="With --take: its mapping file (mocap inspect).", dir_okay=False)
                       ] = None,
    draws: Annotated[int, typer.Option("--draws", min=0, help="With --take or --domains "
                                       "multicontact: draws per perturbation family.")] = 10,
    domains: Annotated[DomainGraph | None, typer.Option(
        help="'multicontact' (default; --quick: paper): the synthetic person with double "
        "support (mocap synth --source person) on the multi-contact graph, every stage to a "
        "replayed co-simulation; 'paper': the synthetic subject on the paper's two domains, "
        "its claims judged.")] = None,
) -> None:
    """The whole pipeline on the synthetic person with double support (or --take: a lab's
    take), the person's multi-contact gait: mocap synth --source person -> mocap process ->
    gait fit -> tube fit -> experiments --tube -> fmu build -> run (co-simulation,
    recorded) -> replay -> report.md.  With --domains paper: on the synthetic subject and
    the paper's two domains, its claims judged: mocap synth -> mocap process -> gait fit
    --domains paper -> tube fit -> experiments -> report.md."""
    if take is not None:
        if domains == DomainGraph.PAPER:
            raise typer.BadParameter("--take runs the person's multi-contact gait",
                                     param_hint="--domains")
        _demo_take(take, mapping, out, steps or 20, draws)
        return
    if mapping is not None:
        raise typer.BadParameter("--mapping goes with --take", param_hint="--mapping")
    if domains == DomainGraph.MULTICONTACT or (domains is None and not quick):
        if quick:
            raise typer.BadParameter("--quick runs the paper's graph", param_hint="--quick")
        _demo_person(out, steps or 20, draws)
        return
    _demo_synthetic(out, quick, steps)


def _demo_synthetic(out: Path, quick: bool, steps: int | None) -> None:
    """``demo`` on the synthetic subject (the paper's graph)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    import hp_model
    from characterization.gait.fit import fit_gait
    from characterization.gait.phzd import PHZDOptions
    from characterization.mocap.files import process_file
    from characterization.mocap.steps_artifact import load_steps
    from characterization.mocap.synthetic_subject import SynthOptions, synthesize, write_synthetic
    from characterization.tube.playback import fit_force_tube
    from characterization.tube.playback import write_outputs as write_tube_outputs
    from hp_model.gait_artifact import save_gait
    from orchestrator.experiments.paper import run_experiments
    from orchestrator.experiments.report import write_report

    n_steps = steps or (3 if quick else 20)
    out.mkdir(parents=True, exist_ok=True)
    console = Console()
    stages: list[dict[str, Any]] = []
    model = hp_model.load_model()
    _line(console, "[bold]hpcosim demo[/]: subject -> mocap -> gait -> tube -> experiments "
          "-> report")
    t_all = time.perf_counter()
    # transient: the bar shows the running stage, the lines printed above it stay
    with Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(),
                  console=console, transient=True) as prog:
        task = prog.add_task("demo", total=len(STAGES))
        t0 = time.perf_counter()

        def done(stage: str, output: str) -> None:
            nonlocal t0
            stages.append({"stage": stage, "seconds": time.perf_counter() - t0,
                           "output": output})
            prog.advance(task)
            _stage_line(console, stage, stages[-1]["seconds"], output, out)
            t0 = time.perf_counter()

        prog.update(task, description="synthetic subject")
        opts = SynthOptions(n_strides=8 if quick else 20, seed=1)
        paths = write_synthetic(out / "take", synthesize(model, opts), opts)
        done("synthetic subject", str(paths.get("csv", out / "take")))
        prog.update(task, description="mocap processing")
        take = out / "take" / "take.csv"
        process_file(take, out / "steps.npz", with_figures=False)
        done("mocap processing", str(out / "steps.npz"))
        prog.update(task, description="gait fit")
        data = load_steps(out / "steps.npz")
        gait = fit_gait(model, data, PHZDOptions(), src=str(out / "steps.npz"),
                        verify=not quick,
                        progress=lambda s: prog.update(task, description=f"gait fit: {s}"))
        save_gait(out / "gait.json", gait)
        done("gait fit", str(out / "gait.json"))
        prog.update(task, description="tube fit (playback of the recorded steps)")
        res = fit_force_tube(model, gait, data, n_steps=10 if quick else 20,
                             src=str(out / "steps.npz"))
        write_tube_outputs(out / "tube.json", res, str(out / "steps.npz"),
                           str(out / "gait.json"))
        tube = res.tube
        done("tube fit", str(out / "tube.json"))
        prog.update(task, description="experiments")
        m = run_experiments(model, gait, tube, out, n_steps, eigen=not quick,
                            progress=lambda s: prog.update(task,
                                                           description=f"experiments: {s}"))
        done("experiments", str(out / "metrics.json"))
        prog.update(task, description="report")
        extra = ([f"--quick: {n_steps} steps per run instead of 20, {opts.n_strides} strides, "
                  "no gait verification, no return-map eigenvalues: a check that the "
                  "pipeline runs, its claims not judged (exit status 0)."] if quick else [])
        stages.append({"stage": "report", "seconds": 0.0, "output": str(out / "report.md")})
        write_report(out, m, stages, extra)
        prog.advance(task)
    _claims_table(console, m, judged=not quick)
    # the path whole (a terminal wraps it if it must), never cut
    console.print(f"report: [bold]{out}/report.md[/] ({time.perf_counter() - t_all:.0f} s in "
                  "all; figures, walker animations, metrics.json beside it)", soft_wrap=True)
    # --quick's 3-step runs without eigenvalues cannot show the 20-step claims: not judged
    conclude(claims_verdict(m, judged=not quick))


def _person_experiments(gait: Path, out: Path, steps: int, draws: int, tube: Path | None,
                        subject: Path | None, device: Path | None) -> None:
    """``experiments`` of a multi-contact gait (:mod:`orchestrator.experiments.person_walks`);
    exit 1 unless clfqp walks the nominal steps."""
    from orchestrator.experiments.person_walks import NAMES, run_person_experiments, table_cell

    for given, name in ((subject, "--subject"), (device, "--device")):
        if given is not None:
            raise typer.BadParameter(f"{gait} is a multi-contact gait: it carries its subject "
                                     "and device", param_hint=name)
    from characterization.gait.multicontact_artifact import load_contact_cycle
    from hp_model.force_tube import load_tube
    from orchestrator.cosim.contact_controllers import HeldOracleFellError

    console = Console()
    tb = None if tube is None else load_tube(tube, load_contact_cycle(gait).hash)
    try:
        with console.status("experiments") as st:
            m = run_person_experiments(gait, out, steps, draws,
                                       progress=lambda s: st.update(s), tube=tb)
    except HeldOracleFellError as e:  # the gait does not walk: nothing to run the controllers on
        conclude(Verdict(f"{gait}: {e}"))
        return
    for name in NAMES:
        w = m["nominal"][name]
        walk = w["walk"]
        how = walk["fall"] or "walks"
        _line(console, f"  {name:11s} {walk['steps']:3d} steps, knee "
              f"{table_cell(w['knee_rms_deg'], 2)} deg, ankle {table_cell(w['ankle_rms_deg'], 2)}"
              f" deg RMS over the last stride: {how}")
    for family, row in m["families"].items():
        _line(console, f"  {family:8s} " + ", ".join(f"{n} {row[n]}/{draws}" for n in NAMES))
    if "tube" in m:
        _line(console, "  socket force inside the tube (flat single support): " + ", ".join(
            f"{n} " + ("-" if (v := m["tube"]["inside"][n]) is None else f"{100 * v:.0f} %")
            for n in NAMES))
    console.print(f"wrote {out}/metrics.json, report.md and person.png")
    clfqp = m["nominal"]["clfqp"]["walk"]
    conclude(HOLDS if clfqp["walks"] else Verdict(
        f"clfqp does not walk the gait: after {clfqp['steps']} of {steps} steps, "
        f"{clfqp['fall']}"))


#: what ``demo --take``'s stages' exit statuses mean (orchestrator.cli.outcome)
_STATUS = {0: "holds", 1: "done, negative", 2: "error"}


def _demo_take(take: Path, mapping: Path | None, out: Path, steps: int, draws: int) -> None:
    """``demo --take``: the person's pipeline (:func:`_demo_pipeline`) on a lab's take, the
    gait written even when it is not the person's (``--allow-mismatch``)."""
    _demo_pipeline(out, take, steps, draws, [],
                   [*(["--mapping", str(mapping)] if mapping else [])], ["--allow-mismatch"])


#: strides of the synthetic person's take in ``demo --domains multicontact``: 12 give the
#: tube 12 flat single supports (openOFM's take has 2, which certify nothing)
PERSON_STRIDES = 12


def _demo_person(out: Path, steps: int, draws: int) -> None:
    """``demo`` (``--domains multicontact``, the default): the person's pipeline on the
    synthetic person with double support (``mocap synth --source person``: the packaged
    person's gait walked by its model), processed as the person it is; its fitted gait must
    be the person's."""
    take = out / "take"
    synth = ("synthetic person", lambda: ["mocap", "synth", "--source", "person", "--out",
                                          str(take), "--steps", str(PERSON_STRIDES),
                                          "--seed", "1"])
    _demo_pipeline(out, take / "take.csv", steps, draws, [synth],
                   ["--subject", str(take / "subject.toml")], [], "the synthetic person")


def _demo_pipeline(out: Path, take: Path, steps: int, draws: int,
                   before: list[tuple[str, Callable[[], list[str]]]], process_args: list[str],
                   fit_args: list[str], who: str | None = None) -> None:
    """Each stage the verb a user would type (:func:`orchestrator.cli.main`), its output
    printed as it comes: ``before`` (e.g. making the take), then mocap process ->
    gait fit --domains multicontact -> tube fit -> experiments --tube -> fmu build -> run
    (co-simulation, recorded) -> replay.  A stage that errs ends the demo (exit 2), a
    negative one (the gait not the person's, a walk that falls) is reported and the demo
    goes on (exit 1 at the end); ``report.md`` sums the stages up."""
    from orchestrator.cli import main as hpcosim

    out.mkdir(parents=True, exist_ok=True)
    console = Console()
    gait, rec = out / "gait.json", out / "run.mcap"
    tube = out / "tube.json"

    def experiments_args() -> list[str]:  # with the tube when its stage wrote one
        return ["experiments", "--gait", str(gait), "--out", str(out / "experiments"),
                "--steps", str(steps), "--draws", str(draws),
                *(["--tube", str(tube)] if tube.is_file() else [])]

    stages: list[tuple[str, Callable[[], list[str]]]] = [
        *before,
        ("mocap processing", lambda: ["mocap", "process", str(take), "--out",
                                      str(out / "steps.npz"), *process_args]),
        ("gait fit", lambda: ["gait", "fit", str(out / "steps.npz"), "--domains",
                              "multicontact", *fit_args, "--out", str(gait)]),
        ("tube fit", lambda: ["tube", "fit", str(out / "steps.npz"), "--gait", str(gait),
                              "--out", str(tube)]),
        ("experiments", experiments_args),
        ("fmu build", lambda: ["fmu", "build", "--gait", str(gait), "--out",
                               str(out / "human.fmu")]),
        ("co-simulation", lambda: ["run", "--controller", "clfqp", "--gait", str(gait),
                                   "--fmu", str(out / "human.fmu"), "--steps", str(steps),
                                   "--record", str(rec),
                                   *(["--tube", str(tube)] if tube.is_file() else [])]),
        ("replay", lambda: ["replay", str(rec)]),
    ]
    for stale in (tube, gait):  # an earlier demo's in the folder is not this one's
        stale.unlink(missing_ok=True)
    done: list[tuple[str, float, int, list[str]]] = []
    stopped = ""  # why the stages after a negative one cannot run
    for stage, make_args in stages:
        args = make_args()
        console.rule(f"[bold]{stage}[/]: hpcosim {' '.join(args)}")
        t0 = time.perf_counter()
        rc = hpcosim(args)
        done.append((stage, time.perf_counter() - t0, rc, args))
        if rc not in (0, 1) or (stage == "gait fit" and not gait.is_file()):
            break
        if stage == "gait fit" and (stopped := _no_walk(gait)):
            break
    _write_demo_report(out, who or take.name, done, gait, stopped)
    worst = max(rc for *_x, rc, _a in done)
    for stage, seconds, rc, _args in done:
        _line(console, f"{stage:17s} {seconds:6.1f} s  {_STATUS.get(rc, f'exit {rc}')}")
    if stopped:
        _line(console, f"the later stages not run: {stopped}")
    console.print(f"report: [bold]{out}/report.md[/]", soft_wrap=True)
    if worst >= 2 or (len(done) < len(stages) and not stopped):
        raise typer.Exit(2)
    conclude(HOLDS if worst == 0 else Verdict(
        "; ".join([*(f"{stage}: negative" for stage, _s, rc, _a in done if rc == 1),
                   *([f"the later stages not run ({stopped})"] if stopped else [])])))


def _no_walk(gait: Path) -> str:
    """Why the stages after ``gait fit`` cannot run on the gait file ``gait`` (its cycle
    does not walk even under the held oracle: the tube's playback, the controllers' tables
    and the co-simulation all start from its walk), or ""."""
    import json

    reference = json.loads(gait.read_text()).get("closed_loop_reference", {})
    if reference.get("walks", True):
        return ""
    return (f"the gait does not walk even under the held oracle ({reference.get('fall')}); "
            "the tube, the experiments and the co-simulation start from its walk")


def _write_demo_report(out: Path, who: str, done: list[tuple[str, float, int, list[str]]],
                       gait: Path, stopped: str = "") -> None:
    """``report.md`` of ``demo`` on ``who`` (the synthetic person, or a take's file name):
    each stage's command, time and outcome, the gait's comparison with the take, links to
    what the stages wrote."""
    import json

    from hp_model.atomic_io import atomic_write_text

    lines = [f"# hpcosim demo on {who}", "",
             "The person's multi-contact gait, from the take to a co-simulation "
             "(docs/gait-design.md, docs/cosim.md).  The force tube is made on the flat "
             "prosthesis single supports (`tube.md`) with the bound of `clfqp`'s model "
             "error along the same playbacks; the experiments measure the walks' socket force "
             "against the tube, and `clfqp` (experiments and co-simulation) carries the bound "
             "in its CLF row (its robust term) when the tube holds one.", "",
             "| stage | command | seconds | outcome |", "|---|---|---:|---|"]
    for stage, seconds, rc, args in done:
        lines.append(f"| {stage} | `hpcosim {' '.join(args)}` | {seconds:.1f} | "
                     f"{_STATUS.get(rc, f'exit {rc}')} |")
    if stopped:
        lines += ["", f"The later stages were not run: {stopped}."]
    if gait.is_file():
        doc = json.loads(gait.read_text())
        check, walk = doc.get("check", {}), doc.get("closed_loop", {})
        lines += ["", f"The gait against the take: {check.get('verdict', '?')}.", "",
                  "| criterion | take | gait | error | limit | |", "|---|---:|---:|---:|---:|---|"]
        for r in check.get("rows", []):
            mark = {True: "ok", False: "**no**", None: ""}[r["passed"]]
            limit = "-" if r["limit"] is None else f"{r['limit']:g} {r['unit']}"
            lines.append(f"| {r['criterion']} | {_num(r['take'])} | {_num(r['gait'])} | "
                         f"{_num(r['error'])} | {limit} | {mark} |")
        lines += ["", f"The gait's closed-loop verdict: {walk.get('steps', '?')} of "
                  f"{walk.get('wanted', '?')} steps ({walk.get('controller', '')}).", "",
                  "![the gait against the take](gait.png)", ""]
    lines += ["What each stage wrote: `steps.npz` (and its QA report), `gait.json`, "
              "`experiments/report.md` (the controllers' walks and the perturbation "
              "families), `human.fmu`, `run.mcap` (the co-simulation: Foxglove, "
              "`hpcosim replay`)."]
    atomic_write_text(out / "report.md", "\n".join(lines) + "\n")


def _num(v: float | None) -> str:
    return "-" if v is None else f"{v:.3g}"
