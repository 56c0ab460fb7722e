"""Command-line options shared by the ``hpcosim`` verbs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

SubjectOpt = Annotated[Path | None, typer.Option(
    "--subject", help="Subject TOML, or a steps/gait file holding one (default: the subject "
    "stored in the steps or gait file the verb reads, else the shipped example subject).",
    dir_okay=False)]
DeviceOpt = Annotated[Path | None, typer.Option(
    "--device", help="Device TOML (default: AMPRO3 + iWalk estimates).", dir_okay=False)]


def check_output_file(out: Path, option: str = "--out") -> None:
    """Before any long work: the folder of the file ``out`` exists and can be written into
    (one-line errors naming it; the write itself stays atomic and may still fail, e.g. on a
    full disk)."""
    if not out.parent.is_dir():
        raise FileNotFoundError(f"{out.parent}: no such folder for {option}")
    check_output_folder(out.parent, option)


def check_output_folder(out: Path, option: str = "--out") -> None:
    """Before any long work: the folder ``out`` can be created (or written into), checked
    by making and removing a temporary folder in its nearest existing ancestor; nothing is
    left behind.  One-line errors naming ``out``."""
    import tempfile

    a = out
    while not a.exists() and a != a.parent:
        a = a.parent
    if not a.is_dir():
        raise NotADirectoryError(f"{out}: {a} is not a folder (for {option})")
    try:
        tempfile.TemporaryDirectory(dir=a).cleanup()
    except OSError as e:
        raise PermissionError(f"{out}: cannot write there for {option} ({a}: "
                              f"{e.strerror or e})") from None
