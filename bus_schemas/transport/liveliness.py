"""Liveliness: a bus that tells whether the node at its other end is there.

A node says it is alive (:meth:`Liveliness.announce_alive`) once it is ready, and watches
its peer (:meth:`Liveliness.watch_peer`) to leave when the peer goes away. CAN over zenoh
has it (:class:`~bus_schemas.transport.zenoh_can.ZenohBus`: zenoh liveliness tokens
``hpcosim/run/<run_id>/<plant|ctrl>/alive``); a plain CAN bus (python-can's ``virtual``,
``socketcan``) has not, and :func:`liveliness` gives None for it. This module loads no
transport: the controller node asks it of whatever bus its config opened.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable


class PeerEvents(Protocol):
    """The peer's liveliness, watched: its changes since the last :meth:`poll`."""

    def poll(self) -> list[bool]:
        """The changes since the last call (True: alive, False: gone), oldest first."""
        ...

    def close(self) -> None:
        """Stop watching."""
        ...


@runtime_checkable
class Liveliness(Protocol):
    """A bus whose node can say it is alive and watch whether its peer is."""

    def announce_alive(self) -> None:
        """Declare this node alive now (idempotent)."""
        ...

    def watch_peer(self) -> PeerEvents:
        """Watch the peer node's liveliness (its current state first)."""
        ...


def liveliness(bus: Any) -> Liveliness | None:
    """``bus`` as a :class:`Liveliness`, or None for a bus without liveliness."""
    return bus if isinstance(bus, Liveliness) else None
