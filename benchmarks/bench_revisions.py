"""Before/after: one benchmark script run alternately on this tree and on another git
revision (a temporary worktree), in the same session, so the machine's load drifts hit both
alike; prints each chosen figure's median and spread per side and the after/before ratio.

    python benchmarks/bench_revisions.py --before REV --bench cosim --key rtf.median \\
        [--rounds 3] -- --gait G --tube T --runs 1

``--bench NAME`` runs ``benchmarks/bench_NAME.py`` (of each tree, with that tree first on
PYTHONPATH) with the arguments after ``--`` plus ``--json``; ``--key`` (repeatable) is a
dotted path into that JSON whose value is a number or a list of numbers (their median is
the round's figure).  The revision's tree must have the benchmark script and its --json,
or ``--script-from-here`` runs this tree's script on both.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def pick(d: Any, path: str) -> float:
    for part in path.split("."):
        d = d[int(part)] if isinstance(d, list) else d[part]
    if isinstance(d, list):
        return float(statistics.median(float(x) for x in d))
    return float(d)


def run(tree: Path, bench: str, args: list[str], script_tree: Path | None = None
        ) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.json"
        env = dict(os.environ, PYTHONPATH=str(tree))
        script = (script_tree or tree) / "benchmarks" / f"bench_{bench}.py"
        cmd = [sys.executable, str(script), *args,
               "--json", str(out)]
        p = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
        if p.returncode != 0:
            raise SystemExit(f"bench_{bench}.py in {tree} failed ({p.returncode}): "
                             f"{p.stderr.strip().splitlines()[-1:]}")
        return json.loads(out.read_text())


def main() -> None:
    argv = sys.argv[1:]
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    own = argv[:argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", required=True, help="git revision to compare against")
    ap.add_argument("--bench", required=True, help="cosim, fmu, controllers, sweep, ...")
    ap.add_argument("--key", action="append", required=True, help="dotted path into the JSON")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--script-from-here", action="store_true",
                    help="run this tree's benchmark script on both (the revision's lacks it "
                         "or its --json; the script must work with the revision's API)")
    a = ap.parse_args(own)
    rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", a.before],
                         capture_output=True, text=True, check=True).stdout.strip()
    figs: dict[str, dict[str, list[float]]] = {k: {"before": [], "after": []} for k in a.key}
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "before"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(old),
                        a.before], check=True, capture_output=True)
        try:
            for r in range(a.rounds):
                sides = [("before", old), ("after", ROOT)]
                for side, tree in (sides if r % 2 == 0 else sides[::-1]):
                    d = run(tree, a.bench, extra, ROOT if a.script_from_here else None)
                    for k in a.key:
                        figs[k][side].append(pick(d, k))
                    load = os.getloadavg()[0]
                    print(f"round {r + 1} {side}: " + ", ".join(
                        f"{k} {figs[k][side][-1]:.4g}" for k in a.key)
                        + f" (load average {load:.1f})", flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(old)], capture_output=True)
    print(f"\nbench_{a.bench}.py, {a.rounds} rounds alternating, before = {rev}")
    print("| figure | before median (min-max) | after median (min-max) | after/before |")
    print("|---|---|---|---|")
    for k, v in figs.items():
        b, f = v["before"], v["after"]
        mb, mf = statistics.median(b), statistics.median(f)
        print(f"| {k} | {mb:.4g} ({min(b):.4g}-{max(b):.4g}) | {mf:.4g} ({min(f):.4g}-"
              f"{max(f):.4g}) | {mf / mb:.3f} |")


if __name__ == "__main__":
    main()
