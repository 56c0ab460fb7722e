"""The hpcosim command line, run as a user would (a subprocess of the installed script)."""

from __future__ import annotations

import shutil
import subprocess
import sys

import hp_model

EXE = shutil.which("hpcosim") or f"{sys.executable} -m orchestrator.cli"


def run(*args: str) -> subprocess.CompletedProcess:
    cmd = [*EXE.split(), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


def test_help_and_version():
    r = run("--help")
    assert r.returncode == 0 and "model" in r.stdout
    r = run("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"hpcosim {hp_model.__version__}"
    r = run("model", "check", "--help")
    assert r.returncode == 0 and "--subject" in r.stdout


def test_model_check_passes_on_defaults():
    r = run("model", "check")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "standing on prosthesis" in r.stdout and "NO" not in r.stdout


def test_bad_subject_is_a_one_line_error(tmp_path):
    bad = tmp_path / "subject.toml"
    bad.write_text(hp_model.default_subject_path().read_text().replace(
        "body_mass = 60.0", "body_mass = -1.0"))
    r = run("model", "check", "--subject", str(bad))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "body_mass" in lines[0] and str(bad) in lines[0]
    assert "Traceback" not in r.stderr


def test_missing_file_is_a_one_line_error(tmp_path):
    r = run("model", "check", "--device", str(tmp_path / "nope.toml"))
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "nope.toml" in r.stderr


def _verbs(group, prefix=()):
    """Every command path of a typer group (nested groups included)."""
    for name, cmd in group.commands.items():
        path = (*prefix, name)
        if getattr(cmd, "commands", None):
            yield from _verbs(cmd, path)
        else:
            yield path


def readme_verbs(text: str) -> list[tuple[str, ...]]:
    """The verbs of README's command-line table (rows starting ``| `hpcosim VERB` |``)."""
    import re

    rows = re.findall(r"^\| `hpcosim ([a-z][a-z -]*)` \|", text, flags=re.MULTILINE)
    return [tuple(r.split()) for r in rows]


def test_every_verb_answers_help_and_is_in_the_readme_table(capsys):
    """Each command of ``hpcosim`` (walked from the app itself, not a hand list) prints its
    help with exit 0, and README's verb table lists exactly the app's verbs, each once."""
    from pathlib import Path

    import typer.main

    from orchestrator.cli import app, main

    verbs = sorted(_verbs(typer.main.get_group(app)))
    assert len(verbs) >= 17, verbs
    for v in verbs:
        assert main([*v, "--help"]) == 0, v
        out = capsys.readouterr().out
        assert "Usage" in out, v
    table = readme_verbs((Path(__file__).resolve().parents[1] / "README.md").read_text())
    assert len(table) == len(set(table)), f"README lists a verb twice: {table}"
    assert set(table) == set(verbs), (
        f"README's table lacks {sorted(set(verbs) - set(table))}, "
        f"lists unknown {sorted(set(table) - set(verbs))}")


def test_readme_verbs_parses_the_table():
    text = "| verb | what |\n|---|---|\n| `hpcosim tube fit` | x |\n| `hpcosim demo` | y |\n" \
           "see `hpcosim run` here\n"
    assert readme_verbs(text) == [("tube", "fit"), ("demo",)]
