"""Echo node for the cross-process ZenohBus test (run as a separate OS process).

    python tests/bus_echo_node.py <run_id> <connect endpoint> [max_frames]

Opens a ``ctrl`` ZenohBus connected to the endpoint, prints ``ready``, then sends every
received frame back (same id and data, ``is_rx`` cleared) until it receives id 0x7FF or
``max_frames`` frames, then prints ``done <n>`` and shuts the bus down.
"""

from __future__ import annotations

import sys

import can

from bus_schemas.transport.zenoh_can import ZenohBus


def main() -> int:
    run_id, endpoint = sys.argv[1], sys.argv[2]
    limit = int(sys.argv[3]) if len(sys.argv) > 3 else 1_000_000
    bus = ZenohBus(f"{run_id}/ctrl", connect=endpoint)
    n = 0
    try:
        ok = bus.wait_for_peer(10.0)
        print("ready" if ok else "no-peer", flush=True)
        while n < limit:
            msg = bus.recv(timeout=10.0)
            if msg is None:
                break
            if msg.arbitration_id == 0x7FF:
                break
            bus.send(can.Message(timestamp=msg.timestamp, arbitration_id=msg.arbitration_id,
                                 is_extended_id=msg.is_extended_id, data=msg.data))
            n += 1
    finally:
        bus.shutdown()
    print(f"done {n}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
