"""The controller registry: every name has a row (a builder and a one-line description),
``make_controller`` builds each by name, and the package's modules import one way (no
cycle)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from prosthesis_controller import BaseController, ControllerName, make_controller
from prosthesis_controller.registry import CONTROLLERS, describe

PACKAGE = Path(__file__).resolve().parent.parent / "prosthesis_controller"


def test_every_controller_has_a_row_with_a_one_line_description():
    assert list(CONTROLLERS) == list(ControllerName)
    lines = describe().splitlines()
    assert len(lines) == len(ControllerName)
    for name, entry in CONTROLLERS.items():
        assert entry.description and "\n" not in entry.description
        assert f"{name}: {entry.description}" in lines
    assert describe("; ").count("; ") == len(ControllerName) - 1


def test_make_controller_builds_each_by_name(ctx):
    for name in ControllerName:
        c = make_controller(str(name), None, None, None, context=ctx)
        assert isinstance(c, BaseController) and c.name == name


def test_an_unknown_name_or_no_context_is_a_one_line_error(ctx):
    with pytest.raises(ValueError, match="choose one of") as e:
        make_controller("lqr", None, None, None, context=ctx)
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="a gait, a tube and a model, or a context"):
        make_controller("pd", None, None, None)


def _imports(path: Path) -> set[str]:
    """The package's own modules that ``path`` imports (at any level, run time only: not
    under ``if TYPE_CHECKING``)."""
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING":
            node.body = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module \
                and node.module.startswith("prosthesis_controller."):
            out.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            out.update(a.name.split(".")[1] for a in node.names
                       if a.name.startswith("prosthesis_controller."))
    return out


def test_the_package_modules_import_one_way():
    """No import cycle between the package's modules (the registry imports the controllers,
    the controllers the base, the base the context and the swing law)."""
    graph = {p.stem: _imports(p) for p in PACKAGE.glob("*.py") if p.stem != "__init__"}
    done: set[str] = set()

    def visit(module: str, path: tuple[str, ...]) -> None:
        assert module not in path, f"import cycle: {' -> '.join((*path, module))}"
        if module in done:
            return
        for m in sorted(graph.get(module, ())):
            visit(m, (*path, module))
        done.add(module)

    for module in sorted(graph):
        visit(module, ())
    assert graph["base"] == {"context", "interface", "measurement", "swing"}
