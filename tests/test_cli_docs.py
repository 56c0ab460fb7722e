"""docs/cli.md covers every verb of ``hpcosim`` (walked from the app, not a hand list): under
the verb's heading its synopsis and options exactly as the CLI generates them, every option
of it by name, its exit-1 condition, and a worked example that the CLI's own parser accepts;
the README's verb table states the same exit-1 condition."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from orchestrator.cli.outcome import NEGATIVE_WHEN
from orchestrator.cli.synopsis import documented, heading, reference, rewrite, section, verbs

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "cli.md").read_text()
VERBS = dict(verbs())
REGENERATE = "python -m orchestrator.cli.synopsis --write docs/cli.md"


def test_every_verb_has_a_section_and_no_section_is_of_an_unknown_verb():
    headed = re.findall(r"^### `hpcosim ([a-z -]+)`$", DOC, flags=re.M)
    assert len(headed) == len(set(headed)), headed
    assert {tuple(h.split()) for h in headed} == set(VERBS)
    assert len(VERBS) >= 20


@pytest.mark.parametrize("path", sorted(VERBS), ids=" ".join)
def test_synopsis_and_options_are_the_clis(path):
    assert documented(DOC, path) == reference(path, VERBS[path]), (
        f"docs/cli.md's block of `hpcosim {' '.join(path)}` differs from the CLI: "
        f"{REGENERATE}")


@pytest.mark.parametrize("path", sorted(VERBS), ids=" ".join)
def test_every_option_is_named_under_its_verb(path):
    text = section(DOC, path)
    assert text is not None
    for p in VERBS[path].params:
        if p.param_type_name == "option" and p.opts[0] != "--help":
            assert re.search(rf"(?<![\w-]){re.escape(p.opts[0])}(?![\w-])", text), (
                path, p.opts[0])
    assert "exit 1: " in text


def _examples(text: str, path: tuple[str, ...]) -> list[list[str]]:
    """The command lines of ``hpcosim VERB`` in the section's ``sh`` blocks (comments cut)."""
    out = []
    for block in re.findall(r"^```sh\n(.*?)^```$", text, flags=re.S | re.M):
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            if words[:1 + len(path)] == ["hpcosim", *path]:
                out.append(words[1 + len(path):])
    return out


@pytest.mark.parametrize("path", sorted(VERBS), ids=" ".join)
def test_a_worked_example_the_cli_accepts(path):
    """Each example parses with the verb's own parser (options, types, ranges, choices,
    required arguments); nothing runs."""
    cmd = VERBS[path]
    examples = _examples(section(DOC, path) or "", path)
    assert examples, f"no worked example of `hpcosim {' '.join(path)}` in docs/cli.md"
    for args in examples:
        ctx = cmd.make_context(" ".join(path), list(args))
        assert ctx.params is not None


def test_rewrite_is_idempotent_and_names_a_missing_verb():
    assert rewrite(DOC) == (DOC, [])
    cut = DOC.replace(heading(("replay",)), "### replay")
    assert rewrite(cut)[1] == ["replay"]


def test_readme_table_states_each_verbs_exit_1_condition():
    rows = re.findall(r"^\| `hpcosim ([a-z -]+)` \| .*? \| (.*) \|$",
                      (ROOT / "README.md").read_text(), flags=re.M)
    assert {tuple(v.split()): w for v, w in rows} == NEGATIVE_WHEN


def test_no_option_is_named_that_the_verbs_do_not_have():
    """docs/cli.md names no option of a verb that the CLI lacks (``--quick`` is the demo's
    only: experiments has --no-eigen)."""
    for path, cmd in VERBS.items():
        text = section(DOC, path) or ""
        known = {o for p in cmd.params for o in (*p.opts, *p.secondary_opts)}
        for ex in _examples(text, path):
            assert {w.split("=")[0] for w in ex if w.startswith("--")} <= known, (path, ex)
    assert "--quick" not in (section(DOC, ("experiments",)) or "")
