#!/usr/bin/env python3
"""SOEM (pysoem) brings every device of a `fieldprobe sim ethercat` segment to OP.

    corpus.py IFACE SPEC_JSON

Run by tests/system/vendor_corpus_ethercat.rs inside a private network namespace, once per vendor ESI
file. SPEC_JSON is computed by the Rust test from the ESI file with its own XML reader:

    {"devices": [{"vendor": int, "product": int, "revision": int}, ...]}     # ring order

Steps: config_init finds the devices with these identities (SII, as SOEM reads it); config_map
lays out the process image from the devices' default PDO assignment and mapping (SOEM reads
0x1C12 / 0x1C13 and the mapping objects over CoE); SAFE-OP, then OP with process data exchanged
every 2 ms at the expected working counter (outputs written: 2 per device, inputs read: 1).

Prints `CORPUS_RESULT {json}`; exits 0 when every check passed.
"""

import json
import sys
import time

import pysoem

RESULT = {"ok": False, "steps": []}


class CheckFailed(Exception):
    pass


def check(cond, what):
    if not cond:
        raise CheckFailed(what)


def main():
    iface, spec = sys.argv[1], json.loads(sys.argv[2])
    want = spec["devices"]
    m = pysoem.Master()
    m.open(iface)
    try:
        n = m.config_init()
        check(n == len(want), f"config_init found {n} devices, expected {len(want)}")
        for i, (d, w) in enumerate(zip(m.slaves, want)):
            got = (d.man, d.id, d.rev)
            exp = (w["vendor"], w["product"], w["revision"])
            check(got == exp, f"device {i}: identity {got}, ESI says {exp}")
        RESULT["steps"].append({"step": "config_init", "devices": n})
        size = m.config_map()
        RESULT["steps"].append({"step": "config_map", "image": size})
        check(
            m.state_check(pysoem.SAFEOP_STATE, 2_000_000) == pysoem.SAFEOP_STATE,
            "not all devices reached SAFE-OP: "
            + ", ".join(f"{d.name} 0x{d.state:02x} AL 0x{d.al_status:04x}" for d in m.slaves),
        )
        expected = m.expected_wkc
        m.send_processdata()
        m.receive_processdata(2000)
        m.state = pysoem.OP_STATE
        m.write_state()
        deadline = time.monotonic() + 5.0
        reached = False
        wkc = 0
        while time.monotonic() < deadline:
            m.send_processdata()
            wkc = m.receive_processdata(2000)
            if m.read_state() == pysoem.OP_STATE and all(
                d.state == pysoem.OP_STATE for d in m.slaves
            ):
                reached = True
                break
            time.sleep(0.002)
        check(
            reached,
            "OP not reached in 5 s: "
            + ", ".join(f"{d.name} 0x{d.state:02x} AL 0x{d.al_status:04x}" for d in m.slaves),
        )
        good = 0
        for _ in range(200):
            m.send_processdata()
            wkc = m.receive_processdata(2000)
            good += wkc == expected
            time.sleep(0.002)
        check(good >= 190, f"working counter {expected} in {good} of 200 cycles (last {wkc})")
        RESULT["steps"].append({"step": "op", "expected_wkc": expected, "good": good})
        m.state = pysoem.INIT_STATE
        m.write_state()
        RESULT["ok"] = True
    except CheckFailed as e:
        RESULT["error"] = str(e)
    finally:
        m.close()
    print("CORPUS_RESULT " + json.dumps(RESULT), flush=True)
    sys.exit(0 if RESULT["ok"] else 1)


if __name__ == "__main__":
    main()
