"""The receiver's check of a frame stream: :class:`FrameChecker` classifies each frame
(ok, bad_checksum, bad_counter, bad_length, duplicate, unknown_id), follows each id's
rolling counter and counts every class (what the controller reports in ``CtrlRejects``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import can

from bus_schemas.transport.codec.decode import decode, decode_frame, decoders
from bus_schemas.transport.codec.payloads import FrameStatus, Verdict
from bus_schemas.transport.frame import Frame
from bus_schemas.transport.protocol import FRAME_LENGTH

# hot-path constants (enum attribute lookups cost more than a global)
_OK, _BAD_COUNTER, _DUPLICATE, _UNKNOWN_ID = (
    FrameStatus.OK, FrameStatus.BAD_COUNTER, FrameStatus.DUPLICATE, FrameStatus.UNKNOWN_ID)


class FrameChecker:
    """Classifies received frames (ok / bad_checksum / bad_counter / bad_length / duplicate
    / unknown_id) and counts each class.

    Checks in order: id (in the DBC, standard id, data frame, and in ``accept`` if given),
    length (classic frame, DLC and data length 8), checksum, then the rolling counter per
    frame id.  Session start: the first frame of an id must carry ``first`` (0: both sides
    start their counters there; None accepts any).  Afterwards a counter equal to the last
    accepted one is a ``duplicate``, an advance of 1..``max_gap`` is ok (the skipped frames
    are added to :attr:`lost`), anything else is ``bad_counter`` and leaves the state as it
    was, so one stray or replayed frame never invalidates the next genuine one.  The checker
    resynchronizes only when two consecutive frames agree on a new sequence (a rejected
    counter c followed by c + 1: lost frames or a sender restart), counted in
    :attr:`resyncs`.  Unprotected frames (CtrlStatus, CtrlRejects, CtrlDisturbance) have no
    counter check.
    Never raises.
    """

    def __init__(self, accept: Any = None, *, max_gap: int = 1, first: int | None = 0) -> None:
        if not 1 <= max_gap <= 14:
            raise ValueError("max_gap must be in 1..14")
        if first is not None and not 0 <= first <= 15:
            raise ValueError("first must be a counter value 0..15 or None")
        self.accept = None if accept is None else frozenset(int(i) for i in accept)
        self.max_gap = max_gap
        self.first = first
        self._last: dict[int, int] = {}
        self._candidate: dict[int, int] = {}  # the last rejected counter per id
        self._ok = 0
        self._counts = dict.fromkeys(FrameStatus, 0)  # rejections (OK counted in _ok)
        self.lost = 0
        self.resyncs = 0

    @property
    def counts(self) -> dict[FrameStatus, int]:
        """Frames seen per class (a copy)."""
        out = dict(self._counts)
        out[_OK] = self._ok
        return out

    @property
    def rejected(self) -> int:
        return sum(n for s, n in self._counts.items() if s is not _OK)

    def reset(self) -> None:
        """Forget counter state and counts (a new session: the first frame again)."""
        self._last.clear()
        self._candidate.clear()
        self._ok = 0
        self._counts = dict.fromkeys(FrameStatus, 0)
        self.lost = 0
        self.resyncs = 0

    def _counter_ok(self, fid: int, c: int) -> tuple[bool, str]:
        """Advance the counter state of ``fid`` by the counter ``c``: (ok, why not)."""
        last = self._last.get(fid)
        cand = self._candidate.get(fid)
        if last is not None:
            delta = (c - last) % 16
            if delta == 0:
                return False, "duplicate"
            if delta <= self.max_gap:
                self.lost += delta - 1
                self._last[fid] = c
                self._candidate.pop(fid, None)
                return True, ""
        elif self.first is None or c == self.first:
            self._last[fid] = c
            return True, ""
        if cand is not None and c == (cand + 1) % 16:  # two frames agree: resynchronize
            self._last[fid] = c
            self._candidate.pop(fid, None)
            self.resyncs += 1
            return True, ""
        self._candidate[fid] = c
        return False, (f"counter {c} after {last}" if last is not None
                       else f"counter {c} at the session start (expected {self.first})")

    def check_all(self, frames: Sequence[can.Message | Frame]) -> list[Verdict]:
        """:meth:`check` of each frame in order (the same verdicts, counts and state): a
        sample's frames in one loop, the common case (a well-formed Frame of an accepted
        id, in sequence) inline and anything else through :meth:`check`."""
        decs, accept, last_of, gap = decoders(), self.accept, self._last, self.max_gap
        out: list[Verdict] = []
        for m in frames:
            if type(m) is Frame:
                ts, fid, data = m
                dec = (decs.get(fid) if type(data) is bytes and type(ts) is float
                       and type(fid) is int and len(data) == FRAME_LENGTH else None)
                if dec is not None and (accept is None or fid in accept):
                    v = dec(data, ts)
                    if v.status is _OK:
                        c = v.counter
                        if c is None:
                            self._ok += 1
                            out.append(v)
                            continue
                        last = last_of.get(fid)
                        if last is not None and 0 < (c - last) % 16 <= gap:
                            self.lost += (c - last) % 16 - 1
                            last_of[fid] = c
                            if self._candidate:
                                self._candidate.pop(fid, None)
                            self._ok += 1
                            out.append(v)
                            continue
            out.append(self.check(m))
        return out

    def check(self, msg: can.Message | Frame) -> Verdict:
        v = decode_frame(msg) if type(msg) is Frame else decode(msg)
        if v.status is not _OK:
            self._counts[v.status] += 1
            return v
        fid = cast(int, v.frame_id)  # an OK verdict has its frame id
        if self.accept is not None and fid not in self.accept:
            v = Verdict(_UNKNOWN_ID, fid, v.name, timestamp=v.timestamp,
                        detail="not accepted by this receiver")
        elif v.counter is not None:
            c = v.counter
            last = self._last.get(fid)
            if last is not None and 0 < (c - last) % 16 <= self.max_gap:  # in sequence
                self.lost += (c - last) % 16 - 1
                self._last[fid] = c
                if self._candidate:
                    self._candidate.pop(fid, None)
                self._ok += 1
                return v
            ok, why = self._counter_ok(int(fid), int(c))
            if why == "duplicate":
                v = Verdict(_DUPLICATE, fid, v.name, v.counter, timestamp=v.timestamp,
                            detail=f"counter {v.counter} again")
            elif not ok:
                v = Verdict(_BAD_COUNTER, fid, v.name, v.counter, timestamp=v.timestamp,
                            detail=why)
        if v.status is _OK:
            self._ok += 1
        else:
            self._counts[v.status] += 1
        return v
