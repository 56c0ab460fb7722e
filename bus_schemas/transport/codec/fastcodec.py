"""Per-frame encode and decode functions generated once from the DBC's layouts.

:func:`bus_schemas.transport.protocol.frame_specs` gives each frame's signal layout (start bit,
length, sign, scale, offset, range) as read from ``ampro3.dbc``; this module writes, for
each frame, a straight-line Python function from it (every shift, mask, sign fix, scale
and CRC-table step unrolled, the constants as literals) and compiles it once per process.
The generated code does what a loop over the layout does, in the same order with the same
constants (so the same bytes and floats, bit for bit: the encoders tested against
cantools, the decoders against cantools and the layout loop of
:func:`bus_schemas.transport.codec.decode_signals`), without the loop and the per-signal tuple
unpacking.

- ``encoder(spec)(values, counter) -> bytes``: the 8 data bytes (clamped, rounded half to
  even, counter and checksum filled in); NaN raises ``ValueError``.
- ``decoder(spec, ...)(data, ts) -> Verdict``: checksum check and the typed payload of 8
  data bytes (the caller has checked id and length).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from bus_schemas.transport.crc8 import TABLE, XOROUT
from bus_schemas.transport.protocol import FrameSpec


def _lit(x: Any, consts: dict[str, Any]) -> str:
    """``x`` as a literal in generated code (a named constant when it has none)."""
    if isinstance(x, int | float) and not isinstance(x, bool) and (
            isinstance(x, int) or math.isfinite(x)):
        return repr(x)
    name = f"K{len(consts)}"
    consts[name] = x
    return name


def _crc_lines(spec: FrameSpec, src: str) -> list[str]:
    """Lines leaving the final checksum of ``src[0:7]`` in ``c``."""
    lines = [f"    c = T[{spec.crc_state} ^ {src}[0]]"]
    lines += [f"    c = T[c ^ {src}[{i}]]" for i in range(1, 7)]
    return [*lines, f"    c ^= {XOROUT}"]


def encoder(spec: FrameSpec) -> Callable[[Any, int | None], bytes]:
    """The 8 data bytes of ``values`` (payload order) and ``counter`` for ``spec``: each
    value clamped to [min, max] (NaN raises), rounded half to even as cantools does,
    masked and shifted; then counter and checksum for a protected frame."""
    consts: dict[str, Any] = {}
    lines = ["def enc(values, counter):"]
    terms = []
    for i, (start, mask, lo, hi, scale, offset, linear) in enumerate(spec.enc_plan):
        v = f"v{i}"
        lines += [f"    {v} = float(values[{i}])",
                  f"    if {v} != {v}:",
                  f"        raise NAN({i})",
                  f"    {v} = {_lit(lo, consts)} if {v} < {_lit(lo, consts)} else "
                  f"{_lit(hi, consts)} if {v} > {_lit(hi, consts)} else {v}"]
        raw = (f"round(({v} - {_lit(offset, consts)}) / {_lit(scale, consts)})" if linear
               else f"round({v})")
        terms.append(f"(({raw} & {mask}) << {start})" if start else f"({raw} & {mask})")
    lines.append(f"    w = {' | '.join(terms) or '0'}")
    if not spec.protected:
        lines.append("    return w.to_bytes(8, 'little')")
    else:
        lines += ["    if counter is None:",
                  "        raise NOCOUNTER()",
                  "    w |= (int(counter) & 15) << 48",
                  "    b = w.to_bytes(7, 'little')",
                  *_crc_lines(spec, "b"),
                  "    return (w | c << 56).to_bytes(8, 'little')"]

    def nan(i: int) -> ValueError:
        return ValueError(f"{spec.name}.{spec.payload[i].name}: NaN cannot be encoded")

    def no_counter() -> ValueError:
        return ValueError(f"{spec.name} is protected: a rolling counter is required")

    env = {"T": TABLE, "NAN": nan, "NOCOUNTER": no_counter, **consts}
    exec(compile("\n".join(lines), f"<encoder {spec.name}>", "exec"), env)
    return env["enc"]


def decoder(spec: FrameSpec, verdict: type, payload: type, ok: Any, bad_checksum: Any,
            fix: Callable[[list[Any]], None] | None = None
            ) -> Callable[[bytes | bytearray, float], Any]:
    """Checksum check and typed payload of 8 data bytes of ``spec``'s frame: a ``verdict``
    (:class:`bus_schemas.transport.codec.Verdict`) with status ``ok`` and ``payload(*values)``, or
    ``bad_checksum``. ``fix`` edits the value list in place before the payload is built
    (enum members)."""
    consts: dict[str, Any] = {}
    lines = ["def dec(data, ts):"]
    counter = "None"
    if spec.protected:
        lines += [*_crc_lines(spec, "data"),
                  "    if c != data[7]:",
                  f"        return V(BAD, {spec.frame_id}, {spec.name!r}, timestamp=ts, "
                  "detail=f'checksum {data[7]:#04x}, expected {c:#04x}')"]
        counter = "data[6] & 15"
    lines.append("    w = int.from_bytes(data, 'little')")
    vals = []
    for i, (start, mask, sign, full, scale, offset, linear) in enumerate(spec.dec_plan):
        r = f"r{i}"
        lines.append(f"    {r} = (w >> {start}) & {mask}" if start else f"    {r} = w & {mask}")
        if sign:
            lines += [f"    if {r} & {sign}:", f"        {r} -= {full}"]
        vals.append(f"{r} * {_lit(scale, consts)} + {_lit(offset, consts)}" if linear
                    else r)
    if fix is None:
        lines.append(f"    return V(OK, {spec.frame_id}, {spec.name!r}, {counter}, "
                     f"P({', '.join(vals)}{',' if len(vals) == 1 else ''}), ts)")
    else:
        lines += [f"    vals = [{', '.join(vals)}]", "    FIX(vals)",
                  f"    return V(OK, {spec.frame_id}, {spec.name!r}, {counter}, P(*vals), ts)"]
    env = {"T": TABLE, "V": verdict, "P": payload, "OK": ok, "BAD": bad_checksum,
           "FIX": fix, **consts}
    exec(compile("\n".join(lines), f"<decoder {spec.name}>", "exec"), env)
    return env["dec"]
