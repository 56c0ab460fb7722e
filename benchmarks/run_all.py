"""Run the benchmarks and write docs/performance.md from their JSON (``make bench``).

Each benchmark script runs in its own process with ``--json`` (settings below: ``make bench``
takes about 10 minutes on 2 cores, and ``memory``'s hour of simulated walking 15-40 more;
``--quick``: minimal repetitions, to check the generator);
its figures become one table (median, spread, ratio to the script's in-run reference, target,
met) on a page made from ``benchmarks/performance.md.in`` with the machine, the date and the
commit, written atomically.  A benchmark that fails is listed with its error and the exit
status is 1; the others are still written.  Explanations live in docs/performance-notes.md.
``--merge``: put the tables of the benchmarks run (or, with ``--render-only``, loaded) into
the existing page, keeping its other tables as they are; each merged table names its own
date and commit, and the page's summary is counted again from all its tables (one benchmark
re-measured without the others' 35 minutes).

    PYTHONPATH=. python benchmarks/run_all.py [--out docs/performance.md] [--only NAME ...]
        [--quick] [--results DIR] [--render-only] [--merge]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from string import Template
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # hp_model, when run from a checkout without the install
BENCH = ROOT / "benchmarks"
GAIT = "tests/data/controller/gait_demo.json"  # the demo subject's gait and tube (committed)
TUBE = "tests/data/controller/tube_demo.json"
PACKAGES = ("numpy", "scipy", "casadi", "pin", "piqp", "fmpy", "eclipse-zenoh", "dask",
            "distributed", "matplotlib", "mcap")


@dataclass
class Row:
    """One figure of a benchmark's table."""

    figure: str
    median: float | None
    spread: str = ""  # "min-max", "p99 x", ...
    ratio: float | None = None  # to the benchmark's in-run reference
    target: str = ""
    met: bool | None = None


@dataclass
class Bench:
    """A benchmark script, its arguments (full and --quick), and its table from its JSON."""

    name: str
    title: str
    args: list[str]
    quick: list[str]
    rows: Callable[[Any], list[Row]]
    reference: str = ""  # what the ratio column divides by
    note: str = ""


@dataclass
class Outcome:
    bench: Bench
    args: list[str]
    seconds: float = 0.0
    load: tuple[float, float] = (0.0, 0.0)
    rows: list[Row] = field(default_factory=list)
    error: str = ""
    quick: bool = False
    stamp: str = ""  # "date at commit", when measured (kept in its meta)


def mm(d: dict[str, float], scale: float = 1.0) -> tuple[float, str]:
    """(median, "min-max") of a {median, min, max} dict."""
    return scale * d["median"], f"{fmt(scale * d['min'])}-{fmt(scale * d['max'])}"


def fmt(x: float | None) -> str:
    if x is None:
        return ""
    a = abs(x)
    if float(x).is_integer() and a < 1e6:
        return f"{int(x)}"
    if a >= 100:
        return f"{x:.0f}"
    if a >= 10:
        return f"{x:.1f}"
    return f"{x:.2f}" if a >= 1 else f"{x:.3g}"


# ------------------------------------------------------------------ tables per benchmark

def model_rows(j: dict[str, Any]) -> list[Row]:
    out = []
    for name, r in j.items():
        target, met = "", None
        if name == "ours C: D,H,J,Jdot qd":
            target, met = "ratio <= 1", r["ratio_to_pinocchio_crba_rnea"] <= 1.0
        elif name == "ours C: constrained dynamics":
            target, met = "< 5 us", r["median_us"] < 5.0
        out.append(Row(f"{name} (us)", r["median_us"], f"{fmt(r['min_us'])}-{fmt(r['max_us'])}",
                       r["ratio_to_pinocchio_crba_rnea"], target, met))
    return out


def stage_rows(key: str, unit: str, targets: dict[str, tuple[str, float]]
               ) -> Callable[[Any], list[Row]]:
    def rows(j: dict[str, Any]) -> list[Row]:
        out = []
        for name, d in j[key].items():
            med, spread = mm(d)
            t = targets.get(name)
            out.append(Row(f"{name} ({unit})", med, spread, None, f"< {t[1]:g} {unit}" if t else "",
                           med < t[1] if t else None))
        return out
    return rows


def gait_rows(j: dict[str, Any]) -> list[Row]:
    out = []
    for name, d in j["figures"].items():
        med, spread = mm(d)
        ok = name == "build + solve (s)"
        out.append(Row(name, med, spread, None, "< 60 s" if ok else "", med < 60 if ok else None))
    return out


def gait_multicontact_rows(j: dict[str, Any]) -> list[Row]:
    walls = j["walls_s"]
    med = float(j["median_s"])
    iters = j["iterations"]
    return [Row("targets, NLP and the three IPOPT solves (s)", med,
                f"{fmt(min(walls))}-{fmt(max(walls))}", None, "<= 60 s", med <= 60.0),
            Row("IPOPT iterations", float(statistics.median(iters)),
                f"{min(iters)}-{max(iters)}")]


def contact_controller_rows(j: dict[str, Any]) -> list[Row]:
    rows = []
    for name, r in j["controllers"].items():
        lo, hi = r["median_range_us"]
        med = float(r["median_us"])
        rows += [Row(f"{name} tick, {r['ticks']} ticks of its walk (us)", med,
                     f"{fmt(lo)}-{fmt(hi)}", None, "<= 40 us median", med <= 40.0),
                 Row("  p99 (us)", float(r["p99_us"])),
                 Row("  stance / swing median (us)", float(r["stance_median_us"]),
                     f"swing {fmt(float(r['swing_median_us']))}")]
    return rows


def playback_rows(j: dict[str, Any]) -> list[Row]:
    f, p = j["fit_s"], j["per_frame_us"]
    total = mm(f["total"])
    pin = p["pinocchio"]["median"]
    ours = mm(p["ours"])
    return [Row(f"playback of {j['steps']} steps + tube fit (s)", *total, None, "< 5 s",
                total[0] < 5.0),
            Row("  of which playback (s)", *mm(f["playback"])),
            Row("  of which tube fit (s)", *mm(f["tube"])),
            Row("F_s per frame, Pinocchio + numpy (us)", *mm(p["pinocchio"]), 1.0),
            Row("F_s per frame, ours (socket_ps, C) (us)", *ours, ours[0] / pin, "ratio <= 1",
                ours[0] <= pin)]


def controller_rows(j: dict[str, Any]) -> list[Row]:
    ref = j["rows"]["piqp"]["median_us"]
    out = []
    for name, r in j["rows"].items():
        target, met = "", None
        if name == "clfqp":
            target = "median <= 40 us, p99 <= 150 us, ratio <= 2.5"
            met = r["median_us"] <= 40 and r["p99_us"] <= 150 and r["median_us"] / ref <= 2.5
        label = "bare piqp update + solve" if name == "piqp" else name
        out.append(Row(f"{label} (us per tick)", r["median_us"], f"p99 {fmt(r['p99_us'])}",
                       r["median_us"] / ref, target, met))
    return out


def fmu_rows(j: dict[str, Any]) -> list[Row]:
    b = j["build_s"]
    py = j["python_us_per_period"]
    return [Row("FMU build, total (s)", b["total"], "", None, "< 60 s", b["total"] < 60),
            Row("FMU doStep 1 ms via fmpy (us)", j["fmu_doStep_us_median"],
                f"p90 {fmt(j['fmu_doStep_us_p90'])}", j["fmu_doStep_us_median"] / py,
                "<= 15 us (issue 22)", j["fmu_doStep_us_median"] <= 15),
            Row("FMU doStep via plain ctypes (us)", j["fmu_doStep_ctypes_us_median"], "",
                j["fmu_doStep_ctypes_us_median"] / py),
            Row("set 2 inputs + doStep + get 6 outputs (us)", j["fmu_exchange_us_median"], "",
                j["fmu_exchange_us_median"] / py),
            Row("Python HybridSimulator per 1 ms period, mean (us)", py, "", 1.0,
                "FMU >= 10x faster", j["ratio_median"] >= 10),
            *_multicontact_fmu_rows(j.get("multicontact"))]


def _multicontact_fmu_rows(m: dict[str, Any] | None) -> list[Row]:
    """The multi-contact FMU's rows (openOFM's committed cycle; issue 37), when measured."""
    if m is None:
        return []
    py = m["python_us_per_period"]
    return [Row("multi-contact FMU build, total (s)", m["build_s"]["total"], "", None,
                "< 60 s", m["build_s"]["total"] < 60),
            Row("multi-contact FMU doStep 1 ms via fmpy (us)", m["fmu_doStep_us_median"],
                f"p90 {fmt(m['fmu_doStep_us_p90'])}", m["fmu_doStep_us_median"] / py,
                "<= 30 us (issue 37)", m["fmu_doStep_us_median"] <= 30),
            Row("multi-contact: Python HybridSimulator per 1 ms period, mean (us)", py, "", 1.0,
                "FMU >= 10x faster", m["ratio_median"] >= 10)]


def accuracy_rows(j: dict[str, Any]) -> list[Row]:
    w, f = j["per_step"], j["free_running"]
    sub, ref = j["substeps"], j["ref_substeps"]
    return [Row(f"state error at every impact, max (RK4 x{sub}; q, qd- inf-norm)", w["state"],
                "", None, f"< {j['target_state_error']:g}", w["state"] < j["target_state_error"]),
            Row("  of which q (m, rad)", w["q"]),
            Row("  of which qd- (m/s, rad/s)", w["qd"]),
            Row("impact time error, max (s)", w["t"]),
            Row(f"reference's own error, RK4 x{ref} (Richardson: x{ref // 2} / 15)",
                j["reference_error_estimate"]),
            Row(f"free running {j['steps']} steps: state error, max (loop sensitivity)",
                f["state"]),
            Row(f"free running {j['steps']} steps: impact time error, max (s)", f["t"])]


def sweep_rows(j: dict[str, Any]) -> list[Row]:
    rates = {k: v for k, v in j["runs_per_min"].items() if v}
    ref = rates.get("serial")
    med = {k: sorted(v)[len(v) // 2] if len(v) % 2 else sum(sorted(v)[len(v) // 2 - 1:
                                                                 len(v) // 2 + 1]) / 2
           for k, v in rates.items()}
    out = [Row(f"{k} (runs/min)", med[k], f"{fmt(min(v))}-{fmt(max(v))}",
               med[k] / med["serial"] if ref else None) for k, v in rates.items()]
    if "dask 1 worker" in rates and "dask 2 workers" in rates:
        r = [b / a for a, b in zip(rates["dask 1 worker"], rates["dask 2 workers"], strict=True)]
        out.append(Row("2 workers / 1 worker, per repeat", sorted(r)[len(r) // 2],
                       f"{fmt(min(r))}-{fmt(max(r))}", None, "ideal 2.00"))
    return out


def bus_rows(j: dict[str, float]) -> list[Row]:
    return [Row(f"{k} (us)" if "round trip" in k else f"{k} (us, best of 7 repeats)", v)
            for k, v in j.items()]


def cosim_rows(j: dict[str, Any]) -> list[Row]:
    f = j["figures"]
    out = []
    for key in ("real_time_factor", "tick", "round_trip", "fmu", "overhead",
                "overhead % of (round trip + FMU)", "reply median (latency)",
                "reply p99 (latency)", "controller tick (node)", "MCAP MB"):
        med, spread = mm(f[key])
        target, met = "", None
        if key == "real_time_factor":
            target, met = ">= 5 (issue 22)", med >= 5
        elif key.startswith("overhead %"):
            target, met = "<= 30 %", med <= 30
        unit = ("" if key in ("real_time_factor", "MCAP MB") or "%" in key
                else " (us)" if "latency" in key else " (us per tick)")
        out.append(Row(key.replace("_", " ") + unit, med, spread, None, target, met))
    return out


def floor_rows(j: dict[str, Any]) -> list[Row]:
    f = j["figures"]
    out = []
    for key in ("real_time_factor", "period", "round trip", "fmu",
                "controller tick (controller process)"):
        med, spread = mm(f[key])
        target, met = ("", None)
        if key == "real_time_factor":  # the co-simulation's target cannot exceed this
            target, met = ">= 5 (the co-simulation's ceiling)", med >= 5
        unit = "" if key == "real_time_factor" else " (us per period)"
        out.append(Row(key.replace("_", " ") + unit, med, spread, None, target, met))
    return out


def cold_tick_rows(j: dict[str, Any]) -> list[Row]:
    def median(v: list[float]) -> float:
        v = sorted(v)
        return v[len(v) // 2] if len(v) % 2 else (v[len(v) // 2 - 1] + v[len(v) // 2]) / 2

    out = []
    for name, c in j["controllers"].items():
        for mode, rounds in c["medians_cpu_wall_us"].items():
            cpu = [x[0] for x in rounds]
            rr = c["ratios"].get(mode)
            label = "back to back" if mode == "back-to-back" else f"{mode} of {j['gap_us']:g} us"
            out.append(Row(f"{name}: tick {label} (us CPU)", median(cpu),
                           f"{fmt(min(cpu))}-{fmt(max(cpu))}",
                           median(rr) if rr else None))
    return out


def realtime_rows(j: list[dict[str, Any]]) -> list[Row]:
    n = len(j)
    done = sum(bool(r["completed"]) for r in j)
    out = [Row("runs completed", float(done), f"of {n}", None, "all", done == n)]
    for key, label in (("late", "late replies"), ("missed", "missed replies"),
                       ("overruns", "plant overruns"), ("skipped_slots", "skipped slots"),
                       ("max_lag_ms", "largest lag (ms)"),
                       ("latency_median_us", "reply latency, median (us)"),
                       ("latency_p99_us", "reply latency, p99 (us)"),
                       ("real_time_factor", "real-time factor")):
        v = sorted(float(r[key]) for r in j)
        med = v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2
        target, met = ("0", max(v) == 0) if key == "missed" else ("", None)
        out.append(Row(label, med, f"{fmt(v[0])}-{fmt(v[-1])}", None, target,
                       met))
    return out


def memory_rows(j: dict[str, Any]) -> list[Row]:
    p, n = j["plant"], j.get("node") or {}
    dur, warm = j["duration_s"], j["warmup_s"]
    out = [Row(f"orchestrator RSS after {fmt(warm)} s simulated (MB)", p["warm_mb"]),
           Row(f"orchestrator RSS at {fmt(dur)} s simulated (MB)", p["end_mb"],
               f"max {fmt(p['max_mb'])}"),
           Row("orchestrator growth after the warm-up (%)", p["growth_pct"], "", None,
               "<= 10 % over 3600 s (issue 39)",
               abs(p["growth_pct"]) <= 10 if dur >= 3600 else None),
           Row("orchestrator slope (MB per simulated hour)", p["slope_mb_per_h"], "", None,
               "", None)]
    if n:
        out.append(Row("controller node growth after the warm-up (%)", n["growth_pct"],
                       f"{fmt(n['warm_mb'])} -> {fmt(n['end_mb'])} MB"))
    out.append(Row("restarts (the walker fell or the run faulted)", float(j["restarts"])))
    return out


BENCHES = (
    Bench("model", "12-DOF model from Python, against Pinocchio in the same run",
          ["--repeats", "15", "--calls", "2000"], ["--repeats", "2", "--calls", "50"],
          model_rows, "Pinocchio crba + rnea"),
    Bench("mocap", "motion capture: `mocap process` on a 37-step synthetic take at 120 Hz, "
          "its own work (imports not counted) and end to end",
          ["--repeats", "7"], ["--repeats", "1"],
          stage_rows("stages_s", "s", {"process_file()": ("", 1.0)})),
    Bench("gait", "PHZD gait optimization (two domains, 12 DOF) from the regression's guess",
          ["--repeats", "2"], ["--repeats", "1"], gait_rows),
    Bench("gait_multicontact", "the person's gait on the multi-contact graph (`gait fit "
          "--domains multicontact`) on openOFM's walk, the take's subject",
          ["--repeats", "3"], ["--repeats", "1"], gait_multicontact_rows),
    Bench("contact_controllers", "the multi-contact graph's prosthesis controllers (clfqp, "
          "contact-pd): each one's tick on the measurements of its own walk of the committed "
          "openOFM cycle", ["--repeats", "5"], ["--repeats", "1", "--steps", "2"],
          contact_controller_rows),
    Bench("tube_fit", "force-tube fit: 20 profiles x 150 samples, degree 3",
          ["--repeats", "15"], ["--repeats", "1"],
          stage_rows("stages_ms", "ms", {"fit_tube (all)": ("", 1000.0)})),
    Bench("playback", "socket-force playback of 20 steps + tube fit; F_s per frame",
          ["--repeats", "5", "--frame-repeats", "3"],
          ["--repeats", "1", "--frame-repeats", "1", "--steps", "4"], playback_rows,
          "Pinocchio + numpy per frame"),
    Bench("controllers", "controller tick along the demo gait's stance (its fitted tube)",
          ["--gait", GAIT, "--tube", TUBE, "--ticks", "5000", "--repeats", "3"],
          ["--gait", GAIT, "--tube", TUBE, "--ticks", "300", "--repeats", "1"],
          controller_rows, "bare piqp update + solve of the relaxed QPs"),
    Bench("fmu", "human FMU (fmpy) against the in-process Python simulator",
          ["--periods", "3000"], ["--periods", "300"], fmu_rows,
          "Python simulator per period"),
    Bench("accuracy", "integration accuracy of the FMU's doStep (= the in-process simulator): "
          "per-step restart against a tight reference, clfqp on the demo gait",
          ["--steps", "20"], ["--steps", "2"], accuracy_rows),
    Bench("sweep", "sweep throughput (examples/sweep/quick.toml), serial and Dask",
          ["--draws", "10", "--steps", "3", "--repeats", "2"],
          ["--draws", "2", "--steps", "1", "--repeats", "1", "--serial-only"], sweep_rows,
          "serial, in process"),
    Bench("bus", "CAN codec, MCAP writes, zenoh round trip between two processes",
          ["--frames", "2000"], ["--frames", "200"], bus_rows),
    Bench("cosim", "lockstep co-simulation (clfqp, demo gait, MCAP recording)",
          ["--gait", GAIT, "--tube", TUBE, "--steps", "10", "--runs", "3"],
          ["--gait", GAIT, "--tube", TUBE, "--steps", "1", "--runs", "1"], cosim_rows),
    Bench("lockstep_floor", "the co-simulation's ceiling: the FMU and clfqp in two processes "
          "over zenoh, no CAN, checks or recording",
          ["--gait", GAIT, "--tube", TUBE, "--steps", "10", "--runs", "3"],
          ["--gait", GAIT, "--tube", TUBE, "--steps", "1", "--runs", "1"], floor_rows),
    Bench("cold_tick", "the same controller ticks back to back and after a pause (what a "
          "lockstep side meets each tick)",
          ["--gait", GAIT, "--tube", TUBE, "--ticks", "2000", "--rounds", "5"],
          ["--gait", GAIT, "--tube", TUBE, "--ticks", "100", "--rounds", "1"],
          cold_tick_rows, "back to back, same round"),
    Bench("realtime", "real-time co-simulation (paced to the wall clock)",
          ["--gait", GAIT, "--tube", TUBE, "--steps", "3", "--runs", "3"],
          ["--gait", GAIT, "--tube", TUBE, "--steps", "1", "--runs", "1"], realtime_rows),
    Bench("memory", "memory over a long lockstep co-simulation (clfqp, MCAP recording; "
          "--duration: simulated s)", ["--gait", GAIT, "--tube", TUBE, "--duration", "3600"],
          ["--gait", GAIT, "--tube", TUBE, "--duration", "20", "--warmup", "5"], memory_rows),
)


# ------------------------------------------------------------------ machine, running, page

def machine() -> dict[str, str]:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    versions = []
    for p in PACKAGES:
        try:
            versions.append(f"{p} {metadata.version(p)}")
        except metadata.PackageNotFoundError:
            continue
    return {"cpu": cpu, "cores": str(os.cpu_count()), "os": platform.platform(terse=True),
            "python": platform.python_version(), "packages": ", ".join(versions)}


def commit() -> str:
    def git(*a: str) -> str:
        r = subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True)
        return r.stdout.strip() if r.returncode == 0 else ""

    rev = git("rev-parse", "--short=10", "HEAD") or "unknown (not a git checkout)"
    dirty = git("status", "--porcelain", "--untracked-files=no")
    return f"{rev} (with uncommitted changes)" if dirty else rev


def run(b: Bench, args: list[str], results: Path, quick: bool = False) -> Outcome:
    """Run one benchmark script; its JSON in ``results/NAME.json``, its output in
    ``results/NAME.log``."""
    o = Outcome(b, args, quick=quick)
    path = results / f"{b.name}.json"
    path.unlink(missing_ok=True)
    cmd = [sys.executable, str(BENCH / f"bench_{b.name}.py"), *args, "--json", str(path)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    with open(results / f"{b.name}.log", "w") as log:
        r = subprocess.run(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
    o.seconds, o.load = time.perf_counter() - t0, (load0, os.getloadavg()[0])
    o.stamp = f"{datetime.now(UTC).strftime(DATE)} at commit `{commit()}`"
    meta = {"args": args, "seconds": o.seconds, "load": o.load, "quick": quick,
            "stamp": o.stamp}
    (results / f"{b.name}.meta.json").write_text(json.dumps(meta))
    if r.returncode != 0:
        tail = (results / f"{b.name}.log").read_text().strip().splitlines()
        o.error = f"exit {r.returncode}: {tail[-1] if tail else 'no output'}"
        return o
    return load(b, results)


def load(b: Bench, results: Path) -> Outcome:
    """The outcome of a finished run from ``results`` (its JSON and meta)."""
    try:
        meta = json.loads((results / f"{b.name}.meta.json").read_text())
        o = Outcome(b, list(meta["args"]), float(meta["seconds"]), tuple(meta["load"]),
                    quick=bool(meta.get("quick", False)), stamp=str(meta.get("stamp", "")))
    except (OSError, ValueError, KeyError, TypeError) as e:
        return Outcome(b, [], error=f"its {b.name}.meta.json: {type(e).__name__}: {e}")
    try:
        o.rows = b.rows(json.loads((results / f"{b.name}.json").read_text()))
    except (OSError, ValueError, KeyError, TypeError) as e:
        o.error = f"its JSON: {type(e).__name__}: {e}"
    return o


def table(o: Outcome, stamped: bool = False) -> str:
    """The section of one benchmark; ``stamped``: saying when and at which commit it was
    measured (a table merged into an older page)."""
    b = o.bench
    head = (f"### {b.name}: {b.title}\n\n`benchmarks/bench_{b.name}.py {' '.join(o.args)}`: "
            f"{o.seconds:.0f} s, load average {o.load[0]:.1f} -> {o.load[1]:.1f}.")
    if stamped:
        head += f" Measured {o.stamp or 'at an unrecorded date and commit'}" + \
            (" (**--quick**)." if o.quick else ".")
    if o.error:
        return f"{head}\n\n**Failed** ({o.error}); its output: `{b.name}.log`.\n"
    if b.reference:
        head += f" Ratio: to {b.reference}, in the same run."
    lines = [head, "", "| figure | median | spread | ratio | target | met |",
             "|---|---:|---:|---:|---|:---:|"]
    for r in o.rows:
        met = "" if r.met is None else ("yes" if r.met else "**no**")
        lines.append(f"| {r.figure} | {fmt(r.median)} | {r.spread} | {fmt(r.ratio)} | "
                     f"{r.target} | {met} |")
    return "\n".join(lines) + "\n"


DATE = "%Y-%m-%d %H:%M UTC"
_SECONDS = re.compile(r"^`benchmarks/bench_\w+\.py[^`]*`: (\d+) s,", re.M)
_MET = re.compile(r"^\|.*\| (yes|\*\*no\*\*) \|$", re.M)
_MACHINE = {"CPU": "cpu", "cores": "cores", "OS": "os", "Python": "python",
            "packages": "packages"}
_STAMP = re.compile(r"^Measured (.+?) at commit `(.+?)` by", re.M)


def summary(tables: list[str], quick: bool) -> str:
    """The page's summary line, counted from its sections (as :func:`table` writes them)."""
    failed = [t[4:].split(":", 1)[0] for t in tables if "\n**Failed** (" in t]
    met = [m for t in tables for m in _MET.findall(t)]
    minutes = sum(int(s) for t in tables for s in _SECONDS.findall(t)) / 60
    out = (f"{len(tables)} benchmarks, {minutes:.1f} min; targets met: "
           f"{met.count('yes')} of {len(met)}"
           + (f"; **failed: {', '.join(failed)}**" if failed else ""))
    return out + (" (**--quick**: minimal repetitions, figures not comparable)" if quick else "")


def render(tables: list[str], when: str, rev: str, quick: bool, note: str = "",
           m: dict[str, str] | None = None) -> str:
    """The page: the template filled with the machine ``m`` (default this one), ``when`` and
    ``rev``, the summary (and ``note``) and the sections."""
    m = m or machine()
    tmpl = Template((BENCH / "performance.md.in").read_text())
    return tmpl.substitute(
        date=when, commit=rev, cpu=m["cpu"], cores=m["cores"], os=m["os"],
        python=m["python"], packages=m["packages"], summary=summary(tables, quick) + note,
        tables="\n".join(tables))


def sections(page: str) -> tuple[str, dict[str, str]]:
    """A page's header and its sections by benchmark name (each from its ``### name:``)."""
    parts = re.split(r"^(?=### )", page, flags=re.M)
    return parts[0], {p[4:].split(":", 1)[0]: p.rstrip("\n") + "\n" for p in parts[1:]}


def merged(old: str, outcomes: list[Outcome]) -> str:
    """``old`` (a page this script wrote) with the sections of ``outcomes`` in place of (or
    beside) its own, in :data:`BENCHES` order; ValueError (one line) for a page not
    written here or on another machine."""
    head, kept = sections(old)
    stamp = _STAMP.search(head)
    rows = dict(re.findall(r"^\| (CPU|cores|OS|Python|packages) \| (.*) \|$", head, re.M))
    if stamp is None or not kept or len(rows) != len(_MACHINE):
        raise ValueError("not a page written by run_all.py (no 'Measured ... at commit', "
                         "machine table or benchmark section)")
    was = {key: rows[label] for label, key in _MACHINE.items()}
    now = machine()
    for key in ("cpu", "cores"):
        if was[key] != now[key]:
            raise ValueError(f"measured on another machine (its {key} is {was[key]!r}, "
                             f"not {now[key]!r}): run all the benchmarks instead")
    new = {o.bench.name: table(o, stamped=True) for o in outcomes}
    tables = [new.get(b.name) or kept[b.name] for b in BENCHES
              if b.name in new or b.name in kept]
    # the tables re-measured since the page's run: these, and those an earlier merge dated
    dated = [b.name for b in BENCHES if b.name in new
             or (b.name in kept and re.search(r"\. Measured .+ at commit", kept[b.name]))]
    note = ("; re-measured since, each dated in its table: " + ", ".join(dated)) if dated else ""
    quick = "(**--quick**" in head or any(o.quick for o in outcomes)
    return render(tables, stamp.group(1), stamp.group(2), quick, note, was)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "performance.md")
    ap.add_argument("--only", action="append", metavar="NAME",
                    help=f"run only these ({', '.join(b.name for b in BENCHES)})")
    ap.add_argument("--quick", action="store_true", help="minimal repetitions (a check)")
    ap.add_argument("--results", type=Path,
                    help="keep each benchmark's JSON and output here (default: a temporary "
                    "folder)")
    ap.add_argument("--render-only", action="store_true",
                    help="write the page from --results of an earlier run, running nothing")
    ap.add_argument("--merge", action="store_true",
                    help="put these benchmarks' tables into the existing --out page, keeping "
                    "its other tables")
    a = ap.parse_args(argv)
    names = {b.name: b for b in BENCHES}
    unknown = [n for n in a.only or [] if n not in names]
    if unknown:
        print(f"run_all: error: unknown benchmark {unknown[0]!r}; choose from "
              f"{', '.join(names)}", file=sys.stderr)
        return 2
    if a.render_only and not (a.results and a.results.is_dir()):
        print("run_all: error: --render-only needs --results DIR of an earlier run",
              file=sys.stderr)
        return 2
    if not a.out.parent.is_dir():
        print(f"run_all: error: {a.out.parent} is not a folder", file=sys.stderr)
        return 2
    old = None
    if a.merge:
        try:
            old = a.out.read_text()
            merged(old, [])  # refuse a page it cannot merge into before running anything
        except (OSError, ValueError) as e:
            print(f"run_all: error: --merge into {a.out}: "
                  f"{getattr(e, 'strerror', None) or e}", file=sys.stderr)
            return 2
    chosen = [names[n] for n in a.only] if a.only else list(BENCHES)
    when = datetime.now(UTC)
    with tempfile.TemporaryDirectory() as tmp:
        results = a.results or Path(tmp)
        results.mkdir(parents=True, exist_ok=True)
        outcomes = []
        for b in chosen:
            if a.render_only:
                if not (results / f"{b.name}.meta.json").exists():
                    continue
                o = load(b, results)
            else:
                print(f"bench_{b.name} ...", end=" ", flush=True)
                o = run(b, b.quick if a.quick else b.args, results, a.quick)
                print(f"{o.seconds:.0f} s" + (f": FAILED ({o.error})" if o.error else ""),
                      flush=True)
            outcomes.append(o)
        page = (merged(old, outcomes) if old is not None else
                render([table(o) for o in outcomes], when.strftime(DATE), commit(),
                       any(o.quick for o in outcomes)))
    from hp_model.atomic_io import atomic_write_bytes

    try:
        atomic_write_bytes(a.out, page.encode())
    except OSError as e:
        print(f"run_all: error: cannot write {a.out}: {e.strerror or e}", file=sys.stderr)
        return 2
    print(f"wrote {a.out}")
    return 1 if any(o.error for o in outcomes) else 0


if __name__ == "__main__":
    sys.exit(main())
