"""Each verb's synopsis, options and exit-1 condition, generated from the ``hpcosim`` app.

docs/cli.md holds one ``text`` block per verb, the first fenced block under the verb's
heading (``### `hpcosim VERB` ``); tests/test_cli_docs.py checks each against
:func:`reference`, and ``python -m orchestrator.cli.synopsis --write docs/cli.md`` rewrites
them (a verb without a heading is named, not added: its prose and example are the author's).
"""

from __future__ import annotations

import re
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path
from typing import Any

WIDTH = 96  # characters of a generated line
NAME_COLUMN = 28  # width of the option column
NBSP = "\u00a0"  # not a place to wrap (textwrap breaks at ASCII whitespace only)

#: the help record's value types, as a synopsis names them
METAVARS = {"int range": "N", "int": "N", "float range": "X", "float": "X", "str": "TEXT",
            "file": "FILE", "dir": "DIR", "path": "PATH", "list[str]": "TEXT"}


def command_tree() -> Any:
    """The click command of the ``hpcosim`` app."""
    import typer.main

    from orchestrator.cli import app

    return typer.main.get_command(app)


def verbs(group: Any = None, prefix: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...],
                                                                           Any]]:
    """(verb path, click command) of every verb of ``group`` (default: ``hpcosim``)."""
    group = command_tree() if group is None else group
    for name, cmd in sorted(group.commands.items()):
        if getattr(cmd, "commands", None):
            yield from verbs(cmd, (*prefix, name))
        else:
            yield (*prefix, name), cmd


def _metavar(kind: str) -> str:
    return METAVARS.get(kind, kind)


def _record(cmd: Any, param: Any) -> tuple[str, str]:
    """(name as the synopsis writes it, help) of one parameter."""
    ctx = cmd.context_class(cmd, info_name=cmd.name)
    rec = param.get_help_record(ctx)
    if rec is None:
        return "", ""
    name, help_ = rec
    help_ = " ".join(help_.split())
    m = re.fullmatch(r"(.*?) <(.+)>", name)
    if m:
        head, kind = m.groups()
        if "|" in kind and len(kind) > 24:  # a long closed set: its name, its words in the help
            words = kind.split("|")
            if not all(w in help_ for w in words):
                help_ += f" (one of {', '.join(words)})"
            kind = param.name.upper()
        if param.param_type_name == "argument":
            name = head.upper() if head == head.lower() else head
        else:
            name = f"{head} {_metavar(kind)}"
    return name.replace(" / ", "/"), help_


def synopsis(path: tuple[str, ...], cmd: Any) -> str:
    """``hpcosim VERB ARGS [--option X] ...``, wrapped at :data:`WIDTH`."""
    words = ["hpcosim", *path]
    for p in cmd.params:
        name, _ = _record(cmd, p)
        if not name or name == "--help":
            continue
        words.append(name if p.required else f"[{name}]")
    # an option and its value stay on one line: wrapped at the spaces between words only
    text = textwrap.fill(" ".join(w.replace(" ", NBSP) for w in words), WIDTH,
                         subsequent_indent="    ", break_long_words=False,
                         break_on_hyphens=False)
    return text.replace(NBSP, " ")


def options(cmd: Any) -> list[str]:
    """One entry per argument and option (not --help): name, then its help and default."""
    lines: list[str] = []
    for p in cmd.params:
        name, help_ = _record(cmd, p)
        if not name or name == "--help":
            continue
        first = f"  {name:<{NAME_COLUMN - 2}}"
        if len(first) > NAME_COLUMN:
            lines.append(f"  {name}")
            first = " " * NAME_COLUMN
        lines += textwrap.wrap(help_, WIDTH, initial_indent=first,
                               subsequent_indent=" " * NAME_COLUMN,
                               break_on_hyphens=False) or [first.rstrip()]
    return lines


def reference(path: tuple[str, ...], cmd: Any) -> str:
    """The generated block of a verb: synopsis, blank line, options, exit-1 condition."""
    from orchestrator.cli.outcome import NEGATIVE_WHEN

    when = NEGATIVE_WHEN.get(path, "(not stated: add the verb to outcome.NEGATIVE_WHEN)")
    when = when.replace("`", "").replace(" - ", f"{NBSP}-{NBSP}")
    return "\n".join([synopsis(path, cmd), "", *options(cmd), "",
                      *(x.replace(NBSP, " ") for x in textwrap.wrap(
                          "exit 1: " + when, WIDTH, subsequent_indent="    "))])


def heading(path: tuple[str, ...]) -> str:
    return f"### `hpcosim {' '.join(path)}`"


def section(doc: str, path: tuple[str, ...]) -> str | None:
    """The text under the verb's heading up to the next heading of level 2 or 3 (None if
    the document has no such heading)."""
    h = heading(path)
    lines = doc.splitlines()
    if h not in lines:
        return None
    i = lines.index(h) + 1
    j = next((k for k in range(i, len(lines)) if re.match(r"#{2,3} ", lines[k])), len(lines))
    return "\n".join(lines[i:j])


FENCE = re.compile(r"^```text\n(.*?)^```$", re.S | re.M)


def _block(doc: str, path: tuple[str, ...]) -> re.Match[str] | None:
    """The verb's ``text`` block in ``doc`` (positions in ``doc``), None without one."""
    s = section(doc, path)
    if s is None:
        return None
    start = doc.index(heading(path) + "\n")
    return FENCE.search(doc, start, start + len(heading(path)) + 1 + len(s))


def documented(doc: str, path: tuple[str, ...]) -> str | None:
    """The verb's generated block as docs/cli.md has it (None: no heading or no block)."""
    m = _block(doc, path)
    return m.group(1).rstrip("\n") if m else None


def rewrite(doc: str) -> tuple[str, list[str]]:
    """``doc`` with every verb's block regenerated; the verbs it has no block for."""
    missing = []
    for path, cmd in verbs():
        m = _block(doc, path)
        if m is None:
            missing.append(" ".join(path))
            continue
        doc = doc[:m.start(1)] + reference(path, cmd) + "\n" + doc[m.end(1):]
    return doc, missing


def main(argv: list[str] | None = None) -> int:
    """``--write FILE``: regenerate the blocks of FILE; else print every verb's block."""
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--write"] and len(argv) == 2:
        from hp_model.atomic_io import atomic_write_text

        f = Path(argv[1])
        doc, missing = rewrite(f.read_text())
        atomic_write_text(f, doc)
        for m in missing:
            print(f"{f}: no block for `hpcosim {m}`: add a heading "
                  f"'{heading(tuple(m.split()))}' and an empty ```text block", file=sys.stderr)
        return 1 if missing else 0
    for path, cmd in verbs():
        print(f"{heading(path)}\n\n```text\n{reference(path, cmd)}\n```\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
