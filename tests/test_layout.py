"""The packages' folders by subject (docs/layout.md): imports point one way between the
packages and between the subpackages of ``orchestrator`` and ``characterization``, and no
folder holds a family of files named by a shared prefix or suffix in place of a package."""

from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

from hp_model.domains import PAPER_DOMAINS

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hp_model", "characterization", "human_fmu", "prosthesis_controller",
            "bus_schemas", "orchestrator")

BUS = ("bus_schemas", "bus_schemas.transport", "bus_schemas.recording")
#: unit -> the units it may import (besides itself); a unit is a package or a subpackage
ALLOWED = {
    "hp_model": set(),
    # the transport loads nothing of the project (the controller process imports it)
    "bus_schemas": set(),
    "bus_schemas.transport": set(),
    "bus_schemas.recording": {"hp_model", "bus_schemas.transport"},
    "human_fmu": {"hp_model"},
    "prosthesis_controller": {"hp_model", "bus_schemas.transport"},
    "characterization": {"hp_model"},
    "characterization.mocap": {"hp_model"},
    "characterization.gait": {"hp_model", "characterization.mocap"},
    "characterization.tube": {"hp_model", "characterization.mocap", "characterization.gait"},
    "orchestrator": {"hp_model"},
    "orchestrator.loop": {"hp_model", "human_fmu", "prosthesis_controller", *BUS},
    # the recordings refit the tube
    "orchestrator.cosim": {"hp_model", "human_fmu", "prosthesis_controller", *BUS,
                           "characterization.mocap", "characterization.gait",
                           "characterization.tube", "orchestrator", "orchestrator.loop"},
    "orchestrator.experiments": {"hp_model", "human_fmu", "prosthesis_controller",
                                 *BUS, "characterization", "characterization.mocap",
                                 "characterization.gait", "characterization.tube",
                                 "orchestrator", "orchestrator.loop", "orchestrator.cosim"},
}
ALLOWED["orchestrator.sweep"] = ALLOWED["orchestrator.experiments"] | {
    "orchestrator.experiments"}
ALLOWED["orchestrator.cli"] = set(ALLOWED) - {"orchestrator.cli"}
ALLOWED["characterization"] = set()  # the package's own __init__ imports nothing


def _unit(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] not in PACKAGES:
        return None
    two = ".".join(parts[:2])
    return two if two in ALLOWED else parts[0]


def _modules() -> list[tuple[str, Path]]:
    out = []
    for pkg in PACKAGES:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            rel = f.relative_to(ROOT).with_suffix("")
            parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
            out.append((".".join(parts), f))
    return out


def _imports(path: Path, module: str) -> set[str]:
    """Every module ``path`` imports, at top level or inside a function."""
    found: set[str] = set()
    is_pkg = path.name == "__init__.py"
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                base = module.split(".")
                base = base[:len(base) - node.level + (1 if is_pkg else 0)]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            found.add(name)
            found.update(f"{name}.{a.name}" for a in node.names)
    return found


def test_imports_point_one_way() -> None:
    bad = []
    for module, path in _modules():
        own = _unit(module)
        assert own is not None
        for imp in _imports(path, module):
            other = _unit(imp)
            if other is None or other == own:
                continue
            if other not in ALLOWED[own]:
                bad.append(f"{path.relative_to(ROOT)} ({own}) imports {imp} ({other})")
    assert not bad, "\n".join(sorted(set(bad)))


def test_no_folder_holds_a_prefix_or_suffix_family() -> None:
    bad = []
    for pkg in PACKAGES:
        for folder in [ROOT / pkg, *(p.parent for p in (ROOT / pkg).rglob("*/__init__.py"))]:
            names = [f.stem for f in folder.glob("*.py") if "_" in f.stem.strip("_")]
            for label, key in (("prefix", lambda n: n.split("_")[0]),
                               ("suffix", lambda n: n.split("_")[-1])):
                for word, n in Counter(map(key, names)).items():
                    if n >= 3:
                        bad.append(f"{folder.relative_to(ROOT)}: {n} files with the {label} "
                                   f"{word!r} (a subpackage?)")
    assert not bad, "\n".join(bad)


def test_no_domain_is_named_by_a_string_literal() -> None:
    """A domain is a member of ``hp_model.domains.Domain`` wherever the product code names
    one: adding a domain is then one edit there (issue 36).  A string constant equal to a
    domain's word anywhere else is a second place to edit."""

    words = {d.value for d in PAPER_DOMAINS}
    home = ROOT / "hp_model" / "domains.py"
    bad = []
    for _, path in _modules():
        if path == home:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Constant) and node.value in words:
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.value!r}")
    assert not bad, "domain words outside hp_model/domains.py:\n" + "\n".join(bad)


def test_orchestrator_modules_are_small() -> None:
    """No module of the orchestrator over 450 lines (issue 36: a module a reader can hold)."""
    files = sorted((ROOT / "orchestrator").rglob("*.py"))
    big = [f"{p.relative_to(ROOT)}: {n} lines" for p in files
           if (n := len(p.read_text().splitlines())) > 450]
    assert not big, "\n".join(big)


def test_the_standalone_fmu_runner_knows_the_domains() -> None:
    """tests/fmu_runner.py runs where the project is not importable, so it spells the FMU's
    domain codes itself: they must be :class:`~hp_model.domains.Domain`'s."""
    from tests.fmu_runner import DOMAINS

    assert tuple(d.value for d in PAPER_DOMAINS) == DOMAINS
