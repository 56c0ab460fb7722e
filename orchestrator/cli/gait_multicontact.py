"""``hpcosim gait fit --domains multicontact``: the person's gait on the multi-contact graph
(:mod:`characterization.gait.multicontact`), compared with the take, its virtual constraints
regressed and walked in closed loop with the prosthesis on ``clfqp``
(:mod:`orchestrator.experiments.contact_walk`), and written with both; a gait that is not
the person's or does not walk is refused unless ``--allow-mismatch``."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from rich.console import Console

from orchestrator.cli.outcome import HOLDS, Verdict, conclude


def fit_multicontact_gait(steps: Path, out: Path, subject: Path | None, device: Path | None,
                          nodes: int, max_iter: int, allow_mismatch: bool, figure: bool = True,
                          *, motor_margin: float = 0.15, max_joint_speed: float | None = None
                          ) -> None:
    """Targets from the steps, the fit, the comparison printed, the artifact (and, with
    ``figure``, its figure against the take next to it) written (a mismatch only with
    ``allow_mismatch``), the verdict as the exit code."""
    from characterization.gait.figures import save_person_figure
    from characterization.gait.fit import worn_device
    from characterization.gait.multicontact import (
        GRAPH,
        MultiContactError,
        MultiContactOptions,
        fit_multicontact,
        take_strides,
        targets_from_steps,
    )
    from characterization.gait.multicontact_artifact import save_multicontact_gait, to_document
    from characterization.gait.multicontact_summary import take_summary
    from characterization.gait.person_check import StanceForce
    from characterization.gait.take_closure import closure_line, double_support_closure
    from characterization.mocap.steps_artifact import load_steps, plate_forces
    from hp_model.config import (
        default_device_path,
        default_subject_path,
        load_device,
        load_subject,
    )
    from hp_model.human_prosthesis import HumanProsthesisModel
    from orchestrator.cli.options import check_output_file
    from orchestrator.cli.subject import subject_note, subject_source

    console = Console(stderr=True)
    check_output_file(out)
    data = load_steps(steps)
    person = load_subject(subject_source(subject, steps) or default_subject_path())
    dev = load_device(device or default_device_path())
    Console().print(subject_note(subject, steps), soft_wrap=True, highlight=False)
    if device is None:  # the device the person would wear: its pylon and foot fitted
        dev, notes = worn_device(person, dev)
        for line in notes:
            Console().print(line, soft_wrap=True, highlight=False)
    model = HumanProsthesisModel(person, dev, graph=GRAPH)
    targets = targets_from_steps(data, model, str(steps))
    _say_flat_feet(targets.flat_foot_pitch)
    closure = double_support_closure(model, take_strides(data, model, str(steps)))
    if closure:
        Console().print(closure_line(closure), soft_wrap=True, highlight=False)
    opt = MultiContactOptions(nodes=nodes, max_iter=max_iter, motor_margin=motor_margin,
                              max_joint_speed=max_joint_speed)
    with console.status(f"gait fit: multi-contact ({', '.join(GRAPH.domains)})"):
        result = fit_multicontact(model, targets, opt)
    if not result.success:
        raise MultiContactError(f"gait fit, multi-contact optimization: IPOPT ended with "
                                f"{result.status} after {result.iterations} iterations")
    plates = plate_forces(data, str(steps))  # the take's force plates, where it has them
    grf, bw = ({f: StanceForce(fx=s.fx, fz=s.fz) for f, s in plates[0].items()}, plates[1]) \
        if plates is not None else (None, float("nan"))
    take = take_summary(targets, str(steps), grf, bw)
    result, gait, check, outputs, (walk, reference, pd_walk) = _judged(model, take, result,
                                                                       str(out), console)
    passed = check.passed and walk.walks
    if passed or allow_mismatch:
        doc = to_document(result, targets, dict(gait.grf), check, model.parameter_hash(), opt,
                          mismatch_allowed=not passed)
        doc["targets"]["double_support_closure"] = [c.to_json() for c in closure]
        doc["subject"] = person.model_dump(mode="json")
        doc["device"] = dev.model_dump(mode="json")  # the gait's model, remade from the file
        doc["virtual_constraints"] = outputs.to_json()
        doc["closed_loop"] = walk.to_json()
        doc["closed_loop_reference"] = reference.to_json()
        doc["closed_loop_contact_pd"] = pd_walk.to_json()
        save_multicontact_gait(out, doc)
        if figure:
            save_person_figure(out.with_suffix(".png"), take, gait)
        Console().print(f"[bold]gait[/bold] {out}: speed {result.speed:.2f} m/s, stride "
                        f"{result.stride_time:.2f} s, double supports "
                        + ", ".join(f"{d} {T * 1000:.0f} ms"
                                    for d, T in result.double_supports().items())
                        + f"; IPOPT {result.iterations} iterations, "
                        f"{result.solve_seconds:.1f} s; angles' limit: "
                        f"{result.stats.get('angle_limit_stage')}", highlight=False)
    why = "; ".join(w for w, bad in ((check.verdict(), not check.passed),
                                     (f"the gait {walk.line()}", not walk.walks)) if bad)
    conclude(_verdict(passed, why, allow_mismatch))


def _say_flat_feet(pitch: dict[str, float]) -> None:
    """One line: how far off flat the take's feet read while flat on the ground (rad)."""
    import math

    if pitch:
        Console().print("take: its feet read " + ", ".join(
            f"{math.degrees(v):+.1f} deg ({foot})" for foot, v in pitch.items())
            + " while flat on the ground; taken out of the ankles' angles (the model's "
            "flat sole is at 0)", soft_wrap=True, highlight=False)


def _judged(model: Any, take: Any, result: Any, name: str, console: Console
            ) -> tuple[Any, Any, Any, Any, tuple[Any, ...]]:
    """The fit compared with the take (printed) and walked (:func:`_walks`): (the result
    kept, its summary, the comparison, its virtual constraints, the walks).  When the gait of
    the angles' limit (the fit's fourth solve) does not walk and the fit before it does, that
    one is kept, its ``angle_limit_stage`` saying why."""
    from characterization.gait.contact_gait import contact_gait
    from characterization.gait.multicontact_summary import gait_summary
    from characterization.gait.person_check import check_person, print_check

    def judge(r: Any) -> tuple[Any, Any, Any, tuple[Any, ...]]:
        gait = gait_summary(model, r, name)
        check = check_person(take, gait)
        print_check(Console(), check)
        outputs = contact_gait(model, r)
        return gait, check, outputs, _walks(model, outputs, r.trajectory, console)

    gait, check, outputs, walks = judge(result)
    before = result.without_limit
    if walks[0].walks or before is None:
        return result, gait, check, outputs, walks
    Console().print("the gait of the angles' limit does not walk: the fit before its solve, "
                    "compared and walked", highlight=False)
    b_gait, b_check, b_outputs, b_walks = judge(before)
    if not b_walks[0].walks:
        return result, gait, check, outputs, walks
    stage = (f"{result.stats.get('angle_limit_stage')}; its gait {walks[0].line()}: the fit "
             "before it kept")
    kept = replace(before, stats={**before.stats, "angle_limit_stage": stage})
    return kept, b_gait, b_check, b_outputs, b_walks


def _walks(model: Any, outputs: Any, trajectory: Any, console: Console) -> tuple[Any, ...]:
    """The fitted cycle walked 10 steps with the prosthesis on clfqp (the verdict), the held
    oracle (the reference) and contact-pd (the baseline), each printed on its line."""
    from characterization.gait.contact_gait import walk_contact_gait
    from orchestrator.experiments.contact_walk import walk_prosthesis_controllers

    with console.status("gait fit: the fitted cycle with the prosthesis on clfqp and "
                        "contact-pd"):
        walk, pd_walk = walk_prosthesis_controllers(model, outputs, trajectory)
    Console().print(f"[bold]closed loop[/bold] {walk.line()}", soft_wrap=True,
                    highlight=False)
    with console.status("gait fit: the fitted cycle with the reference"):
        reference = walk_contact_gait(model, outputs, trajectory)
    for what, w in (("reference", reference), ("baseline", pd_walk)):
        Console().print(f"[bold]{what}[/bold] {w.line()} (reported, not required)",
                        soft_wrap=True, highlight=False)
    return walk, reference, pd_walk


def _verdict(passed: bool, why: str, allow_mismatch: bool) -> Verdict:
    if passed:
        return HOLDS
    if allow_mismatch:
        return Verdict(f"{why}; written by --allow-mismatch, marked mismatch_allowed")
    return Verdict(f"{why}; not written (--allow-mismatch writes it anyway)")
