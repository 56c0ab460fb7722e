"""Command-line options shared by the ``hpcosim`` verbs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

SubjectOpt = Annotated[Path | None, typer.Option(
    "--subject", help="Subject TOML (default: the shipped example subject).", dir_okay=False)]
DeviceOpt = Annotated[Path | None, typer.Option(
    "--device", help="Device TOML (default: AMPRO3 + iWalk estimates).", dir_okay=False)]
