#!/usr/bin/env python3
"""python-canopen 2.4.1 LocalNode (CANopen slave) for tests/system/canopen_interop.rs: our Rust master
talks to it over python-can's udp_multicast bus.

  canopen_local_node.py GROUP PORT NODE_ID EDS SECONDS   (or socketcan:IF 0 NODE_ID EDS SECONDS)

Builds a LocalNode from EDS (python-canopen's own EDS import), adds one writable
VISIBLE_STRING object 0x2FF0 "fieldprobe scratch" (the test EDS has no writable string, and a
segmented download needs one), sends its boot-up, enters PRE-OPERATIONAL (heartbeat per 0x1017,
0 in the test EDS: none until the master writes 0x1017), prints "READY" and serves until
SECONDS pass. On exit it prints one JSON line with the NMT state and what was written to 0x2FF0.
"""
import json
import sys
import time

import canopen
from canopen import objectdictionary as odm

SCRATCH = 0x2FF0
SCRATCH_INITIAL = "initial scratch text"


def connect(net, group, port):
    """GROUP PORT of python-can's udp_multicast bus, or `socketcan:IF` (PORT ignored)."""
    if group.startswith("socketcan:"):
        net.connect(interface="socketcan", channel=group[len("socketcan:"):])
    else:
        net.connect(interface="udp_multicast", channel=group, port=port)


def main(argv):
    group, port, node_id, eds, seconds = argv[1], int(argv[2]), int(argv[3]), argv[4], float(argv[5])
    net = canopen.Network()
    connect(net, group, port)
    try:
        node = canopen.LocalNode(node_id, eds)
        scratch = odm.ODVariable("fieldprobe scratch", SCRATCH, 0)
        scratch.data_type = odm.VISIBLE_STRING
        scratch.access_type = "rw"
        scratch.default = SCRATCH_INITIAL
        node.object_dictionary.add_object(scratch)
        net.add_node(node)
        node.nmt.send_command(0x81)          # boot-up 0x700+id [00]
        node.nmt.state = "PRE-OPERATIONAL"   # starts the heartbeat if 0x1017 != 0
        print("READY", flush=True)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            time.sleep(0.05)
        written = node.data_store.get(SCRATCH, {}).get(0)
        print(json.dumps({
            "nmt_state": node.nmt.state,
            "scratch": written.decode("utf-8", "replace") if written is not None else None,
        }), flush=True)
    finally:
        net.disconnect()


if __name__ == "__main__":
    main(sys.argv)
