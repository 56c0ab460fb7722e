"""One of each (issue 36): one strict config base and one set of range types
(``hp_model.config``), one JSON encoder (``hp_model.json_io``), one figure helper
(``hp_model.figures``).  The range types refuse what they must; the product packages hold no
second base, no inline float range, no ``json.dump`` and no ``savefig`` of their own."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import pytest
from pydantic import ValidationError

from hp_model.config import (
    NonNegative,
    Positive,
    PositiveOrInf,
    StrictConfig,
    UnitInterval,
    validation_message,
)

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hp_model", "characterization", "human_fmu", "prosthesis_controller",
            "bus_schemas", "orchestrator")
NAN, INF = math.nan, math.inf


class Ranges(StrictConfig):
    positive: Positive = 1.0
    non_negative: NonNegative = 0.0
    unit: UnitInterval = 0.5
    bound: PositiveOrInf = 1.0
    plain: float = 0.0
    pair: tuple[float, float] = (0.0, 0.0)


@pytest.mark.parametrize(("field", "ok", "refused"), [
    ("positive", [1e-12, 3.0], [0.0, -1.0, INF, NAN]),
    ("non_negative", [0.0, 2.0], [-1e-12, INF, NAN]),
    ("unit", [0.0, 1.0, 0.3], [-0.1, 1.1, NAN]),
    ("bound", [0.1, INF], [0.0, -INF, NAN]),
    ("plain", [-5.0, 0.0], [INF, -INF, NAN]),
    ("pair", [(1.0, -1.0)], [(INF, 0.0), (0.0, NAN)]),
])
def test_range_types_refuse_what_they_must(field, ok, refused):
    for v in ok:
        assert getattr(Ranges(**{field: v}), field) == v
    for v in refused:
        with pytest.raises(ValidationError):
            Ranges(**{field: v})


def test_strict_config_is_frozen_and_refuses_unknown_fields():
    with pytest.raises(ValidationError, match="Extra inputs"):
        Ranges(positve=2.0)
    r = Ranges()
    with pytest.raises(ValidationError, match="frozen"):
        r.positive = 2.0  # type: ignore[misc]


def test_validation_message_is_one_line_naming_the_field():
    with pytest.raises(ValidationError) as e:
        Ranges(positive=-1.0, unit=2.0)
    assert validation_message(e.value) == \
        "field 'positive': Input should be greater than 0 (and 1 more)"


def _product_modules() -> list[tuple[Path, ast.Module]]:
    return [(f, ast.parse(f.read_text(), str(f))) for pkg in PACKAGES
            for f in sorted((ROOT / pkg).rglob("*.py"))]


def _calls(tree: ast.Module, attr: str) -> list[ast.Call]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call)
            and isinstance(n.func, ast.Attribute) and n.func.attr == attr]


def test_one_strict_config_base_and_one_set_of_range_types():
    """Only hp_model/config.py derives from pydantic's BaseModel, sets a model config or
    writes a float range (``Annotated[float, Field(...)]``)."""
    home = ROOT / "hp_model" / "config.py"
    bad = []
    for f, tree in _product_modules():
        if f == home:
            continue
        for n in ast.walk(tree):
            if isinstance(n, ast.ClassDef) and any(
                    ast.unparse(b).split(".")[-1] == "BaseModel" for b in n.bases):
                bad.append(f"{f.relative_to(ROOT)}: class {n.name}(BaseModel)")
            if isinstance(n, ast.Name) and n.id == "ConfigDict":
                bad.append(f"{f.relative_to(ROOT)}:{n.lineno}: ConfigDict")
            if isinstance(n, ast.Subscript) and ast.unparse(n).startswith(
                    ("Annotated[float, Field(", "Annotated[float, pydantic.Field(")):
                bad.append(f"{f.relative_to(ROOT)}:{n.lineno}: {ast.unparse(n)}")
    assert not bad, "\n".join(bad)


def test_one_json_encoder():
    """JSON is written through hp_model.json_io; the bus's MCAP recorder (orjson, the same
    rule) and its zenoh configuration strings are its own."""
    bad = [f"{f.relative_to(ROOT)}:{c.lineno}: {ast.unparse(c.func)}"
           for f, tree in _product_modules()
           if f != ROOT / "hp_model" / "json_io.py" and "bus_schemas" not in f.parts
           for attr in ("dump", "dumps") for c in _calls(tree, attr)
           if ast.unparse(c.func) in ("json.dump", "json.dumps")]
    assert not bad, "\n".join(bad)


def test_one_figure_helper():
    bad = [f"{f.relative_to(ROOT)}:{c.lineno}" for f, tree in _product_modules()
           if f != ROOT / "hp_model" / "figures.py" for c in _calls(tree, "savefig")]
    assert not bad, "\n".join(bad)
