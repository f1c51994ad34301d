#!/usr/bin/env python3
"""SOEM (pysoem) reads a device's object dictionary through CoE SDO Information.

    od.py IFACE POSITION

Run by tests/system/pysoem_sdoinfo.rs inside a private network namespace on one end of a veth pair
whose other end `fieldprobe sim ethercat` serves. Scans the segment (config_init: PRE-OP) and
reads `slave.od` of the device at ring POSITION: SOEM's ecx_readODlist (Get OD List),
ecx_readODdescription (Get Object Description) and ecx_readOE (Get Entry Description for every
sub-index of an ARRAY / RECORD).

Prints one line `OD_RESULT {json}`: {"ok": bool, "objects": [{"index", "name", "object_code",
"data_type", "bit_length", "obj_access", "entries": [{"name", "data_type", "bit_length",
"obj_access"}]}], "error": str}. Nothing is judged here (the caller does). Exit 0 when the
dictionary was read, 1 otherwise.
"""

import json
import sys

import pysoem


def text(b):
    return b.decode("latin-1") if isinstance(b, (bytes, bytearray)) else str(b)


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    iface, position = sys.argv[1], int(sys.argv[2])
    result = {"ok": False, "objects": []}
    master = pysoem.Master()
    try:
        master.open(iface)
        try:
            result["devices"] = master.config_init()
            s = master.slaves[position]
            for o in s.od:
                result["objects"].append({
                    "index": o.index,
                    "name": text(o.name),
                    "object_code": o.object_code,
                    "data_type": o.data_type,
                    "bit_length": o.bit_length,
                    "obj_access": o.obj_access,
                    "entries": [{
                        "name": text(e.name),
                        "data_type": e.data_type,
                        "bit_length": e.bit_length,
                        "obj_access": e.obj_access,
                    } for e in o.entries],
                })
            result["ok"] = True
        finally:
            master.close()
    except Exception as e:  # pysoem errors: reported, judged by the caller
        result["error"] = f"{type(e).__name__}: {e}"
    print("OD_RESULT " + json.dumps(result), flush=True)
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
