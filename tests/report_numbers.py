"""Numbers in a rendered report that carry more digits than their meaning (issue 40).

The budget of decimals per unit: frames as integers or 0.1 frame, angles 0.1 deg, lengths
0.1 mm (3 decimals in m), times 1 ms (3 decimals in s), speeds 0.01 m/s, rates 0.001 Hz; a
number with no unit (a lab direction, a ratio) at most 3 decimals.  In a Markdown table a
number takes its column's unit, from the header ("residual (mm RMS)", "time (s)", the lab
events' "max abs" / "median abs" frames); in a line that declares its unit before a colon
("calibration (pitch offsets subtracted, deg): hat +4.4, ...") its numbers take that unit.
"""

from __future__ import annotations

import re

#: decimals allowed per unit
BUDGET = {"frame": 1, "frames": 1, "deg": 1, "mm": 1, "m": 3, "s": 3, "m/s": 2, "Hz": 3}
UNITLESS = 3
#: a decimal number, and the unit word right after it if any
_NUMBER = re.compile(r"(?<![\w.])([-+]?\d+\.(\d+))(?:\s*(m/s|mm|deg|frames?|Hz|s|m)(?![\w/]))?")
_HEADER_UNIT = re.compile(r"\((m/s|mm|deg|frames?|Hz|s|m)\b")
_LINE_UNIT = re.compile(r"\b(m/s|mm|deg|frames?|Hz|s|m)\):")


def _column_units(header: str) -> list[str | None]:
    cells = [c.strip() for c in header.strip().strip("|").split("|")]
    units: list[str | None] = []
    for c in cells:
        m = _HEADER_UNIT.search(c)
        units.append(m.group(1) if m else "frames" if c in ("max abs", "median abs") else None)
    return units


def _excess(text: str, unit: str | None) -> list[str]:
    out = []
    for m in _NUMBER.finditer(text):
        u = m.group(3) or unit
        if len(m.group(2)) > BUDGET.get(u or "", UNITLESS):
            out.append(f"{m.group(0)!r} (unit {u or 'none'})")
    return out


def digits_beyond_meaning(markdown: str) -> list[str]:
    """Every number of the report with more decimals than its unit's budget, with its
    line; [] when every number is rounded to its meaning."""
    bad: list[str] = []
    units: list[str | None] = []
    for line in markdown.splitlines():
        if not line.startswith("|"):
            units = []
            declared = _LINE_UNIT.search(line)
            bad += [f"{b} in {line!r}"
                    for b in _excess(line, declared.group(1) if declared else None)]
            continue
        if not units:  # a table's header
            units = _column_units(line)
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        for cell, unit in zip(cells, units, strict=False):
            bad += [f"{b} in {line!r}" for b in _excess(cell, unit)]
    return bad
