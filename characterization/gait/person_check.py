"""Is a fitted gait the person's gait?  Issue 37 point 4, as pure functions over plain data.

Both sides are a :class:`WalkSummary`: the take's (from its foot events or force plates,
markers and joint angles) and the gait's (from the optimized cycle).  :func:`check_person`
compares them criterion by criterion (:data:`LIMITS`, docs/person-check.md):

* mean walking speed and stride time within 10 % of the take's;
* each double support within 30 ms of the take's (the same index on both sides, in the
  order the summary gives them, e.g. after the human foot's touchdown, then the prosthesis
  foot's);
* each joint angle within 3 deg RMS of the take's over the normalized cycle;
* per foot with plates on the take side: the vertical force's correlation over the
  normalized stance >= 0.9 and its two peaks within 15 % of body weight;
* the gait's own ground forces: the centre of pressure moving heel to toe inside the sole
  with a margin (where the foot is flat, away from its handovers to the heel or toe point),
  and the required friction max |F_x| / F_z (F_z > 10 % BW) <= 0.35; where the take has no
  plates for a foot, the gait's vertical force peaks and whether they make a double hump
  (:func:`hump`) are shown, not judged.

A criterion that cannot be evaluated (a quantity missing on one side) is a row with
``passed = None``: shown, not failed, except the gait's own ground-force rows, which fail
when the gait has no ground forces (the gait must carry them).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from characterization.mocap.force_plates import LOADED_BW, double_hump, required_friction


@dataclass(frozen=True)
class Limits:
    """The criteria's bounds (issue 37 point 4)."""

    speed_rel: float = 0.10  # of the take's mean speed
    stride_rel: float = 0.10  # of the take's stride time
    double_support_s: float = 0.030  # s
    joint_rms_deg: float = 3.0  # deg
    grf_corr: float = 0.9  # Pearson correlation of F_z over the normalized stance
    grf_peak_bw: float = 0.15  # of body weight
    cop_margin_m: float = 0.01  # m inside each end of the sole
    cop_travel: float = 0.5  # of the sole's length, heel to toe at least
    friction: float = 0.35  # max |F_x| / F_z


LIMITS = Limits()


def _ro(a: Any) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class StanceForce:
    """One foot's ground reaction over its stance, uniformly sampled on 0..1 of the stance:
    ``fx`` forward, ``fz`` up (N, the ground on the foot, sagittal frame); ``cop_x`` m along
    x in the foot's sole coordinates (NaN where unloaded; optional on the take side);
    ``sole`` (heel end, toe end) m in the same coordinates, for the gait's CoP check;
    ``pivot`` True where the foot turns about its heel or toe point (a multi-contact gait's
    heel strike and push-off: its centre of pressure is that point, on the sole's end by
    design, so the margin applies where the foot is flat) and where it hands over to one."""

    fx: np.ndarray
    fz: np.ndarray
    cop_x: np.ndarray | None = None
    sole: tuple[float, float] | None = None
    pivot: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "fx", _ro(self.fx))
        object.__setattr__(self, "fz", _ro(self.fz))
        if self.cop_x is not None:
            object.__setattr__(self, "cop_x", _ro(self.cop_x))


@dataclass(frozen=True)
class WalkSummary:
    """A walk, whether a take's or a gait's.  ``speed`` m/s (mean forward speed),
    ``stride_time`` s, ``double_supports`` s (each double support of a stride, in a fixed
    order), ``joint_angles`` joint -> deg over the normalized cycle (uniform samples, 0..1
    of the stride, same joint names on both sides), ``grf`` foot -> :class:`StanceForce`,
    ``body_weight`` N, ``source`` a name for the table."""

    speed: float
    stride_time: float
    double_supports: tuple[float, ...] = ()
    joint_angles: Mapping[str, np.ndarray] = field(default_factory=dict)
    grf: Mapping[str, StanceForce] = field(default_factory=dict)
    body_weight: float = float("nan")
    source: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "double_supports", tuple(float(d) for d in
                                                          self.double_supports))
        object.__setattr__(self, "joint_angles", MappingProxyType(
            {k: _ro(v) for k, v in self.joint_angles.items()}))
        object.__setattr__(self, "grf", MappingProxyType(dict(self.grf)))


@dataclass(frozen=True)
class CheckRow:
    """One criterion: its name, the take's and the gait's value, the difference against
    ``limit`` (in ``unit``), and whether it passed (None: not evaluated)."""

    criterion: str
    take: float
    gait: float
    error: float
    limit: float
    unit: str
    passed: bool | None
    note: str = ""

    def describe(self) -> str:
        """One line with the numbers, e.g. for the verdict."""
        val = f"take {self.take:.3g}, gait {self.gait:.3g}: " if np.isfinite(self.take) else \
            f"gait {self.gait:.3g}: " if np.isfinite(self.gait) else ""
        lim = f"{self.error:.3g} {self.unit} (limit {self.limit:.3g})"
        return f"{self.criterion}: {val}{lim}{'; ' + self.note if self.note else ''}"


@dataclass(frozen=True)
class PersonCheck:
    """The comparison: ``rows`` in order; ``passed`` when no row failed."""

    take_source: str
    gait_source: str
    rows: tuple[CheckRow, ...]

    @property
    def passed(self) -> bool:
        return not self.failures

    @property
    def failures(self) -> tuple[CheckRow, ...]:
        return tuple(r for r in self.rows if r.passed is False)

    def verdict(self) -> str:
        """One line: the gait is the person's, or each failing criterion with its numbers."""
        if self.passed:
            return f"the gait is the person's ({len(self.rows)} criteria)"
        return "not the person's gait: " + "; ".join(r.describe() for r in self.failures)

    def to_json(self) -> dict[str, Any]:
        """A JSON-able dict for the gait artifact (non-finite numbers as None)."""
        def num(x: float) -> float | None:
            return float(x) if np.isfinite(x) else None
        return {"take": self.take_source, "gait": self.gait_source, "passed": self.passed,
                "verdict": self.verdict(),
                "rows": [{"criterion": r.criterion, "take": num(r.take), "gait": num(r.gait),
                          "error": num(r.error), "limit": r.limit, "unit": r.unit,
                          "passed": r.passed, "note": r.note} for r in self.rows]}


#: m: the centre of pressure may pass its margin by this much (numerical: the fit holds it
#: there as a constraint, met to IPOPT's tolerance; on OpenSim's strides under 0.5 mm)
COP_TOLERANCE = 1e-3


def _rel(criterion: str, take: float, gait: float, limit: float) -> CheckRow:
    err = abs(gait - take) / abs(take) if np.isfinite(take) and take != 0 else float("nan")
    ok = bool(err <= limit) if np.isfinite(err) else None
    return CheckRow(criterion, take, gait, 100 * err, 100 * limit, "%", ok)


def _resampled(x: np.ndarray, n: int) -> np.ndarray:
    return np.interp(np.linspace(0, 1, n), np.linspace(0, 1, len(x)), x)


def _double_support_rows(take: WalkSummary, gait: WalkSummary, lim: Limits) -> list[CheckRow]:
    n = max(len(take.double_supports), len(gait.double_supports))
    out = []
    for i in range(n):
        t = take.double_supports[i] if i < len(take.double_supports) else float("nan")
        g = gait.double_supports[i] if i < len(gait.double_supports) else float("nan")
        err = abs(g - t)
        ok = bool(err <= lim.double_support_s) if np.isfinite(err) else \
            (False if np.isfinite(t) else None)
        note = "" if np.isfinite(err) else ("the gait has none" if np.isfinite(t)
                                            else "the take has none")
        out.append(CheckRow(f"double support {i + 1}", t, g, 1000 * err,
                            1000 * lim.double_support_s, "ms", ok, note))
    return out


def _joint_rows(take: WalkSummary, gait: WalkSummary, lim: Limits) -> list[CheckRow]:
    out = []
    for j in sorted(set(take.joint_angles) | set(gait.joint_angles)):
        if j not in take.joint_angles or j not in gait.joint_angles:
            out.append(CheckRow(f"{j} RMS", float("nan"), float("nan"), float("nan"),
                                lim.joint_rms_deg, "deg", None,
                                "only the " + ("take" if j in take.joint_angles else "gait")
                                + " has it"))
            continue
        t = take.joint_angles[j]
        g = _resampled(gait.joint_angles[j], len(t))
        rms = float(np.sqrt(np.mean((g - t) ** 2)))
        out.append(CheckRow(f"{j} RMS", float("nan"), float("nan"), rms, lim.joint_rms_deg,
                            "deg", bool(rms <= lim.joint_rms_deg)))
    return out


def _grf_rows(foot: str, take: WalkSummary, gait: WalkSummary, lim: Limits) -> list[CheckRow]:
    t, g = take.grf[foot], gait.grf.get(foot)
    if g is None:
        return [CheckRow(f"{foot} F_z", float("nan"), float("nan"), float("nan"),
                         lim.grf_corr, "", False, "the gait has no ground force for it")]
    tz = t.fz / take.body_weight
    gz = _resampled(g.fz / gait.body_weight, len(tz))
    with np.errstate(divide="ignore", invalid="ignore"):  # a flat force: NaN, fails
        corr = float(np.corrcoef(tz, gz)[0, 1])
    out = [CheckRow(f"{foot} F_z correlation", float("nan"), float("nan"), corr,
                    lim.grf_corr, "", bool(corr >= lim.grf_corr))]
    for name, k in (("first peak", 0), ("second peak", 2)):
        pt, pg = double_hump(tz)[k], double_hump(gz)[k]
        err = abs(pg - pt)
        out.append(CheckRow(f"{foot} F_z {name}", pt, pg, 100 * err, 100 * lim.grf_peak_bw,
                            "% BW", bool(err <= lim.grf_peak_bw)))
    return out


def cop_heel_to_toe(s: StanceForce, body_weight: float, lim: Limits = LIMITS
                    ) -> tuple[bool, float, str]:
    """(passed, travel as a fraction of the sole, why): the loaded part's centre of
    pressure inside the sole by ``cop_margin_m`` (where the foot is flat: not on a
    ``pivot``) and moving heel to toe by at least ``cop_travel`` of the sole."""
    if s.cop_x is None or s.sole is None:
        return False, float("nan"), "no centre of pressure or sole"
    heel, toe = s.sole
    length = toe - heel
    c = _resampled(s.cop_x, len(s.fz)) if len(s.cop_x) != len(s.fz) else s.cop_x
    m = (s.fz > LOADED_BW * body_weight) & np.isfinite(c)
    if not m.any():
        return False, float("nan"), "never loaded"
    flat = m if s.pivot is None else m & ~np.asarray(s.pivot, bool)
    travel = float((c[m][-1] - c[m][0]) / length)
    lo, hi = (float(c[flat].min()), float(c[flat].max())) if flat.any() else (heel + 1, toe - 1)
    why = []
    # (less than COP_TOLERANCE over the margin is the fit's own bound, met to IPOPT's tolerance)
    if lo < heel + lim.cop_margin_m - COP_TOLERANCE:
        why.append(f"behind the heel margin by {1000 * (heel + lim.cop_margin_m - lo):.0f} mm")
    if hi > toe - lim.cop_margin_m + COP_TOLERANCE:
        why.append(f"beyond the toe margin by {1000 * (hi - toe + lim.cop_margin_m):.0f} mm")
    if travel < lim.cop_travel:
        why.append(f"travels {100 * travel:.0f} % of the sole")
    return not why, travel, "; ".join(why)


#: of body weight: how far both peaks of a double hump rise above the valley between them
HUMP_BW = 0.1


def hump(fz_bw: np.ndarray) -> tuple[float, float, float, bool]:
    """(first peak, valley, second peak, a double hump?) of a vertical force over a
    normalized stance in body weights (:func:`double_hump`): a double hump when each peak
    is inside the stance (not at its ends: a force that starts or ends on its largest value
    is an impact's or a cut's) and rises :data:`HUMP_BW` above the valley."""
    p1, v, p2 = double_hump(fz_bw)
    n = len(fz_bw)
    i1, i2 = int(np.argmax(fz_bw[: n // 2])), n // 2 + int(np.argmax(fz_bw[n // 2:]))
    inside = i1 > 0 and i2 < n - 1
    return p1, v, p2, bool(inside and min(p1, p2) >= v + HUMP_BW)


def _own_force_rows(foot: str, gait: WalkSummary, lim: Limits, plates: bool
                    ) -> list[CheckRow]:
    g = gait.grf[foot]
    ok, travel, why = cop_heel_to_toe(g, gait.body_weight, lim)
    mu = required_friction(g.fx, g.fz, LOADED_BW * gait.body_weight)
    rows = []
    if not plates:  # shown, not judged: the limits are against the take's plates
        p1, v, p2, two = hump(g.fz / gait.body_weight)
        rows.append(CheckRow(
            f"{foot} F_z peaks", float("nan"), max(p1, p2), float("nan"), float("nan"),
            "BW", None, f"first {p1:.2f}, valley {v:.2f}, second {p2:.2f} BW: "
            f"{'a' if two else 'no'} double hump; the take has no force plates"))
    rows.append(CheckRow(f"{foot} CoP heel to toe", float("nan"), 100 * travel,
                         100 * travel, 100 * lim.cop_travel, "% sole", ok, why))
    rows.append(CheckRow(f"{foot} required friction", float("nan"), mu, mu, lim.friction, "",
                         bool(mu <= lim.friction) if np.isfinite(mu) else False))
    return rows


def check_person(take: WalkSummary, gait: WalkSummary, limits: Limits = LIMITS
                 ) -> PersonCheck:
    """Every criterion of the module docstring, in order."""
    rows = [_rel("mean speed", take.speed, gait.speed, limits.speed_rel),
            _rel("stride time", take.stride_time, gait.stride_time, limits.stride_rel),
            *_double_support_rows(take, gait, limits), *_joint_rows(take, gait, limits)]
    for foot in sorted(take.grf):
        rows += _grf_rows(foot, take, gait, limits)
    if not gait.grf:
        rows.append(CheckRow("ground forces", float("nan"), float("nan"), float("nan"), 0.0,
                             "", False, "the gait carries no ground forces"))
    for foot in sorted(gait.grf):
        rows += _own_force_rows(foot, gait, limits, foot in take.grf)
    return PersonCheck(take.source, gait.source, tuple(rows))


def print_check(console: Any, check: PersonCheck) -> None:
    """The comparison as a rich table on ``console`` and the one-line verdict."""
    from rich.table import Table

    table = Table(title=f"the gait against the take ({check.take_source})")
    for c in ("criterion", "take", "gait", "error", "limit", ""):
        table.add_column(c, justify="left" if c in ("criterion", "") else "right")

    def f(x: float) -> str:
        return f"{x:.3g}" if np.isfinite(x) else "-"
    for r in check.rows:
        mark = {True: "[green]ok[/]", False: "[red]FAIL[/]", None: "[dim]n/a[/]"}[r.passed]
        table.add_row(r.criterion, f(r.take), f(r.gait), f"{f(r.error)} {r.unit}".strip(),
                      f"{f(r.limit)} {r.unit}".strip(), mark + (f" {r.note}" if r.note else ""))
    console.print(table)
    console.print(("[green]" if check.passed else "[red]") + check.verdict() + "[/]")
