"""Every verb of ``hpcosim`` with bad arguments: one line ``hpcosim: error: ...`` on stderr
naming what is wrong, a non-zero exit, never a traceback and nothing on stdout."""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import pytest
import typer.main

from orchestrator.cli import app, main


def _leaves(cmd, path=()):
    subs = getattr(cmd, "commands", None)
    if subs:
        for name, sub in subs.items():
            yield from _leaves(sub, (*path, name))
    else:
        yield path, cmd


LEAVES = dict(_leaves(typer.main.get_command(app)))


OUTPUTS = {"out"}  # parameters naming what a verb writes (a new path is fine there)


def _required(cmd, value: str, out: str) -> list[str]:
    """Every required argument and option of ``cmd``: inputs given ``value``, outputs
    ``out``."""
    args: list[str] = []
    for p in cmd.params:
        if not p.required:
            continue
        v = out if p.name in OUTPUTS else value
        kind = p.type_descriptor.annotation
        if isinstance(kind, type) and issubclass(kind, Enum):  # a closed set: its first word
            v = str(next(iter(kind)).value)
        args += [v] if p.param_type_name == "argument" else [p.opts[0], v]
    return args


def _has_input(cmd) -> bool:
    return any(p.required and p.name not in OUTPUTS for p in cmd.params)


WITH_INPUT = sorted(p for p, c in LEAVES.items() if _has_input(c))


def _one_line_error(capsys, argv: list[str], *words: str) -> str:
    rc = main(argv)
    cap = capsys.readouterr()
    assert rc != 0, argv
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hpcosim: error: "), (argv, cap.err)
    assert "Traceback" not in cap.err and not cap.out.strip(), (argv, cap)
    for w in words:
        assert w in lines[0], (argv, lines[0])
    return lines[0]


def test_every_verb_is_reached():
    names = {" ".join(p) for p in LEAVES}
    assert {"run", "replay", "demo", "experiments", "gait fit", "tube fit", "tube refit",
            "mocap process", "mocap synth", "fmu build", "sweep run", "sweep report",
            "sweep replay", "model check", "controller serve"} <= names


@pytest.mark.parametrize("path", sorted(LEAVES), ids=" ".join)
def test_unknown_option(capsys, path):
    _one_line_error(capsys, [*path, "--no-such-option"], "--no-such-option")


@pytest.mark.parametrize("path", WITH_INPUT, ids=" ".join)
def test_missing_file(capsys, path, tmp_path):
    args = _required(LEAVES[path], str(tmp_path / "missing" / "file.json"),
                     str(tmp_path / "out"))
    _one_line_error(capsys, [*path, *args])


@pytest.mark.parametrize("path", WITH_INPUT, ids=" ".join)
def test_directory_instead_of_a_file(capsys, path, tmp_path):
    d = tmp_path / "a_directory"
    d.mkdir()
    _one_line_error(capsys, [*path, *_required(LEAVES[path], str(d), str(tmp_path / "out"))])


NUMBERS = [(("run",), "--steps"), (("run",), "--max-time"), (("demo",), "--steps"),
           (("experiments",), "--steps"), (("mocap", "synth"), "--steps"),
           (("tube", "fit"), "--degree"), (("gait", "fit"), "--degree"),
           (("sweep", "run"), "--workers"), (("replay",), "--speed")]


BAD_VALUES = ["abc", "0", "-1", "nan"]
#: valid zeros: degree 0 (a constant curve), replay speed 0 (as fast as possible)
VALID = {("--degree", "0"), ("--speed", "0")}
CASES = [(p, o, v) for p, o in NUMBERS for v in BAD_VALUES if (o, v) not in VALID]


@pytest.mark.parametrize(("path", "opt", "value"), CASES,
                         ids=[f"{' '.join(p)} {o} {v}" for p, o, v in CASES])
def test_bad_numbers(capsys, path, opt, value, tmp_path):
    args = _required(LEAVES[path], "x", str(tmp_path / "out"))
    _one_line_error(capsys, [*path, *args, opt, value], opt)


DATA = Path(__file__).resolve().parent / "data" / "controller"
GAIT, TUBE = str(DATA / "gait_demo.json"), str(DATA / "tube_demo.json")
BAD_BUS = {"unknown interface": 'interface = "no-such-can"\n',
           "unknown key": 'interface = "zenoh"\nbogus = 1\n',
           "not TOML": "interface = \n"}


@pytest.mark.parametrize("case", sorted(BAD_BUS))
@pytest.mark.parametrize("verb", ["serve", "replay"])
def test_bad_bus_configs(capsys, tmp_path, case, verb):
    bus = tmp_path / "bus.toml"
    bus.write_text(BAD_BUS[case])
    argv = (["controller", "serve", "--controller", "clfqp", "--gait", GAIT, "--tube", TUBE,
             "--bus", str(bus)] if verb == "serve"
            else ["replay", str(DATA / "NOTICE.md"), "--to-bus", str(bus)])
    line = _one_line_error(capsys, argv)
    assert str(bus) in line or "no-such-can" in line


def test_a_file_that_is_not_an_fmu(capsys, tmp_path):
    fmu = tmp_path / "human.fmu"
    fmu.write_text("garbage")
    _one_line_error(capsys, ["run", "--controller", "clfqp", "--gait", GAIT, "--tube", TUBE,
                             "--fmu", str(fmu), "--steps", "1"], str(fmu), "not an FMU")


#: a folder nobody may create, root included (sysfs refuses it): a read-only output
READ_ONLY_OUT = "/sys/hpcosim-read-only/out"
#: every verb that writes, with inputs it accepts: the output is checked before any work
WRITERS = {"mocap synth": ["mocap", "synth", "--out", READ_ONLY_OUT],
           "demo": ["demo", "--out", READ_ONLY_OUT],
           "experiments": ["experiments", "--gait", GAIT, "--tube", TUBE, "--out",
                           READ_ONLY_OUT],
           "gait fit": ["gait", "fit", GAIT, "--out", READ_ONLY_OUT + ".json"],
           "tube fit": ["tube", "fit", GAIT, "--gait", GAIT, "--out", READ_ONLY_OUT + ".json"],
           "fmu build": ["fmu", "build", "--gait", GAIT, "--out", READ_ONLY_OUT + ".fmu"],
           "run": ["run", "--controller", "clfqp", "--gait", GAIT, "--tube", TUBE, "--steps",
                   "1", "--record", READ_ONLY_OUT + ".mcap"],
           "sweep run": ["sweep", "run", str(Path(__file__).resolve().parents[1] / "examples"
                                             / "sweep" / "quick.toml"),
                         "--out", READ_ONLY_OUT, "--workers", "1"]}


@pytest.mark.parametrize("verb", sorted(WRITERS))
def test_read_only_output(capsys, verb):
    _one_line_error(capsys, WRITERS[verb], "/sys/hpcosim-read-only")


@pytest.mark.parametrize("path", WITH_INPUT, ids=" ".join)
def test_unreadable_file(capsys, path, tmp_path):
    """Every input given a file that is not what the verb reads (binary garbage, not UTF-8,
    not JSON, TOML, C3D, MCAP, NPZ or an FMU)."""
    bad = tmp_path / "garbage.bin"
    bad.write_bytes(bytes(range(256)) * 4)
    _one_line_error(capsys, [*path, *_required(LEAVES[path], str(bad), str(tmp_path / "o"))])


#: every option that is a choice of words, with the words it offers
CHOICES = [(["model", "check"], "--backend", "'auto', 'c', 'sx'"),
           (["run", "--controller", "clfqp", "--gait", GAIT, "--tube", TUBE], "--mode",
            "'lockstep', 'realtime'"),
           (["sweep", "run", "spec.toml", "--out", "o"], "--backend", "'simulator', 'fmu'"),
           (["sweep", "replay", "o", "clfqp/human/0"], "--backend", "'simulator', 'fmu'"),
           (["tube", "fit", "s.npz", "--gait", GAIT, "--out", "t.json"], "--phase",
            "'gait', 'step'")]


@pytest.mark.parametrize(("argv", "opt", "words"), CHOICES,
                         ids=[f"{' '.join(a[:2])} {o}" for a, o, _ in CHOICES])
def test_a_choice_outside_its_words_names_them(capsys, argv, opt, words):
    _one_line_error(capsys, [*argv, opt, "nonsense"], opt, "'nonsense'", words)
