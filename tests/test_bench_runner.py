"""``make bench``'s generator (``benchmarks/run_all.py``) on one real, quick benchmark: the
page it writes has the machine, the date, the commit and the benchmark's table, and it
renders the same page again from the kept JSON; bad input is a one-line error."""

from __future__ import annotations

import json
import os
import platform
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_all(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / "run_all.py"), *args],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)


def test_run_all_writes_the_page_from_a_real_benchmark(tmp_path):
    page, res = tmp_path / "performance.md", tmp_path / "results"
    r = run_all("--only", "model", "--quick", "--out", str(page), "--results", str(res))
    assert r.returncode == 0, r.stdout + r.stderr
    text = page.read_text()
    rev = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], cwd=ROOT,
                         capture_output=True, text=True).stdout.strip()
    assert re.search(r"Measured \d{4}-\d\d-\d\d \d\d:\d\d UTC at commit `" + rev, text)
    assert f"| cores | {os.cpu_count()} |" in text
    assert f"| Python | {platform.python_version()} |" in text
    assert re.search(r"\| packages \| .*numpy \d", text) and "| CPU | " in text
    assert "### model: " in text and "| figure | median | spread | ratio | target | met |" in text
    # the table is the JSON's: each case's median and ratio to Pinocchio, and its target
    figures = json.loads((res / "model.json").read_text())
    assert len(figures) == 7
    for name, f in figures.items():
        row = next(x for x in text.splitlines() if x.startswith(f"| {name} (us) |"))
        med = float(row.split("|")[2])
        assert abs(med - f["median_us"]) <= 0.01 * f["median_us"] + 0.01, (row, f)
    ours = next(x for x in text.splitlines() if x.startswith("| ours C: D,H,J,Jdot qd (us) |"))
    assert "ratio <= 1" in ours and ("yes" in ours or "**no**" in ours)
    assert "--quick" in text and "${" not in text
    # the same page again from the kept results, nothing run
    again = tmp_path / "again.md"
    r = run_all("--render-only", "--results", str(res), "--out", str(again))
    assert r.returncode == 0, r.stderr
    def undated(s: str) -> str:
        return re.sub(r"Measured .* UTC", "", s)

    assert undated(again.read_text()) == undated(text)


def test_run_all_bad_input_is_a_one_line_error(tmp_path):
    page = tmp_path / "p.md"
    for args, msg in ((["--only", "nope"], "unknown benchmark 'nope'"),
                      (["--render-only"], "needs --results"),
                      (["--out", str(tmp_path / "no" / "p.md")], "is not a folder"),
                      (["--merge", "--only", "model"], "--merge into")):
        r = run_all(*(args if "--out" in args else [*args, "--out", str(page)]))
        assert r.returncode == 2 and msg in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not page.exists()


def test_cold_tick_table_is_its_json(tmp_path):
    """``bench_cold_tick``: every controller and way of running gets a row whose median is
    the rounds' median CPU time and whose ratio is to back to back of the same round."""
    page, res = tmp_path / "performance.md", tmp_path / "results"
    r = run_all("--only", "cold_tick", "--quick", "--out", str(page), "--results", str(res))
    assert r.returncode == 0, r.stdout + r.stderr
    text = page.read_text()
    j = json.loads((res / "cold_tick.json").read_text())
    assert set(j["controllers"]) == {"clfqp", "pd"}
    for name, c in j["controllers"].items():
        modes = c["medians_cpu_wall_us"]
        assert list(modes) == ["back-to-back", "after a sleep", "after a yield-poll",
                               "after a busy spin"]
        for mode, rounds in modes.items():
            assert len(rounds) == j["rounds"] == 1
            cpu, wall = rounds[0]
            # each tick's CPU-time interval lies inside its wall-time one, so CPU <= wall
            # tick by tick, hence for the medians too (to the two clocks' agreement)
            assert 0 < cpu <= wall + 0.5, (name, mode, cpu, wall)
            label = ("back to back" if mode == "back-to-back"
                     else f"{mode} of {j['gap_us']:g} us")
            row = next(x for x in text.splitlines()
                       if x.startswith(f"| {name}: tick {label} (us CPU) |"))
            cells = [x.strip() for x in row.split("|")]
            assert abs(float(cells[2]) - cpu) <= 0.01 * cpu + 0.05, (row, cpu)
            if mode == "back-to-back":
                assert cells[4] == ""
            else:
                ratio = c["ratios"][mode][0]
                assert abs(ratio - cpu / modes["back-to-back"][0][0]) < 1e-12
                assert abs(float(cells[4]) - ratio) <= 0.01 * ratio, (row, ratio)


def test_lockstep_floor_walks_and_its_table_is_its_json(tmp_path):
    """``bench_lockstep_floor``: the real FMU and controller walk a step in two processes
    over zenoh; the period holds its two measured parts (round trip, FMU) and the table
    holds the JSON's figures."""
    page, res = tmp_path / "performance.md", tmp_path / "results"
    r = run_all("--only", "lockstep_floor", "--quick", "--out", str(page), "--results", str(res))
    assert r.returncode == 0, r.stdout + r.stderr
    f = json.loads((res / "lockstep_floor.json").read_text())["figures"]
    period, rtt, fmu = f["period"]["median"], f["round trip"]["median"], f["fmu"]["median"]
    # one step of the demo gait is about 0.5-0.6 s: that many 1 ms periods, all exchanged
    assert 300 <= f["periods"]["median"] <= 1000
    assert rtt > 0 and fmu > 0 and rtt + fmu <= period
    assert abs(f["real_time_factor"]["median"] - 1e3 / period) <= 1e-9 * 1e3 / period
    assert 0 < f["controller tick (controller process)"]["median"] < rtt
    text = page.read_text()
    row = next(x for x in text.splitlines() if x.startswith("| real time factor |"))
    rtf = f["real_time_factor"]["median"]
    assert abs(float(row.split("|")[2]) - rtf) <= 0.01 * rtf
    assert ">= 5 (the co-simulation's ceiling)" in row


def _memory_results(res: Path, growth: float, stamp: str) -> None:
    """A memory benchmark's kept JSON and meta (as ``run`` writes them)."""
    res.mkdir(exist_ok=True)
    j = {"duration_s": 3600.0, "warmup_s": 60.0, "restarts": 0,
         "plant": {"warm_mb": 150.0, "end_mb": 150.0 * (1 + growth / 100), "max_mb": 160.0,
                   "growth_pct": growth, "slope_mb_per_h": 0.5},
         "node": {"warm_mb": 100.0, "end_mb": 101.0, "growth_pct": 1.0}}
    (res / "memory.json").write_text(json.dumps(j))
    meta = {"args": ["--duration", "3600"], "seconds": 1200.0, "load": [1.0, 2.0],
            "quick": False, "stamp": stamp}
    (res / "memory.meta.json").write_text(json.dumps(meta))


def test_merge_replaces_one_table_and_keeps_the_others(tmp_path):
    page, res = tmp_path / "performance.md", tmp_path / "results"
    _memory_results(res, 25.0, "2026-01-01 00:00 UTC at commit `aaaaaaaaaa`")
    r = run_all("--render-only", "--only", "memory", "--results", str(res), "--out", str(page))
    assert r.returncode == 0, r.stderr
    model = ("### model: 12-DOF model\n\n`benchmarks/bench_model.py --repeats 15`: 64 s, "
             "load average 1.0 -> 1.0.\n\n| figure | median | spread | ratio | target | met |\n"
             "|---|---:|---:|---:|---|:---:|\n| x (us) | 1.50 | 1-2 | 0.5 | ratio <= 1 | yes |\n")
    page.write_text(page.read_text() + "\n" + model)
    measured = next(x for x in page.read_text().splitlines() if x.startswith("Measured "))
    _memory_results(res, 0.42, "2026-02-03 04:05 UTC at commit `bbbbbbbbbb`")
    r = run_all("--render-only", "--only", "memory", "--results", str(res), "--merge",
                "--out", str(page))
    assert r.returncode == 0, r.stderr
    text = page.read_text()
    assert model in text and text.index("### model:") < text.index("### memory:")
    assert text.count("### memory:") == 1 and text.count("### ") == 2
    mem = text[text.index("### memory:"):]
    assert "Measured 2026-02-03 04:05 UTC at commit `bbbbbbbbbb`." in mem
    row = next(x for x in mem.splitlines()
               if x.startswith("| orchestrator growth after the warm-up (%) |"))
    assert float(row.split("|")[2]) == 0.42 and row.endswith("| yes |")
    # the page's date and commit stay the first page's; the summary counts both tables
    # (64 s + 1200 s, one target met in each)
    assert measured in text.splitlines()
    assert ("2 benchmarks, 21.1 min; targets met: 2 of 2; re-measured since, each dated in "
            "its table: memory.") in text
    # a page of another machine is refused, untouched
    other = text.replace(f"| cores | {os.cpu_count()} |", "| cores | 999 |")
    page.write_text(other)
    r = run_all("--render-only", "--only", "memory", "--results", str(res), "--merge",
                "--out", str(page))
    assert r.returncode == 2 and "another machine" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and page.read_text() == other
