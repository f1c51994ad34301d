#!/usr/bin/env python3
"""Read a candump -L log with python-can 4.6.1's own reader (can.CanutilsLogReader), the
independent reader of tests/system/candump_logs.rs.

  read_candump.py FILE    one JSON object per message: {"t": float, "channel": str,
                          "id": int, "ext": bool, "rtr": bool, "err": bool, "data": "hex"},
                          then "DONE n". A line the reader refuses ends the script with the
                          exception on stderr and exit 1.
"""
import json
import sys

import can


def main(argv):
    n = 0
    for msg in can.CanutilsLogReader(argv[1]):
        print(
            json.dumps(
                {
                    "t": msg.timestamp,
                    "channel": str(msg.channel),
                    "id": msg.arbitration_id,
                    "ext": msg.is_extended_id,
                    "rtr": msg.is_remote_frame,
                    "err": msg.is_error_frame,
                    "data": bytes(msg.data or b"").hex(),
                }
            )
        )
        n += 1
    print(f"DONE {n}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
