"""Why a walk ended: one enum of fall reasons, shared by the simulator, the FMU and every
report.

The integer values are the FMU's ``fall_code`` output (its C constants and messages are
generated from :class:`FallReason` by :func:`c_definitions`); a :class:`Fall` carries the
reason with the numbers of the event (time, domain, phase and the reason's own values), so
no report parses a message.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

from hp_model.domains import Domain


class FallReason(IntEnum):
    """Why the walker fell; the value is the FMU's ``fall_code`` (0: walking)."""

    NONE = 0
    NON_FINITE = 1
    HIP_LOW = 2
    PHASE_BACKWARD = 3
    NO_TOUCHDOWN = 4
    FRICTION_CONE = 5
    HEEL_OR_TOE = 6
    PHASE_STALLED = 7
    DIVERGED = 8

    @property
    def description(self) -> str:
        """One line naming the check (and its SimOptions / FMU parameter)."""
        return _DESCRIPTION[self]

    @property
    def label(self) -> str:
        """Short lower-case name for tables and counts (``hip-low``)."""
        return self.name.lower().replace("_", "-")


_DESCRIPTION = {
    FallReason.NONE: "walking (no fall)",
    FallReason.NON_FINITE: "non-finite state",
    FallReason.HIP_LOW: "hip height below min_hip_height",
    FallReason.PHASE_BACKWARD: "phase tau ran backward more than tau_backward",
    FallReason.NO_TOUCHDOWN: "no touchdown by tau_max (or late_touchdown s past the designed one)",
    FallReason.FRICTION_CONE: "stance foot left the friction cone for cone_periods periods",
    FallReason.HEEL_OR_TOE: "landed on heel or toe (touchdown pitch above max_touchdown_pitch)",
    FallReason.PHASE_STALLED: ("phase stalled: no touchdown within max_step_time of the start "
                               "or the last impact"),
    FallReason.DIVERGED: "state diverged: a generalized speed above max_speed",
}


@dataclass(frozen=True)
class Fall:
    """A fall: its reason, simulation time t (s), domain, phase tau, and the reason's numbers
    (``values``, SI units: e.g. ``hip_height`` m, ``F_x``/``F_z`` N, ``pitch`` rad)."""

    reason: FallReason
    t: float
    domain: Domain
    tau: float
    values: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "reason", FallReason(self.reason))
        object.__setattr__(self, "domain", Domain(self.domain))
        object.__setattr__(self, "values", {k: float(x) for k, x in self.values.items()})

    @property
    def code(self) -> int:
        return int(self.reason)

    def detail(self) -> str:
        """The reason with its numbers, e.g. ``hip height 0.540 m below 0.55 m``."""
        v = self.values
        r = self.reason
        try:
            if r is FallReason.HIP_LOW:
                return f"hip height {v['hip_height']:.3f} m below {v['limit']} m"
            if r is FallReason.PHASE_BACKWARD:
                return f"phase ran backward (tau {self.tau:.3f}, peak {v['tau_peak']:.3f})"
            if r is FallReason.NO_TOUCHDOWN:
                return f"no touchdown by tau = {v['limit']:.3g}"
            if r is FallReason.PHASE_STALLED:
                return f"phase stalled (no touchdown within {v['limit']:g} s)"
            if r is FallReason.FRICTION_CONE:
                return (f"stance foot left the friction cone (F_x {v['F_x']:.0f} N, "
                        f"F_z {v['F_z']:.0f} N)")
            if r is FallReason.HEEL_OR_TOE:
                return f"landed on heel or toe (foot pitch {v['pitch']:.3f} rad)"
            if r is FallReason.DIVERGED:
                return f"state diverged (a speed above {v['limit']:g} m/s or rad/s)"
        except KeyError:
            pass
        return r.description

    def message(self) -> str:
        """``t = 1.234 s, ps, tau = 0.512: <detail>`` (the run's one-line reason)."""
        return f"t = {self.t:.3f} s, {self.domain}, tau = {self.tau:.3f}: {self.detail()}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: reason label and code, t, domain, tau, values."""
        return {"reason": self.reason.label, "code": self.code, "t": float(self.t),
                "domain": self.domain, "tau": float(self.tau),
                "values": {k: float(x) for k, x in self.values.items()}}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Fall:
        return cls(FallReason(int(d["code"])), float(d["t"]), Domain(str(d["domain"])),
                   float(d["tau"]), d.get("values", {}))


class FallOutcome:
    """Mixin of a run's result with a ``fall`` (:class:`Fall` or None): ``failed`` and the
    one-line ``reason``."""

    fall: Fall | None

    @property
    def failed(self) -> bool:
        return self.fall is not None

    @property
    def reason(self) -> str:
        """The fall's one-line message ("" without a fall)."""
        return self.fall.message() if self.fall is not None else ""


def c_definitions(prefix: str = "HP_FALL_") -> str:
    """C source: one ``#define <prefix><NAME> <code>`` per reason and
    ``static const char *fall_reason(int code)`` returning the description (the FMU's
    codes and log messages, generated from :class:`FallReason`)."""
    lines = [f"#define {prefix}{r.name} {int(r)}" for r in FallReason]
    lines += ["", "static const char *fall_reason(int code) {", "    switch (code) {"]
    for r in FallReason:
        if r is not FallReason.NONE:
            text = r.description.replace("\\", "\\\\").replace('"', '\\"')
            lines.append(f'    case {prefix}{r.name}: return "{text}";')
    lines += ['    default: return "none";', "    }", "}"]
    return "\n".join(lines) + "\n"
