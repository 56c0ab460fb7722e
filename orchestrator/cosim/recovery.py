"""Recovery of a recording cut short (``hpcosim recording recover``): a killed run leaves its
MCAP as ``.<name>.part``; every completely written record of it is copied into a complete
file."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

from mcap.records import Attachment, Channel, DataEnd, Footer, Message, Metadata, Schema

from orchestrator.cosim.recording import RecordingError


def recovered_name(part: Path) -> Path:
    """``.<name>.part`` -> ``<name>`` next to it (other names: ``<name>.recovered.mcap``)."""
    n = part.name
    if n.startswith(".") and n.endswith(".part"):
        return part.with_name(n[1:-len(".part")])
    return part.with_name(f"{part.stem}.recovered.mcap")


class _Copier:
    """Copies the records of an MCAP stream into writer ``w`` (schema and channel ids
    renumbered), counting the messages per topic in ``counts``."""

    def __init__(self, w: Any, counts: dict[str, int]) -> None:
        self.w, self.counts = w, counts
        self.schemas: dict[int, int] = {}
        self.channels: dict[int, tuple[int, str]] = {}

    def copy(self, r: Any) -> bool:
        """Copy one record (a message of an unknown channel is left out); True at the end
        of the data (DataEnd, Footer)."""
        w = self.w
        if isinstance(r, Schema):
            self.schemas[r.id] = w.register_schema(r.name, r.encoding, r.data)
        elif isinstance(r, Channel):
            cid = w.register_channel(r.topic, r.message_encoding,
                                     self.schemas.get(r.schema_id, 0), dict(r.metadata))
            self.channels[r.id] = (cid, r.topic)
        elif isinstance(r, Message) and r.channel_id in self.channels:
            cid, topic = self.channels[r.channel_id]
            w.add_message(cid, r.log_time, r.data, r.publish_time, r.sequence)
            self.counts[topic] = self.counts.get(topic, 0) + 1
        elif isinstance(r, Attachment):
            w.add_attachment(r.create_time, r.log_time, r.name, r.media_type, r.data)
        elif isinstance(r, Metadata):
            w.add_metadata(r.name, dict(r.metadata))
        return isinstance(r, (DataEnd, Footer))


def recover(part: str | Path, out: str | Path | None = None) -> dict[str, Any]:
    """Restore what a killed run's ``.part`` recording holds: every record of every chunk
    that was completely written (schemas, channels, messages, attachments, metadata), read
    sequentially up to the first incomplete or corrupt record, into a complete MCAP file
    ``out`` (default :func:`recovered_name`; never overwritten, written atomically).
    Returns the counts per topic and whether the input was complete."""
    from mcap.exceptions import McapError
    from mcap.stream_reader import StreamReader
    from mcap.writer import CompressionType, Writer

    from hp_model.atomic_io import atomic_write_with

    part = Path(part)
    if not part.is_file():
        raise FileNotFoundError(f"{part}: no such file")
    out = Path(out) if out is not None else recovered_name(part)
    if out.exists():
        raise RecordingError(f"{out}: exists (pass another --out)")
    counts: dict[str, int] = {}
    state: dict[str, Any] = {"complete": False, "stopped": ""}

    def write(tmp: str) -> None:
        with open(part, "rb") as f, open(tmp, "wb") as g:
            w = Writer(g, compression=CompressionType.ZSTD)
            w.start(profile="", library="hpcosim recover")
            copier = _Copier(w, counts)
            try:
                for r in StreamReader(f, validate_crcs=True).records:
                    if copier.copy(r):
                        state["complete"] = True
                        break
            except (McapError, EOFError, ValueError, OSError, struct.error) as e:
                state["stopped"] = f"{type(e).__name__}: {e}"
            if not counts:
                raise RecordingError(f"{part}: no complete chunk to recover "
                                     f"({state['stopped'] or 'no messages'})")
            w.add_metadata("recovered", {"from": str(part), "complete_input": str(
                state["complete"]).lower(), "stopped_at": state["stopped"] or "end"})
            w.finish()

    atomic_write_with(out, write, suffix=".mcap")
    return {"out": str(out), "messages": sum(counts.values()), "topics": counts,
            "complete_input": state["complete"], "stopped_at": state["stopped"] or None}
