"""Paths relative to the user's working folder work for every option of every verb
(``orchestrator.cli.paths``): a co-simulation run from a folder of its own with relative
paths for every file it takes, and, for every verb walked from the app, every path parameter
given a relative path reaches the verb as the absolute path in the working folder."""

from __future__ import annotations

import functools
import shutil
from enum import Enum
from pathlib import Path

import pytest
import typer.main

import hp_model
from orchestrator.cli import app, main
from orchestrator.cli.paths import is_absolutized
from orchestrator.cli.synopsis import verbs
from tests.cli_support import GAIT, TUBE, cosim_files, hpcosim

__all__ = ["cosim_files"]  # a fixture of tests/cli_support.py


def _callbacks(t: typer.Typer, prefix: tuple[str, ...] = ()) -> dict[tuple[str, ...], object]:
    """Verb path -> the callback typer calls (the app's registrations, sub-apps included)."""
    out: dict[tuple[str, ...], object] = {}
    for info in t.registered_commands:
        name = info.name or info.callback.__name__.replace("_", "-")
        out[(*prefix, name)] = info.callback
    for g in t.registered_groups:
        out.update(_callbacks(g.typer_instance, (*prefix, g.name)))
    return out


CALLBACKS = _callbacks(app)
PATH_PARAMS = {path: [p for p in cmd.params if p.type_descriptor.annotation is Path]
               for path, cmd in verbs()}


def test_every_verb_takes_its_paths_from_the_working_folder():
    assert set(CALLBACKS) == set(PATH_PARAMS)
    assert all(is_absolutized(cb) for cb in CALLBACKS.values())
    assert sum(len(v) for v in PATH_PARAMS.values()) >= 40  # the table below is not empty


def _argv(cmd, rel: dict[str, str]) -> list[str]:
    """Every path parameter of ``cmd`` (required or not) given its relative path in ``rel``,
    every other required one a value its type accepts."""
    args: list[str] = []
    for p in cmd.params:
        kind = p.type_descriptor.annotation
        if kind is Path:
            v = rel[p.name]
        elif not p.required:
            continue
        elif isinstance(kind, type) and issubclass(kind, Enum):
            v = str(next(iter(kind)).value)
        else:
            v = "x"
        args += [v] if p.param_type_name == "argument" else [p.opts[0], v]
    return args


@pytest.mark.parametrize("path", sorted(p for p, v in PATH_PARAMS.items() if v), ids=" ".join)
def test_relative_paths_reach_the_verb_absolute(path, tmp_path, monkeypatch):
    """The verb itself stands in for a recorder of its arguments (the wrapper looks it up at
    call time): what it would receive, run from ``tmp_path`` with relative paths."""
    cmd = dict(verbs())[path]
    rel = {p.name: f"sub/{p.name}.file" for p in PATH_PARAMS[path]}
    seen: dict[str, object] = {}
    cb = CALLBACKS[path]
    verb = cb.__wrapped__

    @functools.wraps(verb)
    def recorder(*args, **kwargs):
        seen.update(kwargs)

    monkeypatch.setattr(cb, "__wrapped__", recorder)
    monkeypatch.chdir(tmp_path)
    assert main([*path, *_argv(cmd, rel)]) == 0
    for name, r in rel.items():
        assert seen[name] == tmp_path / r and seen[name].is_absolute(), (name, seen[name])


@pytest.mark.parametrize("link", [False, True])
def test_links_are_kept_and_home_expanded(tmp_path, monkeypatch, link):
    """An output given through a symbolic link stays the link (the writer decides what to do
    with it), ``~`` is the user's home."""
    from orchestrator.cli.paths import absolute

    monkeypatch.chdir(tmp_path)
    if link:
        (tmp_path / "real").mkdir()
        (tmp_path / "via").symlink_to(tmp_path / "real")
        assert absolute("via/x.json") == tmp_path / "via" / "x.json"
    else:
        monkeypatch.setenv("HOME", str(tmp_path / "home"))
        assert absolute("~/x.json") == tmp_path / "home" / "x.json"


def test_text_paths_are_taken_from_the_working_folder_too(tmp_path, monkeypatch):
    """The two verbs that take a path as text: ``tube refit``'s recordings (globs) and
    ``animate``'s RUN.mcap reach their functions as absolute paths."""
    import orchestrator.cosim.tube_refit as tube_refit
    import orchestrator.experiments.animation as animation

    got: dict[str, object] = {}

    def refit(paths, gait, out, **kw):
        got["refit"] = paths
        shutil.copy(TUBE, out)
        return {}

    def gif(source, model, **kw):
        got["animate"] = source
        return b"GIF89a"

    monkeypatch.setattr(tube_refit, "refit_tube", refit)
    monkeypatch.setattr(animation, "recording_gif", gif)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "runs").mkdir()
    for n in ("a", "b"):
        (tmp_path / "runs" / f"{n}.mcap").write_bytes(b"")
    assert main(["tube", "refit", "runs/*.mcap", "--gait", str(GAIT), "--out", "t.json"]) == 0
    assert got["refit"] == [str(tmp_path / "runs" / f"{n}.mcap") for n in ("a", "b")]
    assert main(["animate", "runs/a.mcap", "--out", "w.gif"]) == 0
    assert got["animate"] == str(tmp_path / "runs" / "a.mcap")
    assert (tmp_path / "w.gif").read_bytes() == b"GIF89a"


@pytest.mark.serial  # a lockstep co-simulation (tests/test_cosim.py: reply deadlines)
def test_run_from_another_folder_with_relative_paths(cosim_files, tmp_path):
    """``hpcosim run`` from the user's folder, every file it takes relative to it (gait,
    tube, FMU, subject, device, the recording), while the controller process runs in the
    checkout: it walks, the recording lands in the user's folder and names the files by
    their absolute paths."""
    from orchestrator.cosim.recording import read_recording

    f = cosim_files
    for name in ("gait", "tube", "fmu"):
        shutil.copy(f[name], tmp_path / Path(f[name]).name)
    shutil.copy(hp_model.default_subject_path(), tmp_path / "subject.toml")
    shutil.copy(hp_model.default_device_path(), tmp_path / "device.toml")
    (tmp_path / "runs").mkdir()
    r = hpcosim("run", "--controller", "clfqp", "--gait", "gait.json", "--tube", "tube.json",
                "--fmu", "human.fmu", "--subject", "subject.toml", "--device", "device.toml",
                "--steps", "2", "--record", "runs/rel.mcap", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    rec = read_recording(tmp_path / "runs" / "rel.mcap", messages=False)
    assert rec.config["gait"] == str(tmp_path / "gait.json")
    assert rec.config["subject"] == str(tmp_path / "subject.toml")
    assert rec.config["record"] == str(tmp_path / "runs" / "rel.mcap")
    assert rec.metadata["summary"]["steps"] == "2"
