"""``hpcosim gait library``: the person's gait fitted again over a range of walking speeds,
each fit continued from its neighbour's (:mod:`characterization.gait.library`), written as
one artifact; each speed's gait walked with the held oracle."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from rich.console import Console
from rich.table import Table

from orchestrator.cli.outcome import HOLDS, Verdict, conclude

if TYPE_CHECKING:
    from characterization.gait.contact_gait import ContactWalk


def parse_speeds(text: str) -> tuple[float, ...]:
    """``0.6,0.8,1.2`` -> the speeds (m/s); ValueError naming the bad entry."""
    out = []
    for part in text.split(","):
        try:
            out.append(float(part))
        except ValueError:
            raise ValueError(f"--speeds: {part.strip()!r} is not a speed in m/s") from None
    return tuple(out)


def _walk_cell(walk: ContactWalk) -> str:
    """A walk in a table cell: its steps and speed, or where it fell."""
    if walk.walks:
        return f"walks {walk.steps} steps, {np.median(walk.speeds):.3f} m/s"
    return f"falls after {walk.steps} steps: {walk.fall}"


def make_gait_library(steps: Path, gait: Path, out: Path, speeds: tuple[float, ...]) -> None:
    """The library of ``gait`` (fitted from ``steps``) at ``speeds``, written to ``out``;
    the verdict (every gait walks) as the exit code."""
    from characterization.gait.library import (
        LibraryOptions,
        fit_library,
        save_gait_library,
        to_document,
    )
    from characterization.gait.multicontact import targets_from_steps
    from characterization.gait.multicontact_artifact import (
        fit_options,
        load_contact_cycle,
        load_multicontact_gait,
    )
    from characterization.mocap.steps_artifact import load_steps
    from orchestrator.cli.options import check_output_file

    check_output_file(out)
    cycle = load_contact_cycle(gait)
    doc = load_multicontact_gait(gait)
    fit_opt = fit_options(doc, gait)
    targets = targets_from_steps(load_steps(steps), cycle.model, str(steps))
    options = LibraryOptions()
    console = Console(stderr=True)
    with console.status("gait library") as status:
        gaits = fit_library(cycle.model, targets, cycle, speeds, fit_opt, options,
                            progress=lambda m: status.update(m))
    save_gait_library(out, to_document(gaits, cycle, str(gait), doc["subject"], doc["device"],
                                       fit_opt, options))
    table = Table(title=f"gait library {out}")
    for col in ("speed m/s", "target", "stride s", "stride m", "IPOPT", "held oracle"):
        table.add_column(col)
    for g in gaits:
        assert g.walk is not None  # fit_library walks every gait
        table.add_row(f"{g.speed:.3f}", f"{g.target:.2f}", f"{g.stride_time:.3f}",
                      f"{g.stride_length:.3f}",
                      "the fitted gait" if g.source else
                      f"{g.solver.get('iterations')} it, {g.solver.get('seconds', 0):.0f} s",
                      _walk_cell(g.walk))
    Console().print(table)
    falls = [f"the gait at {g.speed:.2f} m/s {g.walk.line()}" for g in gaits
             if g.walk is not None and not g.walk.walks]
    conclude(HOLDS if not falls else Verdict("; ".join(falls)))
