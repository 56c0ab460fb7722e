"""The fault plan of a co-simulation (``hpcosim run --perturb``): which fault, injected where
and when.

``--perturb`` is ``CASE[:START[:EVERY[:COUNT]]]`` for the frame and process cases,
``stall[:START[:MS]]`` for the plant's own lateness and ``human[:AMPLITUDE[:SEED]]`` for a
perturbed human gait (:class:`PerturbCase` lists them).  Frame faults act on the plant's
``KneeFeedback`` frame of ticks ``START, START + EVERY, ...`` (``COUNT`` times)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import can

from bus_schemas.transport import codec
from bus_schemas.transport.protocol import FrameId
from hp_model.choices import Choice


class PerturbCase(Choice):
    """What ``--perturb`` injects (module docstring)."""

    NONE = "none"
    DROP = "drop"  # the KneeFeedback frame not sent
    DELAY = "delay"  # sent after the cycle's SimTime: too late for it
    DUPLICATE = "duplicate"  # sent twice
    CORRUPT_COUNTER = "corrupt-counter"  # a rolling counter out of sequence
    CORRUPT_CHECKSUM = "corrupt-checksum"  # one bit of the payload flipped
    CORRUPT_LENGTH = "corrupt-length"  # 7 bytes instead of 8
    KILL = "kill"  # SIGKILL the controller process (dies, its liveliness goes)
    HANG = "hang"  # SIGSTOP it (hangs alive: only the missing replies show it)
    STALL = "stall"  # the plant loop sleeps (a page fault, a GC pause, descheduling)
    HUMAN = "human"  # the human FMU's gait perturbed (no fault on the link)

    @property
    def is_process(self) -> bool:
        """A fault of the controller process (at tick START, once)."""
        return self in (PerturbCase.KILL, PerturbCase.HANG)

    @property
    def is_plant(self) -> bool:
        """The plant's own lateness: before tick START the plant loop sleeps."""
        return self is PerturbCase.STALL

    @property
    def is_frame(self) -> bool:
        """A fault of the plant's KneeFeedback frames."""
        return self not in (PerturbCase.NONE, PerturbCase.HUMAN) and not (
            self.is_process or self.is_plant)


@dataclass
class FaultPlan:
    """Frame faults injected into the plant's KneeFeedback frames (or the controller kill):
    at ticks ``start, start + every, ...`` (``count`` times)."""

    case: PerturbCase = PerturbCase.NONE
    start: int = 100
    every: int = 97
    count: int = 5
    amplitude: float = 0.0  # rad, the human perturbation
    seed: int = 0
    stall_ms: float = 50.0  # stall: the plant's sleep [ms]

    @classmethod
    def parse(cls, text: str | None) -> FaultPlan:
        """The plan of a ``--perturb`` value; ValueError naming ``--perturb``, the cases
        and the part that is wrong (an unknown case, a number that is not one or out of
        its range, too many parts)."""
        if not text or text == PerturbCase.NONE:
            return cls()
        parts = text.split(":")
        try:
            case = PerturbCase(parts[0])
        except ValueError:
            raise _bad(text, f"unknown case {parts[0]!r}; choose one of "
                       f"{', '.join(PerturbCase)}") from None
        if case is PerturbCase.NONE:
            raise _bad(text, "'none' takes no parameters")
        if case is PerturbCase.HUMAN:
            _arity(text, parts, "human[:AMPLITUDE[:SEED]]", 2)
            amp = _number(text, parts, 1, "AMPLITUDE (rad)", 0.001, 0.0, math.inf)
            seed = _whole(text, parts, 2, "SEED", 0, 0, SEED_LIMIT - 1)
            return cls(case, amplitude=amp, seed=seed)
        if case is PerturbCase.STALL:
            _arity(text, parts, "stall[:START[:MS]]", 2)
            return cls(case, start=_whole(text, parts, 1, "START", 100, 0, None), count=1,
                       stall_ms=_number(text, parts, 2, "MS", 50.0, 0.0, math.inf, open_=True))
        _arity(text, parts, f"{case}[:START[:EVERY[:COUNT]]]", 3)
        return cls(case, start=_whole(text, parts, 1, "START", 100, 0, None),
                   every=_whole(text, parts, 2, "EVERY", 97, 1, None),
                   count=_whole(text, parts, 3, "COUNT", 5, 1, None))

    def fmu_parameters(self) -> tuple[dict[str, float], dict[str, int]]:
        """The human FMU's start values for this plan (real, integer): the perturbation's
        amplitude [rad] and seed for ``human``, none otherwise."""
        if self.case is not PerturbCase.HUMAN:
            return {}, {}
        return {"human_perturbation": self.amplitude}, {"human_seed": self.seed}

    def hits(self, k: int) -> bool:
        """Whether tick ``k`` is one of the plan's (never for ``none`` and ``human``)."""
        if self.case in (PerturbCase.NONE, PerturbCase.HUMAN) or k < self.start:
            return False
        d = k - self.start
        return d % max(1, self.every) == 0 and d // max(1, self.every) < self.count

    def process_fault_due(self, k: int) -> bool:
        """Whether the controller process is to be killed or stopped at tick ``k``."""
        return self.case.is_process and k == self.start

    def apply(self, k: int, frames: list[Any]) -> tuple[list[Any], str | None]:
        """Frames to send this tick (SimTime last unless delayed) and the fault applied."""
        if not self.case.is_frame or not self.hits(k):
            return frames, None
        knee, rest = frames[0], frames[1:]
        case = self.case
        if case is PerturbCase.DROP:
            return rest, case.value
        if case is PerturbCase.DELAY:
            return [*rest, knee], case.value  # arrives after the cycle's SimTime: too late
        if case is PerturbCase.DUPLICATE:
            return [knee, knee, *rest], case.value
        return [_corrupted(case, knee), *rest], case.value


#: the human perturbation's seed is the FMU's 32-bit signed Integer
SEED_LIMIT = 2**31


def _bad(text: str, why: str) -> ValueError:
    return ValueError(f"--perturb {text!r}: {why}")


def _arity(text: str, parts: list[str], form: str, most: int) -> None:
    """At most ``most`` parameters after the case (``form``: what it takes)."""
    if len(parts) - 1 > most:
        raise _bad(text, f"too many parts; expected {form}")


def _number(text: str, parts: list[str], i: int, name: str, default: float, low: float,
            high: float, *, open_: bool = False) -> float:
    """Part ``i`` as a finite number in [low, high] ((low, high] with ``open_``), or
    ``default`` when absent."""
    if len(parts) <= i:
        return default
    try:
        v = float(parts[i])
    except ValueError:
        raise _bad(text, f"{name} {parts[i]!r} is not a number") from None
    if not math.isfinite(v) or v < low or (open_ and v == low) or v > high:
        raise _bad(text, f"{name} {parts[i]!r}: expected a finite number "
                   f"{'>' if open_ else '>='} {low:g}")
    return v


def _whole(text: str, parts: list[str], i: int, name: str, default: int, low: int,
           high: int | None) -> int:
    """Part ``i`` as a whole number in [low, high], or ``default`` when absent."""
    if len(parts) <= i:
        return default
    try:
        v = int(parts[i])
    except ValueError:
        raise _bad(text, f"{name} {parts[i]!r} is not a whole number") from None
    if v < low or (high is not None and v > high):
        raise _bad(text, f"{name} {v}: expected a whole number >= {low}"
                   + (f" and <= {high}" if high is not None else ""))
    return v


def _corrupted(case: PerturbCase, knee: can.Message) -> can.Message:
    """The KneeFeedback frame ``knee`` corrupted as ``case`` says."""
    if case is PerturbCase.CORRUPT_COUNTER:
        v = codec.decode(knee).value
        return codec.encode_frame(FrameId.KNEE_FEEDBACK,
                                  {"KneeAngle": v.angle, "KneeVelocity": v.velocity},
                                  ((knee.data[6] & 0x0F) + 5) % 16, timestamp=knee.timestamp)
    if case is PerturbCase.CORRUPT_LENGTH:
        return can.Message(timestamp=knee.timestamp, arbitration_id=knee.arbitration_id,
                           is_extended_id=False, dlc=7, data=bytes(knee.data[:7]))
    bad = can.Message(timestamp=knee.timestamp, arbitration_id=knee.arbitration_id,
                      is_extended_id=False, dlc=8, data=bytearray(knee.data))
    bad.data[0] ^= 0x01  # corrupt-checksum
    return bad
