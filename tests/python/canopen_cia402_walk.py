#!/usr/bin/env python3
"""python-canopen (BaseNode402) walks CiA 402 nodes through the power state machine.

  canopen_cia402_walk.py GROUP PORT NODE_ID [NODE_ID ...]

For each node on python-can's udp_multicast bus GROUP:PORT (the tests run `fieldprobe sim
canopen --eds FILE` there, tests/system/vendor_eds_corpus.rs): python-canopen's BaseNode402 state
setter moves the drive to SWITCH ON DISABLED, READY TO SWITCH ON, SWITCHED ON and OPERATION
ENABLED in turn (it picks the controword of each transition, CiA 402 §6.2 figure "state
machine", and writes it by SDO: no PDO is set up here), and after each step the statusword
0x6041 is read back by SDO.

Prints ONE JSON line (the caller judges it; nothing about values is asserted here):
  {"nodes": {"1": {"ok": true, "steps": [{"target": "...", "statusword": 0x..}, ...]}, ...}}

The object dictionary of the remote node is written out here (only 0x6040 / 0x6041, types
from CiA 402), so python-canopen reads no EDS and shares no code with the emulator.
"""
import json
import sys
import traceback

import canopen
from canopen import objectdictionary as odm

TARGETS = ["SWITCH ON DISABLED", "READY TO SWITCH ON", "SWITCHED ON", "OPERATION ENABLED"]


def od402():
    od = odm.ObjectDictionary()
    for index, name, access in ((0x6040, "Controlword", "rw"), (0x6041, "Statusword", "ro")):
        v = odm.ODVariable(name, index, 0)
        v.data_type = odm.UNSIGNED16
        v.access_type = access
        od.add_object(v)
    return od


def walk(net, node_id):
    out = {"steps": []}
    node = canopen.BaseNode402(node_id, od402())
    net.add_node(node)
    # A loaded two-core machine: python-canopen's defaults (0.4 s a step, 0.8 s in all) are
    # tight; the emulated drive acts on an SDO controlword at once.
    node.sdo.RESPONSE_TIMEOUT = 2.0
    node.TIMEOUT_SWITCH_STATE_SINGLE = 3.0
    node.TIMEOUT_SWITCH_STATE_FINAL = 10.0
    try:
        for target in TARGETS:
            node.state = target
            out["steps"].append({"target": target, "statusword": node.sdo[0x6041].raw})
        out["ok"] = True
    except Exception as e:  # report, the Rust side decides
        out["ok"] = False
        out["error"] = f"{type(e).__name__}: {e}"
        out["traceback"] = traceback.format_exc()
    return out


def main(argv):
    group, port, nodes = argv[1], int(argv[2]), [int(n) for n in argv[3:]]
    net = canopen.Network()
    net.connect(interface="udp_multicast", channel=group, port=port)
    result = {"nodes": {}}
    try:
        for n in nodes:
            result["nodes"][str(n)] = walk(net, n)
    finally:
        net.disconnect()
    print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main(sys.argv)
