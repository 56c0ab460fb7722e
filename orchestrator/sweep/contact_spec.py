"""What a sweep spec may draw on each graph (:func:`orchestrator.sweep.spec.parse_spec`
calls these once the gait's kind is known): a multi-contact gait's sweep
(:mod:`orchestrator.sweep.contact`) and the quantities only the person's graph has."""

from __future__ import annotations

from pathlib import Path

from orchestrator.sweep.spec import SweepBackend, SweepSpec, _fail

#: the quantities a sweep of a multi-contact gait draws (the rest change what its controllers
#: do not have yet: a tube margin, a model of their own, the delayed human, a placed start)
MULTICONTACT_QUANTITIES = ("human.bezier_amplitude", "human.output_offset",
                           "human.stiffness", "human.stride_cv", "plant.armature", "sensor.")
#: the controllers of a multi-contact gait's sweep: its robust CLF-QP and its phase PD
#: (``contact-pd``: :mod:`prosthesis_controller.contact_phase_pd`)
MULTICONTACT_CONTROLLERS = ("clfqp", "phase-pd")


def check_multicontact(spec: SweepSpec, path: Path, files: dict[str, Path]) -> None:
    """What a sweep of a multi-contact gait runs (:mod:`orchestrator.sweep.contact`): the
    simulator backend, its two controllers, the families' quantities it draws, and a tube
    (optional) fitted around this gait; one line naming the field otherwise."""
    if spec.backend != SweepBackend.SIMULATOR:
        raise _fail(path, "backend", "a multi-contact gait's sweep runs the in-process "
                    "simulator ('simulator')")
    bad = [c for c in spec.controllers if c not in MULTICONTACT_CONTROLLERS]
    if bad:
        raise _fail(path, "controllers", f"{', '.join(bad)}: a multi-contact gait's sweep "
                    f"runs {' and '.join(MULTICONTACT_CONTROLLERS)}")
    armature = None
    for name, fam in spec.families.items():
        for q in fam.quantities():
            if q == "plant.armature":
                armature = f"families.{name}.{q}"
            if not q.startswith(MULTICONTACT_QUANTITIES):
                raise _fail(path, f"families.{name}.{q}", "not drawn on a multi-contact gait "
                            "(it draws human.bezier_amplitude, human.output_offset, "
                            "human.stiffness, human.stride_cv, plant.armature and sensor.*)")
    if armature is not None:
        from characterization.gait.multicontact_artifact import load_contact_cycle

        device = load_contact_cycle(files["gait"]).model.device
        if device.prosthesis.knee.armature == 0 and device.prosthesis.ankle.armature == 0:
            raise _fail(path, armature, "the gait's device has no rotor inertia: no armature "
                        "to scale (a gait fitted on the shipped device has one)")
    if "tube" in files:
        from characterization.gait.multicontact_artifact import load_contact_cycle
        from hp_model.artifacts import ArtifactError
        from hp_model.force_tube import load_tube

        try:
            load_tube(files["tube"], load_contact_cycle(files["gait"]).hash)
        except (ArtifactError, ValueError) as e:
            raise _fail(path, "tube", str(e)) from None

#: the quantities of the person's graph only (the paper's model has no pace from stride to
#: stride, nor the drives' armature)
PERSON_ONLY = ("human.stride_cv", "plant.armature")


def check_paper(spec: SweepSpec, path: Path, files: dict[str, Path]) -> None:
    """A sweep of a gait of the paper's graph: its force tube given, none of the person's
    quantities drawn; one line naming the field otherwise."""
    if "tube" not in files:
        raise _fail(path, "tube", "a gait of the paper's graph runs with its force tube "
                    "(`hpcosim tube fit`)")
    for name, fam in spec.families.items():
        for q in PERSON_ONLY:
            if q in fam.quantities():
                raise _fail(path, f"families.{name}.{q}", "drawn on a multi-contact gait "
                            "only (the paper's model has no pace from stride to stride, nor "
                            "the drives' armature)")
