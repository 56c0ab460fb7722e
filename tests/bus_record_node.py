"""Recorder node for the interruption test (run as a separate OS process).

    python tests/bus_record_node.py <out.mcap> <ready_after>

Records CAN frames and ground truth every millisecond with the SIGTERM/SIGINT handlers
installed, prints ``ready`` after ``ready_after`` messages, and keeps recording until a
signal finishes the file (exit code 143 for SIGTERM, 130 for SIGINT).
"""

from __future__ import annotations

import sys
import time

from bus_schemas.recording.recorder import Recorder
from bus_schemas.transport import codec


def main() -> int:
    path, ready_after = sys.argv[1], int(sys.argv[2])
    rec = Recorder(path, metadata={"node": "bus_record_node"})
    rec.install_signal_handlers()
    rec.register_all()
    k = 0
    try:
        while True:
            t_ns = k * 1_000_000
            for m in codec.encode_feedback(0.001 * k, 0.0, 0.0, 0.0, 500.0, True, k):
                rec.write_can(m, "tx", t_ns, name=codec.decode(m).name)
            rec.write("/ground_truth", {"t": k * 1e-3, "socket_force": {"Fx": 1.0, "Fz": -700.0,
                                        "My": 0.5}, "q": [0.0] * 12, "qd": [0.0] * 12,
                                        "domain": "ps", "tau": 0.0, "step": 0,
                                        "fallen": False}, t_ns)
            k += 1
            if rec.message_count >= ready_after and k % 10 == 0:
                print("ready", flush=True)
                ready_after = 1 << 60
            time.sleep(0.0005)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
