#!/usr/bin/env python3
"""python-canopen as master drives one CiA 402 node to OPERATION ENABLED by SDO alone.

  canopen_sdo_drive.py --interface udp_multicast --channel 239.74.171.3 --port 43303 \
      --node 5 [--eds FILE]
  canopen_sdo_drive.py --interface socketcan --channel vcan0 --node 5 [--eds FILE]

Written for `fieldprobe sim canopen --eds FILE` (tests/system/canopen_interop.rs), usable against
any CiA 402 node on any python-can interface. No SYNC is ever sent. With --eds, python-canopen
reads the object dictionary from that file; without, a minimal one is written out here.

Prints ONE JSON line with what it observed (the caller judges it; nothing about values is
asserted here):
  statusword_before_sync   0x6041 read by SDO before anything else
  rpdo1_type, tpdo1_type   0x1400 / 0x1800 sub 2 (transmission type)
  heartbeat_ms             0x1017
  steps                    per controlword written to 0x6040 (6, 7, 0xF): the statusword
                           reads until (statusword & 0x6F) showed the CiA 402 state expected
  statusword_final, controlword_readback
  tpdo1_after_start        TPDO1 payload heard within 1 s of NMT start (hex), or null
"""
import argparse
import json
import sys
import threading
import time
import traceback

import canopen
from canopen import objectdictionary as odm

# CiA 402 statusword state coding under mask 0x6F (CiA 402 §6.2):
# READY TO SWITCH ON 0x21, SWITCHED ON 0x23, OPERATION ENABLED 0x27.
STEPS = [(0x0006, 0x21), (0x0007, 0x23), (0x000F, 0x27)]


def minimal_od():
    """The objects this script touches (types from CiA 301 / CiA 402)."""
    od = odm.ObjectDictionary()

    def var(name, index, sub, data_type, access="rw"):
        v = odm.ODVariable(name, index, sub)
        v.data_type = data_type
        v.access_type = access
        return v

    od.add_object(var("Producer heartbeat time", 0x1017, 0, odm.UNSIGNED16))
    for index in (0x1400, 0x1800):
        r = odm.ODRecord(f"PDO comm {index:#06x}", index)
        r.add_member(var("n", index, 0, odm.UNSIGNED8, "ro"))
        r.add_member(var("COB-ID", index, 1, odm.UNSIGNED32))
        r.add_member(var("Transmission type", index, 2, odm.UNSIGNED8))
        od.add_object(r)
    od.add_object(var("Controlword", 0x6040, 0, odm.UNSIGNED16))
    od.add_object(var("Statusword", 0x6041, 0, odm.UNSIGNED16, "ro"))
    return od


def run(net, args, out):
    od = args.eds if args.eds else minimal_od()
    node = canopen.RemoteNode(args.node, od)
    net.add_node(node)
    node.sdo.RESPONSE_TIMEOUT = 1.0

    out["statusword_before_sync"] = node.sdo[0x6041].raw
    out["rpdo1_type"] = node.sdo[0x1400][2].raw
    out["tpdo1_type"] = node.sdo[0x1800][2].raw
    out["heartbeat_ms"] = node.sdo[0x1017].raw

    for controlword, want in STEPS:
        node.sdo[0x6040].raw = controlword
        reads = []
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            sw = node.sdo[0x6041].raw
            reads.append(sw)
            if sw & 0x6F == want:
                break
            time.sleep(0.01)
        out["steps"].append({"controlword": controlword, "statusword_reads": reads})
    out["statusword_final"] = node.sdo[0x6041].raw
    out["controlword_readback"] = node.sdo[0x6040].raw

    # NMT start: an event-driven TPDO1 (type 254 / 255) goes out without a SYNC.
    cob = (node.sdo[0x1800][1].raw & 0x7FF) if out["tpdo1_type"] >= 254 else None
    heard = []
    got = threading.Event()

    def on_tpdo(can_id, data, timestamp):
        heard.append(bytes(data).hex())
        got.set()

    if cob is not None:
        net.subscribe(cob, on_tpdo)
    node.nmt.state = "OPERATIONAL"
    out["tpdo1_after_start"] = heard[0] if cob is not None and got.wait(1.0) else None


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--interface", required=True, help="python-can interface")
    p.add_argument("--channel", required=True, help="python-can channel")
    p.add_argument("--port", type=int, help="udp_multicast port")
    p.add_argument("--node", type=int, required=True, help="node id")
    p.add_argument("--eds", help="EDS for python-canopen's object dictionary")
    args = p.parse_args()
    out = {"steps": []}
    net = canopen.Network()
    kw = {"port": args.port} if args.port is not None else {}
    net.connect(interface=args.interface, channel=args.channel, **kw)
    try:
        run(net, args, out)
        out["ok"] = True
    except Exception:  # report; the caller decides
        out["ok"] = False
        out["traceback"] = traceback.format_exc()
    finally:
        net.disconnect()
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
