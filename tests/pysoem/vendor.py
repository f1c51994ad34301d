#!/usr/bin/env python3
"""SOEM (pysoem) against `fieldprobe sim ethercat` playing vendor CiA 402 devices.

    vendor.py IFACE SPEC_JSON

Run by tests/system/vendor_ethercat.rs inside a private network namespace. SPEC_JSON is computed by the
Rust test from the vendor ESI files with its own XML reader (not fieldprobe's):

    {"devices": [{"vendor": int, "product": int, "revision": int, "name": str, "type": str,
                  "rx": [[index, sub, bits], ...], "tx": [[index, sub, bits], ...],
                  "not_mappable": [index, sub, bits]}, ...]}     # ring order

rx / tx: the ESI's default PDO mapping (RxPdo / TxPdo with Sm 2 / 3), in order; optional keys
rx_pdo / tx_pdo (the default PDOs), rx_fixed / tx_fixed (they are Fixed: only assigned back,
not remapped) and rx_edit (a PDO that is not fixed, where the remapping rules are tried).

Steps per device in PRE-OP: identity and name (config_init); the PDO remapping rules with SDO
downloads: 0x1C12:00 = 0 and 0x1600:00 = 0 accepted, 0x1600:01 = a non-mappable object refused
with 0x06040041, an entry written while 0x1600:00 != 0 refused with 0x06010003, the default
mapping written back. Then config_map (image sizes = the default mapping's bits), SAFE-OP -> OP
with process data at the expected working counter, CiA 402 enable through the process image
(controlword 6 -> 7 -> 15 at the offset of 0x6040, statusword & 0x6F 0x21 -> 0x23 -> 0x27 at the
offset of 0x6041, target 0x607A = actual 0x6064 where both are mapped), and in OP a write to 0x1C12:00 refused with
0x08000022.

Prints `VENDOR_RESULT {json}`; exits 0 when every check passed.
"""

import json
import struct
import sys
import time

import pysoem

RESULT = {"ok": False, "steps": []}
RECEIVE_TIMEOUT_US = 500_000


class CheckFailed(Exception):
    pass


def check(cond, what):
    if not cond:
        raise CheckFailed(what)


def step(name, **kw):
    RESULT["steps"].append(dict(step=name, **kw))


def abort_code(fn):
    """Run an SDO access; the abort code it raised, or None when it succeeded."""
    try:
        fn()
    except pysoem.SdoError as e:
        return e.abort_code
    return None


def offset(entries, index):
    """(byte offset, bits) of `index` in a mapping, or None."""
    bit = 0
    for i, s, n in entries:
        if i == index:
            return bit // 8, n
        bit += n
    return None


FMT = {8: "b", 16: "h", 32: "i"}


def get(buf, entries, index, signed=True):
    o = offset(entries, index)
    f = FMT[o[1]]
    return struct.unpack_from("<" + (f if signed else f.upper()), buf, o[0])[0]


def put(buf, entries, index, value):
    o = offset(entries, index)
    if o is not None:
        struct.pack_into("<" + FMT[o[1]], buf, o[0], value)


def mapping_value(e):
    return (e[0] << 16) | (e[1] << 8) | e[2]


def write_mapping(s, assign, pdo, entries):
    """The CiA 301 procedure: assignment and mapping sub-index 0 = 0, entries, counts."""
    for i, sub, b in [(assign, 0, bytes([0])), (pdo, 0, bytes([0]))] + \
            [(pdo, k + 1, struct.pack("<I", mapping_value(e))) for k, e in enumerate(entries)] + \
            [(pdo, 0, bytes([len(entries)])), (assign, 1, struct.pack("<H", pdo)),
             (assign, 0, bytes([1]))]:
        code = abort_code(lambda: s.sdo_write(i, sub, b))
        check(code is None, f"{i:#06x}:{sub:02x} = {b.hex()} refused with {code}")


def assign(s, a, pdos):
    """PDO assignment `a` = `pdos` (sub-index 0 = 0, entries, count)."""
    for i, sub, b in [(a, 0, bytes([0]))] + \
            [(a, k + 1, struct.pack("<H", p)) for k, p in enumerate(pdos)] + \
            [(a, 0, bytes([len(pdos)]))]:
        code = abort_code(lambda: s.sdo_write(i, sub, b))
        check(code is None, f"{i:#06x}:{sub:02x} = {b.hex()} refused with {code}")


def restore(s, a, pdo, entries, fixed):
    """Back to the ESI's default: a fixed PDO is only assigned, another one also mapped."""
    if fixed:
        assign(s, a, [pdo])
    else:
        write_mapping(s, a, pdo, entries)


def remap_rules(s, d):
    # The rules are tried on a PDO whose mapping may change (the default one may be fixed).
    rx = d.get("rx_edit") or d["rx_pdo"]
    w = lambda i, sub, b: (lambda: s.sdo_write(i, sub, b))
    check(abort_code(w(0x1C12, 0, bytes([0]))) is None, "0x1C12:00 = 0 refused in PRE-OP")
    check(abort_code(w(rx, 0, bytes([0]))) is None, f"{rx:#06x}:00 = 0 refused in PRE-OP")
    bad = struct.pack("<I", mapping_value(d["not_mappable"]))
    code = abort_code(w(rx, 1, bad))
    check(code == 0x06040041,
          f"mapping {d['not_mappable']} into {rx:#06x}:01: abort {code}, expected 0x06040041")
    check(abort_code(w(rx, 1, struct.pack("<I", mapping_value(d["rx"][0])))) is None,
          f"{rx:#06x}:01 refused")
    check(abort_code(w(rx, 0, bytes([1]))) is None, f"{rx:#06x}:00 = 1 refused")
    code = abort_code(w(rx, 1, struct.pack("<I", mapping_value(d["rx"][0]))))
    check(code == 0x06010003, f"{rx:#06x}:01 with sub-index 0 != 0: abort {code}, expected 0x06010003")
    # Back to the ESI's default mapping (a master before us may have changed it).
    restore(s, 0x1C12, d["rx_pdo"], d["rx"], d.get("rx_fixed", False))
    restore(s, 0x1C13, d["tx_pdo"], d["tx"], d.get("tx_fixed", False))
    step("remap_rules", device=d["name"], edited=rx, not_mappable=d["not_mappable"])


def run(iface, spec):
    devices = spec["devices"]
    master = pysoem.Master()
    master.open(iface)
    try:
        n = master.config_init()
        check(n == len(devices), f"config_init found {n} devices, expected {len(devices)}")
        for pos, (s, d) in enumerate(zip(master.slaves, devices)):
            check((s.man, s.id, s.rev) == (d["vendor"], d["product"], d["revision"]),
                  f"device {pos}: identity {(s.man, s.id, s.rev)}, ESI {d}")
            # SOEM's name is the SII General order string (ESI `Type` text).
            want = d.get("type") or d["name"]
            check(s.name == want[:40], f"device {pos}: name {s.name!r}, ESI {want!r}")
            remap_rules(s, d)
        step("identity")
        master.config_map()
        for pos, (s, d) in enumerate(zip(master.slaves, devices)):
            want = (sum(e[2] for e in d["rx"]) // 8, sum(e[2] for e in d["tx"]) // 8)
            got = (len(bytes(s.output)), len(bytes(s.input)))
            check(got == want, f"device {pos}: image {got} bytes, ESI default mapping {want}")
        check(master.state_check(pysoem.SAFEOP_STATE, 2_000_000) == pysoem.SAFEOP_STATE,
              "not all devices reached SAFE-OP")
        outs = [bytearray(len(bytes(s.output))) for s in master.slaves]
        wkcs = set()

        def exchange():
            for s, o in zip(master.slaves, outs):
                s.output = bytes(o)
            master.send_processdata()
            wkcs.add(master.receive_processdata(RECEIVE_TIMEOUT_US))
            time.sleep(0.001)
            return [bytes(s.input) for s in master.slaves]

        ins = exchange()
        for o, i, d in zip(outs, ins, devices):
            if offset(d["tx"], 0x6064) is not None:
                put(o, d["rx"], 0x607A, get(i, d["tx"], 0x6064))
            put(o, d["rx"], 0x6060, 8)
        master.state = pysoem.OP_STATE
        master.write_state()
        for _ in range(200):
            exchange()
            if master.state_check(pysoem.OP_STATE, 1_000) == pysoem.OP_STATE:
                break
        check(master.state_check(pysoem.OP_STATE, 50_000) == pysoem.OP_STATE,
              "not all devices reached OP: " + ", ".join(
                  f"{p}: {sl.state:#x} AL {sl.al_status:#06x}" for p, sl in enumerate(master.slaves)))
        wkcs.clear()
        for _ in range(20):
            exchange()
        check(wkcs == {master.expected_wkc}, f"working counters {wkcs}, expected {master.expected_wkc}")
        step("op", expected_wkc=master.expected_wkc)
        for cw, want in [(0x06, 0x21), (0x07, 0x23), (0x0F, 0x27)]:
            for o, d in zip(outs, devices):
                put(o, d["rx"], 0x6040, cw)
            for _ in range(100):
                ins = exchange()
                if all(get(i, d["tx"], 0x6041, False) & 0x6F == want for i, d in zip(ins, devices)):
                    break
            sws = [hex(get(i, d["tx"], 0x6041, False)) for i, d in zip(ins, devices)]
            check(all(get(i, d["tx"], 0x6041, False) & 0x6F == want for i, d in zip(ins, devices)),
                  f"controlword {cw:#x}: statuswords {sws}, expected & 0x6F == {want:#x}")
        step("cia402_enable", statuswords=sws)
        for pos, s in enumerate(master.slaves):
            code = abort_code(lambda: s.sdo_write(0x1C12, 0, bytes([0])))
            check(code == 0x08000022, f"device {pos}: 0x1C12:00 = 0 in OP: abort {code}, expected 0x08000022")
        step("op_refuses_remap")
        for o, d in zip(outs, devices):
            put(o, d["rx"], 0x6040, 0x06)
        for _ in range(5):
            exchange()
        master.state = pysoem.INIT_STATE
        master.write_state()
        RESULT.update(ok=True)
    finally:
        master.close()


def main():
    iface, spec = sys.argv[1], json.loads(sys.argv[2])
    try:
        run(iface, spec)
    except Exception as e:  # pysoem errors and failed checks
        RESULT.update(ok=False, error=f"{type(e).__name__}: {e}")
    print("VENDOR_RESULT " + json.dumps(RESULT), flush=True)
    sys.exit(0 if RESULT["ok"] else 1)


if __name__ == "__main__":
    main()
