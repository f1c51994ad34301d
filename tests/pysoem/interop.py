#!/usr/bin/env python3
"""SOEM (pysoem) as an independent EtherCAT master against `fieldprobe sim ethercat`.

    interop.py IFACE SPEC_JSON

Run by tests/system/pysoem_interop.rs inside a private network namespace, on one end of a veth pair
whose other end the emulator serves. SPEC_JSON (computed by the Rust test from the ESI XML,
independently of fieldprobe's ESI parser):

    {"devices": [{"vendor": int, "product": int, "revision": int, "type": str, "name": str,
                  "out_bits": int, "in_bits": int}, ...],       # ring order
     "servo": int,                                              # ring position of the CiA 402 drive
     "long_object": {"index": int, "sub": int, "text": str},    # read by segmented upload
     "probe": null | {"device": int, "position_inc": int, "start_inc": int, "end_inc": int},
     "complete_access": null | {"assign": {"0x1C12": [pdo, ...], ...},
                                "mapping": {"0x1A00": [[index, sub, bits], ...], ...}}}

Steps: config_init (identities and names), SDO reads (0x1000, 0x1018:1..3, 0x6041), SDO write +
read-back (0x6065), the segmented upload, complete access (upload of the PDO assignment and a
mapping = the ESI's defaults, download of the same image, read back), config_map (image sizes = ESI PDO bit sums), config_dc
(recorded, not required), SAFE-OP -> OP with cyclic process data and the expected working
counter, CiA 402 enable (controlword 6 -> 7 -> 15, statusword & 0x6F: 0x21 -> 0x23 -> 0x27) in CSP
through the outputs, and, with "probe", a touch-probe latch (0x60B8 via the outputs, a ramp of
0x607A across the surface, 0x60B9 bit 1 and 0x60BA).

Prints one line `PYSOEM_RESULT {json}` and exits 0 when every check passed; on the first failed
check prints the result line with "ok": false and "error", and exits 1.
"""

import json
import struct
import sys
import time

import pysoem

RESULT = {"ok": False, "steps": []}

# CiA 402 servo process image (drives/cia402-generic.toml = ESI default mapping):
# outputs: 0x6040 u16, 0x607A i32, 0x6060 i8, 0x60B8 u16                          (9 bytes)
# inputs:  0x6041 u16, 0x6064 i32, 0x60F4 i32, 0x6061 i8, 0x60B9 u16, 0x60BA..0x60BD i32,
#          0x6077 i16                                                            (31 bytes)
OUT_FMT = "<HiBH"
IN_FMT = "<HiibHiiiih"
CSP = 8


class CheckFailed(Exception):
    pass


def check(cond, what):
    if not cond:
        raise CheckFailed(what)


def step(name, **info):
    entry = {"step": name}
    entry.update(info)
    RESULT["steps"].append(entry)
    print("step", json.dumps(entry), flush=True)


def u32(b):
    return struct.unpack("<I", b[:4])[0]


def u16(b):
    return struct.unpack("<H", b[:2])[0]


# Process-data receive bound of each cycle (µs), see Cyclic.exchange.
RECEIVE_TIMEOUT_US = 500_000


class Cyclic:
    """Cyclic process data with working-counter checks."""

    def __init__(self, master, servo):
        self.master = master
        self.servo = servo
        self.cycles = 0
        self.wkc_errors = 0
        self.wkcs = set()
        self.out = {"cw": 0, "target": 0, "mode": CSP, "tp": 0}

    def exchange(self):
        s = self.master.slaves[self.servo]
        o = self.out
        s.output = struct.pack(OUT_FMT, o["cw"], o["target"], o["mode"], o["tp"])
        self.master.send_processdata()
        # A generous bound (µs): the emulator is an ordinary process beside SOEM; on a loaded
        # machine it may answer a frame tens of milliseconds late (a lost frame is then -1).
        wkc = self.master.receive_processdata(RECEIVE_TIMEOUT_US)
        self.cycles += 1
        self.wkcs.add(wkc)
        if wkc != self.master.expected_wkc:
            self.wkc_errors += 1
        time.sleep(0.001)
        return self.inputs()

    def inputs(self):
        v = struct.unpack(IN_FMT, bytes(self.master.slaves[self.servo].input))
        return {"sw": v[0], "pos": v[1], "fe": v[2], "mode": v[3], "tps": v[4],
                "tp1_pos": v[5], "tp1_neg": v[6], "tp2_pos": v[7], "tp2_neg": v[8],
                "torque": v[9]}

    def until(self, pred, max_cycles, what):
        i = None
        for _ in range(max_cycles):
            i = self.exchange()
            if pred(i):
                return i
        raise CheckFailed(f"{what}: not reached in {max_cycles} cycles, last inputs {i}")


def run(iface, spec):
    devices = spec["devices"]
    servo = spec["servo"]
    master = pysoem.Master()
    master.open(iface)
    try:
        t0 = time.monotonic()
        n = master.config_init()
        check(n == len(devices), f"config_init found {n} devices, expected {len(devices)}")
        found = []
        for pos, (s, e) in enumerate(zip(master.slaves, devices)):
            name = s.name if isinstance(s.name, str) else s.name.decode("latin-1")
            found.append({"vendor": s.man, "product": s.id, "revision": s.rev, "name": name})
            check((s.man, s.id, s.rev) == (e["vendor"], e["product"], e["revision"]),
                  f"device {pos}: identity {s.man:#x}/{s.id:#x}/{s.rev:#x}, ESI "
                  f"{e['vendor']:#x}/{e['product']:#x}/{e['revision']:#x}")
            # SOEM names a device by SII string 1 (ethercatconfig.c `ecx_siistring(.., 1)`), which
            # the SII generator fills with the ESI `Type` (as Beckhoff SIIs do), and keeps at most
            # EC_MAXNAME = 40 characters of it.
            check(name == e["type"][:40], f"device {pos}: SII name {name!r}, ESI Type {e['type']!r}")
        step("config_init", devices=found, seconds=round(time.monotonic() - t0, 3))

        s = master.slaves[servo]
        sdo = {
            "0x1000": u32(s.sdo_read(0x1000, 0)),
            "0x1018:1": u32(s.sdo_read(0x1018, 1)),
            "0x1018:2": u32(s.sdo_read(0x1018, 2)),
            "0x1018:3": u32(s.sdo_read(0x1018, 3)),
            "0x6041": u16(s.sdo_read(0x6041, 0)),
        }
        device_name = s.sdo_read(0x1008, 0).decode("latin-1")
        e = devices[servo]
        check(sdo["0x1000"] & 0xFFFF == 402, f"0x1000 device type {sdo['0x1000']:#x}: profile not 402")
        check((sdo["0x1018:1"], sdo["0x1018:2"], sdo["0x1018:3"]) ==
              (e["vendor"], e["product"], e["revision"]), f"0x1018 {sdo} differs from the ESI {e}")
        # Before the first process-data cycle the drive is NOT READY TO SWITCH ON (xxxx xxxx x0xx 0000)
        # or already SWITCH ON DISABLED (x1xx 0000) (CiA 402 §6.2 statusword).
        check(sdo["0x6041"] & 0x4F in (0x00, 0x40),
              f"0x6041 {sdo['0x6041']:#06x}: neither NOT READY TO SWITCH ON nor SWITCH ON DISABLED")
        check(device_name == e["name"], f"0x1008 device name {device_name!r}, ESI Name {e['name']!r}")
        step("sdo_read", values={k: hex(v) for k, v in sdo.items()}, device_name=device_name)

        old = u32(s.sdo_read(0x6065, 0))
        new = 123_456
        s.sdo_write(0x6065, 0, struct.pack("<I", new))
        back = u32(s.sdo_read(0x6065, 0))
        check(back == new, f"0x6065 wrote {new}, read back {back}")
        s.sdo_write(0x6065, 0, struct.pack("<I", old))
        check(u32(s.sdo_read(0x6065, 0)) == old, "0x6065 restore failed")
        step("sdo_write", index="0x6065", old=old, written=new, read_back=back)

        lo = spec["long_object"]
        data = s.sdo_read(lo["index"], lo["sub"], 1024)
        text = data.decode("latin-1")
        check(text == lo["text"], f"{lo['index']:#06x}:{lo['sub']} read {len(data)} bytes "
                                  f"{text!r}, expected {len(lo['text'])} bytes {lo['text']!r}")
        step("segmented_upload", index=hex(lo["index"]), bytes=len(data))

        ca = spec.get("complete_access")
        if ca:
            complete_access(s, ca)

        iomap = master.config_map()
        sizes = [(len(bytes(sl.output)), len(bytes(sl.input))) for sl in master.slaves]
        for pos, ((o, i), e) in enumerate(zip(sizes, devices)):
            want = ((e["out_bits"] + 7) // 8, (e["in_bits"] + 7) // 8)
            check((o, i) == want, f"device {pos}: image (out, in) = {(o, i)} bytes, ESI {want}")
        step("config_map", iomap=iomap, sizes=sizes, expected_wkc=master.expected_wkc)

        dc = bool(master.config_dc())
        if dc:
            s.dc_sync(True, 1_000_000)
        step("config_dc", dc=dc)

        check(master.state_check(pysoem.SAFEOP_STATE, 2_000_000) == pysoem.SAFEOP_STATE,
              "not all devices reached SAFE-OP: " +
              ", ".join(f"{p}: {sl.state:#x} AL {sl.al_status:#06x}"
                        for p, sl in enumerate(master.slaves)))
        step("safe_op")

        cyc = Cyclic(master, servo)
        first = cyc.exchange()
        cyc.out["target"] = first["pos"]
        master.state = pysoem.OP_STATE
        master.write_state()
        for _ in range(200):
            cyc.exchange()
            if master.state_check(pysoem.OP_STATE, 1_000) == pysoem.OP_STATE:
                break
        check(master.state_check(pysoem.OP_STATE, 50_000) == pysoem.OP_STATE,
              "not all devices reached OP: " +
              ", ".join(f"{p}: {sl.state:#x} AL {sl.al_status:#06x}"
                        for p, sl in enumerate(master.slaves)))
        for _ in range(20):
            cyc.exchange()
        # Every cycle, also those in SAFE-OP before OP was reached: the emulated ESCs count the
        # LRW +1 (inputs read) +2 (outputs written) per device with process data.
        check(cyc.wkcs == {master.expected_wkc},
              f"working counters {sorted(cyc.wkcs)}, expected {master.expected_wkc}")
        step("op", cycles=cyc.cycles, expected_wkc=master.expected_wkc,
             wkcs=sorted(cyc.wkcs), wkc_errors=cyc.wkc_errors)

        # CiA 402 enable in CSP: target = actual position throughout.
        i = cyc.inputs()
        trace = [hex(i["sw"])]
        if i["sw"] & 0x4F == 0x08:  # FAULT: reset on a rising edge of bit 7
            cyc.out["cw"] = 0x80
            i = cyc.until(lambda i: i["sw"] & 0x4F == 0x40, 50, "fault reset")
        for cw, mask, want, name in [(0x06, 0x6F, 0x21, "READY TO SWITCH ON"),
                                     (0x07, 0x6F, 0x23, "SWITCHED ON"),
                                     (0x0F, 0x6F, 0x27, "OPERATION ENABLED")]:
            cyc.out["cw"] = cw
            cyc.out["target"] = i["pos"]
            i = cyc.until(lambda i, m=mask, w=want: i["sw"] & m == w, 100,
                          f"controlword {cw:#x} -> {name}")
            trace.append(hex(i["sw"]))
        check(i["mode"] == CSP, f"0x6061 modes display {i['mode']}, expected {CSP} (CSP)")
        for _ in range(10):
            i = cyc.exchange()
            check(i["sw"] & 0x6F == 0x27, f"left OPERATION ENABLED: statusword {i['sw']:#06x}")
        step("cia402_enable", statuswords=trace, position=i["pos"])

        if spec.get("probe"):
            probe_latch(cyc, spec["probe"])

        check(cyc.wkc_errors == 0,
              f"{cyc.wkc_errors} cycles with a wrong working counter "
              f"(seen {sorted(cyc.wkcs)}, expected {master.expected_wkc})")
        cyc.out["cw"] = 0x06  # shut down
        for _ in range(5):
            cyc.exchange()
        master.state = pysoem.INIT_STATE
        master.write_state()
        RESULT.update(ok=True, cycles=cyc.cycles, expected_wkc=master.expected_wkc,
                      wkc_errors=cyc.wkc_errors, seconds=round(time.monotonic() - t0, 3))
    finally:
        master.close()


def complete_access(s, ca):
    """SDO complete access (ETG.1000.6 §5.6.2.1.2, from sub-index 0: sub-index 0 as 16 bits, then
    the entries), upload and download, on the PDO assignment and a PDO mapping of the servo in
    PRE-OP, against the ESI's default assignment / mapping (ca = {"assign": {hex index: [pdo,
    ...]}, "mapping": {hex index: [[index, sub, bits], ...]}})."""
    seen = {}
    for idx, pdos in ca["assign"].items():
        index = int(idx, 16)
        img = s.sdo_read(index, 0, ca=True)
        n = img[0]
        got = [struct.unpack_from("<H", img, 2 + 2 * k)[0] for k in range(n)]
        check(got == pdos, f"CA upload {idx} = {img.hex()}, ESI default assignment {pdos}")
        # Written back in one request, as TwinCAT and SOEM configure PDOs.
        s.sdo_write(index, 0, img, ca=True)
        again = s.sdo_read(index, 0, ca=True)
        check(again == img, f"CA download {idx} {img.hex()}, then reads {again.hex()}")
        seen[idx] = img.hex()
    for idx, entries in ca["mapping"].items():
        index = int(idx, 16)
        img = s.sdo_read(index, 0, ca=True)
        n = img[0]
        got = [struct.unpack_from("<I", img, 2 + 4 * k)[0] for k in range(n)]
        want = [(i << 16) | (sub << 8) | bits for i, sub, bits in entries]
        check(got == want, f"CA upload {idx}: {[hex(v) for v in got]}, ESI {[hex(v) for v in want]}")
        body = img[: 2 + 4 * n]
        s.sdo_write(index, 0, body, ca=True)  # a normal (not expedited) download
        again = s.sdo_read(index, 0, ca=True)
        check(again[: len(body)] == body, f"CA download {idx}, then reads {again.hex()}")
        seen[idx] = body.hex()
    step("complete_access", objects=seen)


def probe_latch(cyc, p):
    """Touch probe 1, positive edge, while the axis ramps across the probe surface."""
    i = cyc.inputs()
    # 0x60B8: bit 0 enable TP1, bit 1 continuous (0 = first event), bits 2/3 trigger source
    # (0 = TP input 1), bit 4 positive edge.
    cyc.out["tp"] = 0x0011
    i = cyc.until(lambda i: i["tps"] & 0x0001, 50, "touch probe 1 enabled (0x60B9 bit 0)")
    check(not i["tps"] & 0x0002, f"0x60B9 {i['tps']:#06x}: bit 1 set before the ramp")
    start, end = p["start_inc"], p["end_inc"]
    # Ramp to the start (not crossing the surface), settle, then ramp across the surface; the
    # target moves step_inc increments per cycle.
    step_inc = p.get("step_inc", 100)
    for target in ramp(i["pos"], start, step_inc):
        cyc.out["target"] = target
        i = cyc.exchange()
    i = cyc.until(lambda i: abs(i["pos"] - start) <= 2, 2000, f"settled at {start}")
    check(not i["tps"] & 0x0002, f"0x60B9 {i['tps']:#06x}: latched before crossing")
    ts = p.get("timestamp")
    if ts is not None:
        before = timestamps(cyc, ts)
        check(before == (0, 0), f"timestamp terminal: channel 1 latch {before} before crossing")
        # The reference clock's DC system time SOEM read with the last frame (FRMW 0x0910).
        dc_before = cyc.master.dc_time
    latched = None
    for target in ramp(start, end, step_inc):
        cyc.out["target"] = target
        i = cyc.exchange()
        if i["tps"] & 0x0002 and latched is None:
            latched = i
    i = cyc.until(lambda i: abs(i["pos"] - end) <= 2, 2000, f"settled at {end}")
    if latched is None and i["tps"] & 0x0002:
        latched = i
    check(latched is not None, f"0x60B9 {i['tps']:#06x}: bit 1 (TP1 positive edge stored) "
                               f"never set crossing {p['position_inc']} from {start} to {end}")
    check(abs(i["tp1_pos"] - p["position_inc"]) <= 1,
          f"0x60BA = {i['tp1_pos']}, surface at {p['position_inc']} increments (± 1)")
    info = {}
    if ts is not None:
        # The same probe edge, stamped by the EL1252-kind terminal in DC time (channel 1 of
        # 17 bytes: status u8, rising-edge time u64, falling-edge time u64; channel 2 unwired).
        rising, falling = timestamps(cyc, ts)
        check(rising > 0, "timestamp terminal: no rising-edge time on channel 1")
        ch2 = bytes(cyc.master.slaves[ts].input)[17:34]
        check(ch2 == bytes(17), f"timestamp terminal: channel 2 {ch2.hex()} (not wired)")
        info = {"ts_rising": rising, "ts_falling": falling,
                "dc_before": dc_before, "dc_after": cyc.master.dc_time}
    step("touch_probe", status=hex(i["tps"]), tp1_pos=i["tp1_pos"],
         surface_inc=p["position_inc"], cycles=cyc.cycles, **info)


def timestamps(cyc, pos):
    b = bytes(cyc.master.slaves[pos].input)
    return (struct.unpack_from("<Q", b, 1)[0], struct.unpack_from("<Q", b, 9)[0])


def ramp(a, b, step_inc):
    n = max(1, abs(b - a) // step_inc)
    return [a + (b - a) * k // n for k in range(1, n + 1)]


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    try:
        run(sys.argv[1], json.loads(sys.argv[2]))
    except CheckFailed as e:
        RESULT["error"] = str(e)
    except Exception as e:  # pysoem errors (SdoError, WkcError, ...) and the like
        RESULT["error"] = f"{type(e).__name__}: {e}"
    print("PYSOEM_RESULT " + json.dumps(RESULT), flush=True)
    if not RESULT["ok"]:
        print(f"interop.py: FAILED: {RESULT.get('error')}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
