"""The string choices (:mod:`hp_model.choices`): each enum parses its words, refuses anything
else in one line naming the choices, and serializes as the same strings as before."""

from __future__ import annotations

import json

import pytest

from characterization.gait.fit import FitSegments
from characterization.mocap.mapping import SegmentationMethod
from characterization.mocap.synthetic_subject import SynthSource
from hp_model.choices import Choice
from hp_model.closed_loop import ClosedLoopMode
from hp_model.compiled import CompileBackend, FunctionSet
from hp_model.force_tube import TubePhase
from hp_model.hybrid import Constraint, ConstraintKind
from hp_model.tree import Body, JointKind, ModelError
from orchestrator.cosim.faults import PerturbCase
from orchestrator.modes import CosimMode, SweepBackend
from prosthesis_controller.interface import ControllerMode, ControllerName, QpOutcome

#: every enum and the strings files and command lines spell (unchanged formats)
CASES: list[tuple[type[Choice], tuple[str, ...]]] = [
    (CompileBackend, ("auto", "c", "sx")),
    (ConstraintKind, ("frame", "point", "coords")),
    (JointKind, ("revolute", "planar")),
    (ClosedLoopMode, ("full", "human")),
    (QpOutcome, ("not_run", "solved", "infeasible", "failed", "nonfinite")),
    (ControllerMode, ("stance", "swing", "fallback", "fault", "oracle")),
    (ControllerName, ("clfqp", "clfqp-exact", "clfqp-paper", "clfqp-paper-exact", "pd",
                      "passive", "phase-pd")),
    (CosimMode, ("lockstep", "realtime")),
    (PerturbCase, ("none", "drop", "delay", "duplicate", "corrupt-counter", "corrupt-checksum",
                   "corrupt-length", "kill", "hang", "stall", "human")),
    (SweepBackend, ("simulator", "fmu")),
    (SegmentationMethod, ("paper", "contact")),
    (FitSegments, ("touchdown", "paper")),
    (TubePhase, ("gait", "step")),
    (SynthSource, ("model", "template", "person")),
]
IDS = [e.__name__ for e, _ in CASES]


@pytest.mark.parametrize(("enum", "values"), CASES, ids=IDS)
def test_values_are_the_strings(enum, values):
    assert tuple(m.value for m in enum) == values
    for v in values:
        m = enum(v)
        assert m == v and str(m) == v and f"{m}" == v and m is enum(m)
        assert json.dumps({m: [m]}) == json.dumps({v: [v]})


@pytest.mark.parametrize(("enum", "values"), CASES, ids=IDS)
def test_other_input_is_a_one_line_error_listing_the_choices(enum, values):
    with pytest.raises(ValueError) as e:
        enum("nonsense")
    msg = str(e.value)
    assert "\n" not in msg and "'nonsense'" in msg and enum.label() in msg
    assert msg.endswith("choose one of " + ", ".join(values))


def test_label_splits_the_class_name():
    assert CompileBackend.label() == "compile backend"
    assert ConstraintKind.label() == "constraint kind"
    assert ControllerName.label() == "controller"  # its own


def test_sweep_spec_names_a_bad_controller_and_keeps_the_words(tmp_path):
    from orchestrator.sweep.spec import SpecError, parse_spec

    for f in ("g.json", "t.json"):
        (tmp_path / f).write_text("{}")
    doc = {"gait": "g.json", "tube": "t.json", "controllers": ["pd", "clfqp"], "draws": 1,
           "seed": 0, "families": {"f": {}}}
    spec = parse_spec(doc, tmp_path / "spec.toml")
    assert spec.controllers == (ControllerName.PD, ControllerName.CLFQP)
    assert spec.model_dump(mode="json")["controllers"] == ["pd", "clfqp"]
    with pytest.raises(SpecError, match="field 'controllers': unknown controller 'lqr'; choose"):
        parse_spec({**doc, "controllers": ["lqr"]}, tmp_path / "spec.toml")


def test_function_set_and_constraint_parse_their_choice():
    with pytest.raises(ValueError, match="unknown compile backend 'gcc'; choose one of auto"):
        FunctionSet([], "none", backend="gcc")
    with pytest.raises(ValueError, match="unknown constraint kind 'plane'"):
        Constraint("c", "plane", "x")
    c = Constraint("c", "frame", "p_sole")
    assert c.kind is ConstraintKind.FRAME and c.size == 3
    with pytest.raises(ModelError, match="body 'b': unknown joint kind 'hinge'; choose one"):
        Body("b", None, "hinge", ("q",))
    assert Body("b", None, "planar", ("x", "z", "th")).joint.dof == 3


def test_qp_outcome_maps_to_the_bus_status_unchanged():
    from bus_schemas.transport.protocol import QpStatus
    from prosthesis_controller.node import QP_STATUS

    assert set(QP_STATUS) == set(QpOutcome)
    wire = {k.value: int(v) for k, v in QP_STATUS.items()}
    assert wire == {"not_run": 7, "solved": 0, "infeasible": 3, "failed": 6, "nonfinite": 5}
    assert all(isinstance(v, QpStatus) for v in QP_STATUS.values())
    assert {o for o in QpOutcome if o.is_failure} == {"infeasible", "failed", "nonfinite"}


def test_mode_counts_serialize_as_the_words():
    from hp_model.json_io import dumps

    modes = [ControllerMode.STANCE] * 3 + [ControllerMode("fallback")]
    counts = {m: modes.count(m) for m in sorted(set(modes))}
    assert dumps({"modes": counts}) == '{"modes": {"fallback": 1, "stance": 3}}'
    assert counts.get("fallback") == 1 and {"stance": 3}.get(ControllerMode.STANCE) == 3


def test_cosim_config_parses_its_mode_and_records_the_word(tmp_path):
    from orchestrator.cosim.config import CosimConfig, CosimError

    cfg = CosimConfig("pd", tmp_path / "g.json", tmp_path / "t.json", mode="realtime")
    assert cfg.mode is CosimMode.REALTIME
    assert json.dumps(cfg.to_dict()["mode"]) == '"realtime"'
    # the run's own error type, naming the option (issue 39)
    with pytest.raises(CosimError,
                       match="--mode: unknown cosim mode 'fast'; choose one of lockstep"):
        CosimConfig("pd", tmp_path / "g.json", tmp_path / "t.json", mode="fast")


def test_sweep_backend_in_the_spec_serializes_as_the_word(tmp_path):
    from hp_model.artifacts import canonical_hash
    from orchestrator.sweep.spec import parse_spec

    for f in ("g.json", "t.json"):
        (tmp_path / f).write_text("{}")
    doc = {"gait": "g.json", "tube": "t.json", "controllers": ["pd"], "draws": 1, "seed": 0,
           "families": {"f": {}}, "backend": "fmu"}
    spec = parse_spec(doc, tmp_path / "spec.toml")
    assert spec.backend is SweepBackend.FMU
    assert spec.model_dump(mode="json")["backend"] == "fmu"
    assert canonical_hash(spec.identity()) == canonical_hash(
        {"seed": 0, "steps": spec.steps, "backend": "fmu"})


def test_fit_segments_outside_the_choices_is_a_fit_error():
    from characterization.gait.bezier_fit import FitError
    from characterization.gait.fit import fit_segments

    assert fit_segments("paper") is FitSegments.PAPER
    with pytest.raises(FitError, match=r"^unknown fit segments 'steps'; choose one of touch"):
        fit_segments("steps")


def test_playback_options_parse_the_tube_phase():
    from characterization.tube.playback import PlaybackError, PlaybackOptions

    assert PlaybackOptions(tube_phase="step").tube_phase is TubePhase.STEP
    with pytest.raises(PlaybackError, match=r"^unknown tube phase 'stance'; choose one of gait"):
        PlaybackOptions(tube_phase="stance")
