#!/usr/bin/env python3
"""python-can udp_multicast peer for tests/system/can_udp_interop.rs (independent implementation of the
wire format: python-can 4.6.1 + msgpack).

  can_peer.py send GROUP PORT FRAMES_JSON   send the frames, 2 ms apart, then print "SENT n"
  can_peer.py recv GROUP PORT N SECONDS     print "READY" once the bus is open, then one JSON
                                            object per received message (at most N, at most
                                            SECONDS), then "DONE n"

FRAMES_JSON: a list of {"id": int, "ext": bool, "rtr": bool, "err": bool, "len": int,
"data": "hex"}. Received messages are printed with python-can's own field names.
"""
import json
import sys
import time

import can


def open_bus(group, port):
    return can.Bus(interface="udp_multicast", channel=group, port=int(port))


def main(argv):
    mode, group, port = argv[1], argv[2], argv[3]
    if mode == "send":
        frames = json.loads(argv[4])
        with open_bus(group, port) as bus:
            for f in frames:
                msg = can.Message(
                    arbitration_id=f["id"],
                    is_extended_id=f["ext"],
                    is_remote_frame=f["rtr"],
                    is_error_frame=f["err"],
                    dlc=f["len"],
                    data=b"" if f["rtr"] else bytes.fromhex(f["data"]),
                    is_fd=False,
                    check=True,
                )
                bus.send(msg)
                time.sleep(0.002)
            print(f"SENT {len(frames)}", flush=True)
        return 0
    if mode == "recv":
        n, seconds = int(argv[4]), float(argv[5])
        got = 0
        with open_bus(group, port) as bus:
            print("READY", flush=True)
            deadline = time.monotonic() + seconds
            while got < n:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                msg = bus.recv(timeout=left)
                if msg is None:
                    continue
                got += 1
                print(
                    json.dumps(
                        {
                            "arbitration_id": msg.arbitration_id,
                            "is_extended_id": msg.is_extended_id,
                            "is_remote_frame": msg.is_remote_frame,
                            "is_error_frame": msg.is_error_frame,
                            "is_fd": msg.is_fd,
                            "dlc": msg.dlc,
                            "data": bytes(msg.data).hex(),
                        }
                    ),
                    flush=True,
                )
        print(f"DONE {got}", flush=True)
        return 0
    print(f"unknown mode {mode}", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv))
