#!/usr/bin/env python3
"""Independent SYNC observer for tests/system/canopen_udp_run.rs: listens on a python-can udp_multicast
bus and records every SYNC frame (COB-ID 0x080, standard identifier) with python-can's own
timestamp (the kernel's receive time, SO_TIMESTAMPNS), not with anything the sender put in the
datagram.

    sync_listener.py GROUP PORT READY_FILE FIRST_SYNC_FILE MAX_SECONDS

Creates READY_FILE once the bus is open and FIRST_SYNC_FILE at the first SYNC. Stops when no
SYNC came for 1.5 s after the first one, or after MAX_SECONDS. Prints `key=value` lines:
count, the median / 5th / 95th percentile / min / max SYNC period in ms, the first-to-last
span in s.
"""
import statistics
import sys
import time

import can


def main():
    group, port, ready, first, max_s = sys.argv[1:6]
    bus = can.Bus(interface="udp_multicast", channel=group, port=int(port))
    open(ready, "w").close()
    stamps = []
    end = time.monotonic() + float(max_s)
    last_seen = None
    try:
        while time.monotonic() < end:
            msg = bus.recv(0.2)
            now = time.monotonic()
            if last_seen is not None and now - last_seen > 1.5:
                break
            if msg is None or msg.is_error_frame or msg.is_extended_id:
                continue
            if msg.arbitration_id == 0x080:
                stamps.append(msg.timestamp)
                last_seen = now
                if len(stamps) == 1:
                    open(first, "w").close()
    finally:
        bus.shutdown()
    periods = sorted((b - a) * 1e3 for a, b in zip(stamps, stamps[1:]))
    print(f"count={len(stamps)}")
    if len(periods) >= 2:
        q = statistics.quantiles(periods, n=20)
        print(f"median_ms={statistics.median(periods):.4f}")
        print(f"p5_ms={q[0]:.4f}")
        print(f"p95_ms={q[-1]:.4f}")
        print(f"min_ms={periods[0]:.4f}")
        print(f"max_ms={periods[-1]:.4f}")
        print(f"span_s={stamps[-1] - stamps[0]:.4f}")


if __name__ == "__main__":
    main()
