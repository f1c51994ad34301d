#!/usr/bin/env python3
"""SOEM (pysoem) as a second EtherCAT master between two `fieldprobe run`s: SDO reads only.

    sdo_read.py IFACE POSITION INDEX:SUB[:s] ...

Run by tests/system/serve_sessions.rs inside a private network namespace on one end of a veth pair
whose other end `fieldprobe sim ethercat` serves. Scans the segment (config_init: INIT ->
PRE-OP), reads each object of the device at ring POSITION by CoE SDO upload (`:s` = a string,
else an unsigned little-endian integer of the reply's length), and leaves the segment in
PRE-OP (no process data, no state change of the drive).

Prints one line `SDO_RESULT {json}`: {"ok": bool, "devices": n, "values": {"0x1018:1": int |
str, ...}, "error": str}; nothing about the values is judged here (the caller does). Exits 0
when every read succeeded, 1 otherwise.
"""

import json
import sys

import pysoem


def main():
    if len(sys.argv) < 4:
        print(__doc__, file=sys.stderr)
        return 2
    iface, position = sys.argv[1], int(sys.argv[2])
    result = {"ok": False, "values": {}}
    master = pysoem.Master()
    try:
        master.open(iface)
        try:
            result["devices"] = master.config_init()
            s = master.slaves[position]
            for spec in sys.argv[3:]:
                parts = spec.split(":")
                index, sub = int(parts[0], 0), int(parts[1], 0)
                data = bytes(s.sdo_read(index, sub))
                key = f"{index:#06x}:{sub}"
                if len(parts) > 2 and parts[2] == "s":
                    result["values"][key] = data.decode("latin-1")
                else:
                    result["values"][key] = int.from_bytes(data, "little")
            result["ok"] = True
        finally:
            master.close()
    except Exception as e:  # pysoem errors (SdoError, IndexError, ...): reported, judged by the caller
        result["error"] = f"{type(e).__name__}: {e}"
    print("SDO_RESULT " + json.dumps(result), flush=True)
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
