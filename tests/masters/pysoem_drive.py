#!/usr/bin/env python3
"""SOEM (PyPI `pysoem` 1.1.13) against `fieldprobe sim ethercat`: our servo and one CiA 402
device of every vendor ESI file on one segment.

    pysoem_drive.py IFACE SPEC_JSON

Run by tests/system/independent_masters.rs inside a private network namespace, with the SPEC of
tests/masters/kickcat_drive.py (computed from the ESI files by the Rust test). The deeper run on
our own segment (segmented upload, the timestamp terminal, working counters) is
tests/pysoem/interop.py.

Steps: config_init (count, identities); per CoE device 0x1008, 0x1009, 0x100A (= the ESI's
`DefaultString` / `DefaultData` where it gives one), an expedited
write of 0x6060 = 8 read back, complete access of 0x1C12 / 0x1C13 (= the ESI's default
assignment where the ESI gives one) downloaded back, SDO Information (`slave.od`: the object
list holds 0x6041 with the ESI's name); config_map (image sizes = the ESI default mapping),
config_dc and SYNC0 (1 ms) on every drive with DC, SAFE-OP, OP; the CiA 402 enable and the CSP
ramp across the probe surface on every drive; on the touch-probe drives 0x60B8 = 0x0011 through
the outputs (or SDO) and 0x60B9 / 0x60BA after the crossing.

Prints `PYSOEM_RESULT {json}`; exits 0 when every check passed.
"""

import json
import struct
import sys
import time
import traceback

import pysoem

from common import RESULT, CheckFailed, check, step, layout, get, put

RECEIVE_TIMEOUT_US = 100_000


def run(iface, spec):
    devices = spec["devices"]
    master = pysoem.Master()
    master.open(iface)
    try:
        drive(master, devices, spec)
    finally:
        master.close()


def drive(master, devices, spec):
    t0 = time.monotonic()
    n = master.config_init()
    check(n == len(devices), f"config_init found {n} devices, expected {len(devices)}")
    for e, s in zip(devices, master.slaves):
        check((s.man, s.id, s.rev) == (e["vendor"], e["product"], e["revision"]),
              f"device {e['pos']}: identity {s.man:#x}/{s.id:#x}/{s.rev:#x}")
    step("scan", devices=n, seconds=round(time.monotonic() - t0, 3))

    for e, s in zip(devices, master.slaves):
        if not e["coe"]:
            continue
        rec = {"pos": e["pos"]}
        if e["device_name"] is not None:
            name = s.sdo_read(0x1008, 0).rstrip(b"\0").decode("latin-1")
            check(name == e["device_name"], f"device {e['pos']}: 0x1008 {name!r}, ESI {e['device_name']!r}")
            rec["device_name"] = name
        strings = {}
        for idx, want in e["strings"].items():
            got = s.sdo_read(int(idx, 16), 0).rstrip(b"\0").decode("latin-1")
            check(got == want, f"device {e['pos']}: {idx} {got!r}, ESI default {want!r}")
            strings[idx] = got
        rec["strings"] = strings
        if e["drive"]:
            s.sdo_write(0x6060, 0, struct.pack("<b", 8))
            back = struct.unpack("<b", s.sdo_read(0x6060, 0)[:1])[0]
            check(back == 8, f"device {e['pos']}: 0x6060 read back {back}")
        if e["complete_access"]:
            for assign, pdos in ((0x1C12, e["rx_pdos"]), (0x1C13, e["tx_pdos"])):
                img = s.sdo_read(assign, 0, ca=True)
                k = img[0]
                got = [struct.unpack_from("<H", img, 2 + 2 * j)[0] for j in range(k)]
                check(got == pdos if e["pdo_elements"] else len(img) >= 2 + 2 * k,
                      f"device {e['pos']}: CA {assign:#06x} = {img.hex()}, ESI {pdos}")
                # The whole uploaded image back (entries past n included), as a configurator
                # that reads, edits and writes the object does.
                s.sdo_write(assign, 0, img, ca=True)
                again = s.sdo_read(assign, 0, ca=True)
                check(again == img, f"device {e['pos']}: after CA download {assign:#06x}: {again.hex()}")
                rec[f"ca_{assign:04x}"] = img.hex()
        if e["sdo_info"] and "0x6041" in e["object_names"]:
            names = {o.index: o.name for o in s.od}
            got = names.get(0x6041)
            got = got.decode("latin-1") if isinstance(got, bytes) else got
            check(got == e["object_names"]["0x6041"],
                  f"device {e['pos']}: SDO info 0x6041 {got!r}, ESI {e['object_names']['0x6041']!r}")
            rec["sdo_info_objects"] = len(names)
        step("sdo", **rec)

    master.config_map()
    sizes = [[len(bytes(s.output)), len(bytes(s.input))] for s in master.slaves]
    for e, (o, i) in zip(devices, sizes):
        if e["pdo_elements"]:
            want = [sum(b for _, _, b in e["rx"]) // 8, sum(b for _, _, b in e["tx"]) // 8]
            check([o, i] == want, f"device {e['pos']}: image {o, i}, ESI {want}")
    step("mapping", sizes=sizes, expected_wkc=master.expected_wkc)

    dc = bool(master.config_dc())
    drives = [k for k, e in enumerate(devices) if e["drive"]]
    synced = []
    if dc:
        for k in drives:
            if master.slaves[k].dc_sync(True, 1_000_000) is None:
                synced.append(devices[k]["pos"])
    step("dc", dc=dc, sync0=synced)
    check(master.state_check(pysoem.SAFEOP_STATE, 3_000_000) == pysoem.SAFEOP_STATE,
          "not all devices in SAFE-OP: " + ", ".join(
              f"{p}: {sl.state:#x} AL {sl.al_status:#06x}" for p, sl in enumerate(master.slaves)))

    rx = [layout(e["rx"]) for e in devices]
    tx = [layout(e["tx"]) for e in devices]
    outs = [bytearray(len(bytes(s.output))) for s in master.slaves]
    cycles = 0

    def exchange():
        nonlocal cycles
        for s, o in zip(master.slaves, outs):
            if len(o):
                s.output = bytes(o)
        master.send_processdata()
        master.receive_processdata(RECEIVE_TIMEOUT_US)
        cycles += 1
        time.sleep(0.001)
        return [bytes(s.input) for s in master.slaves]

    ins = exchange()
    for k in drives:
        put(outs[k], rx[k], 0x607A, get(ins[k], tx[k], 0x6064))
        if 0x6060 in rx[k]:
            put(outs[k], rx[k], 0x6060, 8)
        if 0x6072 in rx[k]:
            put(outs[k], rx[k], 0x6072, 3000)
    master.state = pysoem.OP_STATE
    master.write_state()
    for _ in range(300):
        exchange()
        if master.state_check(pysoem.OP_STATE, 1_000) == pysoem.OP_STATE:
            break
    check(master.state_check(pysoem.OP_STATE, 50_000) == pysoem.OP_STATE, "not all devices in OP")
    step("op")

    def until(pred, max_cycles, what):
        i = None
        for _ in range(max_cycles):
            i = exchange()
            if pred(i):
                return i
        raise CheckFailed(f"{what}: not reached in {max_cycles} cycles")

    sws = {}
    for cw, want in ((6, 0x21), (7, 0x23), (15, 0x27)):
        for k in drives:
            put(outs[k], rx[k], 0x6040, cw)
        ins = until(lambda i: all(get(i[k], tx[k], 0x6041, False) & 0x6F == want for k in drives),
                    300, f"controlword {cw}")
        for k in drives:
            sws.setdefault(devices[k]["pos"], []).append(get(ins[k], tx[k], 0x6041, False))
    step("cia402_enable", statuswords=sws)

    probes = [k for k in drives if devices[k]["touch_probe"]]
    for k in probes:
        if 0x60B8 in rx[k]:
            put(outs[k], rx[k], 0x60B8, 0x0011)
        else:
            master.slaves[k].sdo_write(0x60B8, 0, struct.pack("<H", 0x0011))
    ins = exchange()
    stp = spec["step_inc"]
    targets = {k: get(ins[k], tx[k], 0x6064) for k in drives}
    for leg in ("start_inc", "end_inc"):
        while True:
            done = True
            for k in drives:
                goal, t = devices[k][leg], targets[k]
                if t != goal:
                    targets[k] = min(goal, t + stp) if goal > t else max(goal, t - stp)
                    done = False
                put(outs[k], rx[k], 0x607A, targets[k])
            ins = exchange()
            if done:
                break
        ins = until(lambda i: all(abs(get(i[k], tx[k], 0x6064) - devices[k][leg]) <= 1 for k in drives),
                    1000, f"actual position at {leg}")
    step("csp", actual={devices[k]["pos"]: get(ins[k], tx[k], 0x6064) for k in drives})

    latches = {}
    for k in probes:
        e = devices[k]
        if 0x60B9 in tx[k] and 0x60BA in tx[k]:
            st, pos = get(ins[k], tx[k], 0x60B9, False), get(ins[k], tx[k], 0x60BA)
        else:
            s = master.slaves[k]
            st = struct.unpack("<H", s.sdo_read(0x60B9, 0)[:2])[0]
            pos = struct.unpack("<i", s.sdo_read(0x60BA, 0)[:4])[0]
        check(st & 0x03 == 0x03, f"device {e['pos']}: 0x60B9 {st:#06x}")
        latches[e["pos"]] = {"status": st, "tp1_pos": pos, "surface": e["probe_inc"]}
    step("touch_probe", latches=latches)
    for k in drives:
        put(outs[k], rx[k], 0x6040, 0)
    exchange()
    master.state = pysoem.INIT_STATE
    master.write_state()
    RESULT["cycles"] = cycles
    RESULT["seconds"] = round(time.monotonic() - t0, 3)


def main():
    iface, spec = sys.argv[1], json.loads(sys.argv[2])
    try:
        run(iface, spec)
        RESULT["ok"] = True
    except Exception as e:  # reported to the Rust test, which fails with it
        RESULT["error"] = f"{type(e).__name__}: {e}"
        RESULT["trace"] = traceback.format_exc()
    print("PYSOEM_RESULT " + json.dumps(RESULT), flush=True)
    sys.exit(0 if RESULT["ok"] else 1)


if __name__ == "__main__":
    main()
