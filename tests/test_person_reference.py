"""The packaged synthetic person (``characterization/data/reference_person_gait.json``,
``tests/person_reference.py``): ``mocap synth --source person`` walks it by default, and its
recipe still gives a gait with the same speed, stride and double supports that walks."""

from __future__ import annotations

import json

import pytest

from characterization.gait.person_synth import REFERENCE_PERSON_GAIT
from orchestrator.cli import main as hpcosim
from tests import person_reference


def _figures(doc: dict) -> dict[str, float]:
    rows = {r["criterion"]: r for r in doc["check"]["rows"]}
    return {"speed": doc["stride"]["speed"], "stride": doc["stride"]["time"],
            "ds1": rows["double support 1"]["gait"], "ds2": rows["double support 2"]["gait"]}


@pytest.mark.slow  # the person's closed loop compiled on a cold cache: about 45 s
def test_the_packaged_person_is_the_default_of_mocap_synth(tmp_path):
    """No --gait: the packaged person walks 2 strides, its subject written beside the take
    (the example subject with its foot to the metatarsal heads)."""
    assert hpcosim(["mocap", "synth", "--source", "person", "--out", str(tmp_path / "t"),
                    "--steps", "2", "--rate", "100"]) == 0
    doc = json.loads(REFERENCE_PERSON_GAIT.read_text())
    assert doc["closed_loop"]["walks"] and not doc["mismatch_allowed"]
    assert (tmp_path / "t" / "subject.toml").read_text().count("metatarsal") == 1


@pytest.mark.slow
def test_the_recipe_gives_the_packaged_person_again(tmp_path):
    """The recipe run anew: the person's gait (exit 0: every criterion and `clfqp`'s walk),
    speed and stride within 0.5 % and the double supports within 2 ms of the packaged file's
    (IPOPT is deterministic on one machine; another libm may move the last digits)."""
    out = tmp_path / "person.json"
    assert person_reference.make(out, tmp_path) == 0
    new, old = (_figures(json.loads(p.read_text())) for p in (out, REFERENCE_PERSON_GAIT))
    for k in ("speed", "stride"):
        assert new[k] == pytest.approx(old[k], rel=0.005), k
    for k in ("ds1", "ds2"):
        assert new[k] == pytest.approx(old[k], abs=0.002), k
