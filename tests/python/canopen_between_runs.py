#!/usr/bin/env python3
"""python-canopen as a second CANopen master between two `fieldprobe run`s.

  canopen_between_runs.py GROUP PORT NODE...

Run by tests/system/canopen_sessions.rs inside a private network namespace against `fieldprobe sim
canopen --bus udp:GROUP:PORT`. For each NODE: SDO uploads of 0x1000, 0x1018:1, 0x1018:2 and
0x1018:4, NMT start (the node's heartbeat must then say OPERATIONAL), then a segmented upload
of 0x1008 that is started (initiate + first segment) and ABANDONED: the script leaves without
finishing or aborting it, as a client that crashed would. The next master has to cope (its NMT
reset communication must clear it in the node).

Prints ONE line `CANOPEN_RESULT {json}` with what it observed (the caller judges the values):
  {"ok": bool, "nodes": {"ID": {"0x1000": int, "0x1018:1": int, "0x1018:2": int,
   "0x1018:4": int, "state_after_start": str, "abandoned_first_segment": hex}}, "error": str}
Exit 0 when every step ran, 1 otherwise.
"""
import json
import sys
import time
import traceback

import canopen
from canopen.sdo.client import ReadableStream


def u32(b):
    return int.from_bytes(bytes(b), "little")


def main():
    if len(sys.argv) < 4:
        print(__doc__, file=sys.stderr)
        return 2
    group, port, ids = sys.argv[1], int(sys.argv[2]), [int(a) for a in sys.argv[3:]]
    out = {"ok": False, "nodes": {}}
    net = canopen.Network()
    net.connect(interface="udp_multicast", channel=group, port=port)
    try:
        streams = []
        for node_id in ids:
            node = net.add_node(node_id, canopen.ObjectDictionary())
            node.sdo.RESPONSE_TIMEOUT = 2.0
            r = {
                "0x1000": u32(node.sdo.upload(0x1000, 0)),
                "0x1018:1": u32(node.sdo.upload(0x1018, 1)),
                "0x1018:2": u32(node.sdo.upload(0x1018, 2)),
                "0x1018:4": u32(node.sdo.upload(0x1018, 4)),
            }
            node.nmt.state = "OPERATIONAL"
            # The node's next heartbeat tells its state (0x05 = OPERATIONAL).
            node.nmt.wait_for_heartbeat(timeout=2.0)
            time.sleep(0.3)
            node.nmt.wait_for_heartbeat(timeout=2.0)
            r["state_after_start"] = node.nmt.state
            # Initiate a segmented upload and take one segment; never finish it.
            s = ReadableStream(node.sdo, 0x1008, 0)
            r["abandoned_first_segment"] = bytes(s.read(7)).hex()
            streams.append(s)  # kept alive: no close, no abort
            out["nodes"][str(node_id)] = r
        out["ok"] = True
    except Exception:  # reported; the caller decides
        out["error"] = traceback.format_exc()
    finally:
        net.disconnect()
    print("CANOPEN_RESULT " + json.dumps(out), flush=True)
    return 0 if out["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
