"""What a user's non-editable install gets: every module and every data file the code loads.

The editable install of the suite hides a package missing from the distribution (a
hand-written package list once left out ``orchestrator.loop``), so this builds the packages
the way a wheel is built (setuptools' build_py on a copy of the tree, no network) and
compares with the files git tracks.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hp_model", "characterization", "human_fmu", "prosthesis_controller",
            "bus_schemas", "orchestrator")


def _tracked(package: str) -> list[str]:
    out = subprocess.run(["git", "ls-files", package], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout.split()
    # the package READMEs are documentation, not files the code loads
    return [f for f in out if not f.endswith(".md") or "data/" in f]


def test_a_built_distribution_holds_every_module_and_data_file(tmp_path: Path) -> None:
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    for pkg in PACKAGES:
        shutil.copytree(ROOT / pkg, src / pkg,
                        ignore=shutil.ignore_patterns("__pycache__", "*.so", "*.o"))
    lib = tmp_path / "lib"
    p = subprocess.run([sys.executable, "-c", "from setuptools import setup; setup()",
                        "-q", "build_py", "--build-lib", str(lib)],
                       cwd=src, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr[-2000:]
    missing = [f for pkg in PACKAGES for f in _tracked(pkg) if not (lib / f).is_file()]
    assert missing == [], f"not in the distribution: {missing}"
