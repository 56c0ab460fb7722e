"""What a sweep spec may draw on each graph (:func:`orchestrator.sweep.spec.parse_spec`
calls these once the gait's kind is known): a multi-contact gait's sweep
(:mod:`orchestrator.sweep.contact`) and the quantities only the person's graph has."""

from __future__ import annotations

from pathlib import Path

from orchestrator.sweep.spec import SweepBackend, SweepSpec, _fail

#: the quantities a sweep of a multi-contact gait draws (the rest change what its controllers
#: do not have yet: a tube margin, a model of their own, the delayed human)
MULTICONTACT_QUANTITIES = ("human.bezier_amplitude", "human.output_offset",
                           "human.stiffness", "human.stride_cv", "human.speed", "plant.armature",
                           "initial.knee", "initial.ankle", "sensor.")
#: what a family that changes the person's speed may draw beside it
WITH_SPEED = ("human.speed", "sensor.")
#: the controllers of a multi-contact gait's sweep: its robust CLF-QP, its phase PD
#: (``contact-pd``: :mod:`prosthesis_controller.contact_phase_pd`) and the paper's baselines
#: on its graph (:mod:`prosthesis_controller.pd`, :mod:`prosthesis_controller.passive`)
MULTICONTACT_CONTROLLERS = ("clfqp", "phase-pd", "pd", "passive")


def check_multicontact(spec: SweepSpec, path: Path, files: dict[str, Path]) -> None:
    """What a sweep of a multi-contact gait runs (:mod:`orchestrator.sweep.contact`): the
    simulator backend, its controllers, the families' quantities it draws, and a tube
    (optional) fitted around this gait; one line naming the field otherwise."""
    if spec.backend != SweepBackend.SIMULATOR:
        raise _fail(path, "backend", "a multi-contact gait's sweep runs the in-process "
                    "simulator ('simulator')")
    bad = [c for c in spec.controllers if c not in MULTICONTACT_CONTROLLERS]
    if bad:
        raise _fail(path, "controllers", f"{', '.join(bad)}: a multi-contact gait's sweep "
                    f"runs {', '.join(MULTICONTACT_CONTROLLERS)}")
    armature = _check_families(spec, path, files)
    if "library" in files:
        _check_library(path, files)
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



def _check_families(spec: SweepSpec, path: Path, files: dict[str, Path]) -> str | None:
    """Each family's quantities drawn on a multi-contact gait, and ``human.speed`` with a
    library and only ``sensor.*`` beside it; the field of a drawn armature (or None)."""
    armature = None
    for name, fam in spec.families.items():
        qs = fam.quantities()
        for q in qs:
            if q == "plant.armature":
                armature = f"families.{name}.{q}"
            if not q.startswith(MULTICONTACT_QUANTITIES):
                raise _fail(path, f"families.{name}.{q}", "not drawn on a multi-contact gait "
                            "(it draws human.bezier_amplitude, human.output_offset, "
                            "human.stiffness, human.stride_cv, human.speed, plant.armature, "
                            "initial.knee, initial.ankle and sensor.*)")
        if "human.speed" in qs:
            other = [q for q in qs if not q.startswith(WITH_SPEED)]
            if other:
                raise _fail(path, f"families.{name}.{other[0]}", "not drawn with human.speed "
                            "(a family that changes the person's speed draws sensor.* beside "
                            "it)")
            if "library" not in files:
                raise _fail(path, f"families.{name}.human.speed", "the person's speed needs "
                            "'library', a gait library of this gait (`hpcosim gait library`)")
    return armature


def _check_library(path: Path, files: dict[str, Path]) -> None:
    """The spec's library read back, of the gait's person and device."""
    from characterization.gait.library import load_gait_library
    from characterization.gait.multicontact_artifact import load_contact_cycle
    from hp_model.artifacts import ArtifactError

    try:
        lib = load_gait_library(files["library"])
    except (ArtifactError, OSError, ValueError) as e:
        raise _fail(path, "library", str(e)) from None
    if lib.model.parameter_hash() != load_contact_cycle(files["gait"]).model.parameter_hash():
        raise _fail(path, "library", "not of the gait's subject and device (its model's "
                    "parameters differ)")


#: the quantities of the person's graph only (the paper's model has no pace from stride to
#: stride, no gait library, nor the drives' armature)
PERSON_ONLY = ("human.stride_cv", "human.speed", "plant.armature")


def check_paper(spec: SweepSpec, path: Path, files: dict[str, Path]) -> None:
    """A sweep of a gait of the paper's graph: its force tube given, none of the person's
    quantities drawn; one line naming the field otherwise."""
    if "tube" not in files:
        raise _fail(path, "tube", "a gait of the paper's graph runs with its force tube "
                    "(`hpcosim tube fit`)")
    if "library" in files:
        raise _fail(path, "library", "a gait library is a multi-contact gait's (`hpcosim "
                    "gait library`)")
    for name, fam in spec.families.items():
        for q in PERSON_ONLY:
            if q in fam.quantities():
                raise _fail(path, f"families.{name}.{q}", "drawn on a multi-contact gait "
                            "only (the paper's model has no pace from stride to stride, no "
                            "gait library, nor the drives' armature)")
