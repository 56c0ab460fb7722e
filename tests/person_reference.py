"""The packaged multi-contact gait the synthetic person walks
(``characterization/data/reference_person_gait.json``, ``mocap synth --source person``'s
default), and the exact recipe that makes it: no third-party data.

The person: the example subject (``hp_model/configs/subject_example.toml``) with its foot to
the metatarsal heads (``ROLL_OFF_OF_FOOT`` of its length, as a take's subject has it), on the
default device with its pylon and foot fitted to them (``worn_device``).  Their walk: the
kinematic template (``mocap synth --source template``) with the foot's roll on
(:data:`ROLL`: heel strike 0.2 rad toe-up, heel rise 0.12 s before the other heel strike,
toe-off 0.7 rad), 6 strides of 1.1 s and 0.6 m steps at 100 Hz, seed 1; processed as that
person and fitted on the multi-contact graph with defaults::

    hpcosim mocap process take.csv --subject subject.toml --out steps.npz
    hpcosim gait fit steps.npz --domains multicontact --out reference_person_gait.json

Regenerate, from the repository root (about a minute)::

    python -m tests.person_reference            # writes the packaged file in place
    python -m tests.person_reference --out G.json
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import tomli_w

from characterization.gait.person_synth import REFERENCE_PERSON_GAIT
from characterization.mocap.synthetic_gait import GaitParams

#: the template's walk (module docstring)
ROLL = GaitParams(heel_strike_pitch=0.2, toe_off_pitch=0.7, heel_rise=0.12,
                  double_support=0.11, step_length=0.6, stride_time=1.1)
STRIDES, RATE, SEED = 6, 100.0, 1


def make(out: Path, work: Path) -> int:
    """Write the gait to ``out`` (work files in ``work``); ``gait fit``'s exit code."""
    from orchestrator.cli import main as hpcosim

    steps = work / "steps.npz"
    rc = make_steps(steps, work)
    if rc != 0:
        return rc
    return hpcosim(["gait", "fit", str(steps), "--domains", "multicontact", "--no-figure",
                    "--out", str(out)])


def make_steps(steps: Path, work: Path) -> int:
    """The person's take (module docstring) processed into ``steps`` (work files in
    ``work``); ``mocap process``'s exit code."""
    from characterization.gait.fit import worn_device
    from characterization.mocap.subject_from_take import ROLL_OFF_OF_FOOT
    from characterization.mocap.synthetic_subject import (
        SynthOptions,
        SynthSource,
        synthesize,
        write_synthetic,
    )
    from hp_model.config import (
        SubjectConfig,
        default_device_path,
        default_subject_path,
        load_device,
        load_subject,
    )
    from hp_model.human_prosthesis import HumanProsthesisModel
    from orchestrator.cli import main as hpcosim

    doc = load_subject(default_subject_path()).model_dump(mode="json", exclude_none=True)
    doc["lengths"]["foot"] = round(doc["lengths"]["foot"] * ROLL_OFF_OF_FOOT, 4)
    doc["notes"] = ("the example subject, its foot to the metatarsal heads: the synthetic "
                    "person of tests/person_reference.py")
    person = SubjectConfig.model_validate(doc)
    model = HumanProsthesisModel(person, worn_device(person,
                                                     load_device(default_device_path()))[0])
    opts = SynthOptions(n_strides=STRIDES, seed=SEED, rate=RATE, source=SynthSource.TEMPLATE,
                        gait=ROLL)
    take = work / "take"
    write_synthetic(take, synthesize(model, opts), opts)
    (take / "subject.toml").write_text(tomli_w.dumps(doc))
    return hpcosim(["mocap", "process", str(take / "take.csv"), "--subject",
                    str(take / "subject.toml"), "--out", str(steps), "--no-figures"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.person_reference",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=REFERENCE_PERSON_GAIT)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        return make(args.out, Path(tmp))


if __name__ == "__main__":
    sys.exit(main())
