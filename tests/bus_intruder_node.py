"""An intruder for the authentication test (run as a separate OS process).

    python tests/bus_intruder_node.py <run_id> <endpoint> <seconds>

(until a line on stdin, at most ``seconds``)

Joins the run's CAN-over-zenoh link without its secret, as the controller would (liveliness
token, torque frames at the device limit with a running counter every 0.5 ms) and listens
for the plant's frames; prints ``ready`` once its session is open, and at the end
``sent <n> received <m>``.
"""

from __future__ import annotations

import select
import sys
import time

from bus_schemas.transport import codec
from bus_schemas.transport.zenoh_can import ZenohBus


def main() -> int:
    run_id, endpoint, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
    bus = ZenohBus(f"{run_id}/ctrl", connect=endpoint)
    print("ready", flush=True)
    sent = received = 0
    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end and not select.select([sys.stdin], [], [], 0)[0]:
            bus.send(codec.encode_torque(2.4, -3.0, sent % 16))
            sent += 1
            while bus.recv(0.0) is not None:
                received += 1
            time.sleep(0.0005)
    finally:
        bus.shutdown()
    print(f"sent {sent} received {received}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
