#!/usr/bin/env python3
"""ebpfcat (PyPI `ebpfcat` 1.0.0, a pure-Python EtherCAT master) against
`fieldprobe sim ethercat`.

    ebpfcat_drive.py IFACE SPEC_JSON

Run by tests/system/independent_masters.rs inside a private user + network namespace, with the SPEC of
tests/masters/kickcat_drive.py (computed from the ESI files by the Rust test).

ebpfcat has two process-data paths. The fast one (`FastEtherCat`, `FastSyncGroup`) compiles the
cycle into an XDP program and loads it with the bpf() system call; that needs CAP_BPF /
CAP_SYS_ADMIN in the *initial* user namespace, which a process in an unprivileged user
namespace (`unshare -rn`, how our tests get a private network) does not have: bpf() fails with
EPERM there (and `kernel.unprivileged_bpf_disabled` is 2 on the CI machine). This script probes
exactly that (`bpf(BPF_MAP_CREATE)`) and records the errno. The plain path (`SimpleEtherCat`
on an AF_PACKET socket, `SyncGroup` running the cycle in Python) needs no eBPF and is what runs
here.

Steps: count the devices; initialise each (`Terminal.initialize`: station address, SII, sync
managers); on every CoE device identity 0x1018 and 0x1008 over SDO, an expedited write of 0x6060
= 8, complete access (ebpfcat's `sdo_read(index)` without a sub-index: CA from sub-index 1) of
0x1C12 / 0x1C13 = the ESI's default assignment, and SDO Information (`read_object_entry` of
0x6041 / 0x1018:1 names); then on the drives (an `EBPFTerminal` per device whose process data
are the ESI's default mapping, a `Device` running the CiA 402 enable, the CSP ramp across the
probe surface and the touch-probe arming in its `update()` each cycle) through a `SyncGroup`:
SAFE-OP, OP, enable, CSP, latch 0x60B9 / 0x60BA.

Known ebpfcat 1.0.0 defect tested around: `sdo_write(data, index)` with complete access (no
sub-index) compares the answer's sub-index with None and always raises after the device
accepted the download, so the CA download is checked by reading the object back.

Prints `EBPFCAT_RESULT {json}`; exits 0 when every check passed.
"""

import asyncio
import json
import struct
import sys
import traceback

from ebpfcat import bpf
from ebpfcat.ebpfcat import (Device, EBPFTerminal, PacketDesc, SimpleEtherCat, SyncGroup,
                             TerminalVar)
from ebpfcat.ethercat import EtherCatError, MachineState, SyncManager, Terminal

from common import RESULT, CheckFailed, check, step, FMT, layout


def bpf_probe():
    """errno of bpf(BPF_MAP_CREATE) (0: allowed)."""
    try:
        fd = bpf.create_map(bpf.MapType.ARRAY, 4, 4, 1)
    except OSError as e:
        return e.errno
    import os
    os.close(fd)
    return 0


async def io(what, coro, timeout=5.0):
    """An ebpfcat request, bounded (ebpfcat polls the mailbox without a time limit)."""
    try:
        return await asyncio.wait_for(coro, timeout)
    except asyncio.TimeoutError:
        raise CheckFailed(f"{what}: no answer within {timeout} s") from None


def drive_terminal(e):
    """An EBPFTerminal class whose process data are the device's default mapping."""
    rx, tx = layout(e["rx"]), layout(e["tx"])
    attrs = {}
    for name, index, lay, sm in (
            ("controlword", 0x6040, rx, SyncManager.OUT), ("target", 0x607A, rx, SyncManager.OUT),
            ("mode", 0x6060, rx, SyncManager.OUT), ("tp_function", 0x60B8, rx, SyncManager.OUT),
            ("max_torque", 0x6072, rx, SyncManager.OUT),
            ("statusword", 0x6041, tx, SyncManager.IN), ("actual", 0x6064, tx, SyncManager.IN),
            ("tp_status", 0x60B9, tx, SyncManager.IN), ("tp1_pos", 0x60BA, tx, SyncManager.IN)):
        if index in lay:
            off, bits = lay[index]
            attrs[name] = PacketDesc(sm, off, FMT[bits].upper() if name in (
                "controlword", "statusword", "tp_function", "tp_status", "max_torque")
                else FMT[bits])
    return type(f"Drive{e['pos']}", (EBPFTerminal,), attrs)


class Axis(Device):
    """CiA 402 enable (6 -> 7 -> 15), then a CSP ramp start -> end, all in update()."""
    controlword = TerminalVar()
    target = TerminalVar()
    statusword = TerminalVar()
    actual = TerminalVar()
    mode = TerminalVar()
    max_torque = TerminalVar()
    tp_function = TerminalVar()

    def __init__(self, terminal, e, step_inc):
        super().__init__()
        self.e, self.step_inc = e, step_inc
        self.terminal = terminal
        self.controlword = terminal.controlword
        self.target = terminal.target
        self.statusword = terminal.statusword
        self.actual = terminal.actual
        # Where the process image carries them, 0x6060 (CSP = 8) and 0x6072 (max torque,
        # MyActuator maps it) come from the outputs, not from the SDO writes before.
        self.has_mode = hasattr(type(terminal), "mode")
        self.has_torque = hasattr(type(terminal), "max_torque")
        if self.has_mode:
            self.mode = terminal.mode
        if self.has_torque:
            self.max_torque = terminal.max_torque
        # 0x60B8 = 0x0011 (TP1 enabled, first event, TP1 input, rising edge) in the outputs
        # where it is mapped (else written by SDO before the cycle starts).
        self.has_tp = e["touch_probe"] and hasattr(type(terminal), "tp_function")
        if self.has_tp:
            self.tp_function = terminal.tp_function
        self.phase = "enable"
        self.cw = 6
        self.goal = None
        self.t = None
        self.trace = []
        self.done = asyncio.get_event_loop().create_future()

    def update(self):
        sw = self.statusword
        pos = self.actual
        if self.t is None:
            self.t = pos
        if self.phase == "enable":
            want = {6: 0x21, 7: 0x23, 15: 0x27}[self.cw]
            if sw & 0x6F == want:
                self.trace.append(sw)
                if self.cw == 15:
                    self.phase, self.goal = "start", self.e["start_inc"]
                else:
                    self.cw = {6: 7, 7: 15}[self.cw]
        elif self.phase in ("start", "end"):
            if self.t != self.goal:
                d = self.goal - self.t
                self.t += max(-self.step_inc, min(self.step_inc, d))
            elif abs(pos - self.goal) <= 1:
                if self.phase == "start":
                    self.phase, self.goal = "end", self.e["end_inc"]
                else:
                    self.phase = "done"
                    if not self.done.done():
                        self.done.set_result(pos)
        self.controlword = self.cw
        self.target = self.t
        if self.has_mode:
            self.mode = 8
        if self.has_torque:
            self.max_torque = 3000
        if self.has_tp:
            self.tp_function = 0x0011

    def get_terminals(self):
        return {self.terminal: True}


async def run(iface, spec):
    devices = spec["devices"]
    RESULT["bpf_errno"] = bpf_probe()
    ec = SimpleEtherCat(iface)
    await ec.connect()
    n = await ec.count()
    check(n == len(devices), f"count: {n} devices, expected {len(devices)}")
    step("scan", devices=n)

    terminals = []
    for e in devices:
        cls = drive_terminal(e) if e["drive"] else Terminal
        t = cls(ec)
        await io(f"device {e['pos']}: initialize(-e['pos'], 1000 + e['pos'])", t.initialize(-e["pos"], 1000 + e["pos"]))
        if not e["drive"] and e["coe"] and not e["one_buffer_process_data"]:
            # A plain Terminal stays in INIT after initialize(); the mailbox works from PRE-OP
            # (ETG.1000.6: the mailbox sync managers are enabled in INIT -> PRE-OP).
            await io(f"device {e['pos']}: PRE-OP", t.to_operational(MachineState.PRE_OPERATIONAL))
        terminals.append(t)

    for e, t in zip(devices, terminals):
        if not e["coe"] or e["one_buffer_process_data"]:
            # ebpfcat 1.0.0 defect: Terminal.parse_sync_managers tells the sync managers apart by
            # the operation mode of their control byte alone, so a process-data SM in one-buffer
            # (mailbox) mode, which the AX2000-B110 ESI declares for its inputs (ControlByte
            # 0x22), is taken for the read mailbox and ebpfcat polls the wrong memory forever.
            continue
        rec = {"pos": e["pos"]}
        ident = []
        for k in (1, 2, 3):
            ident.append(struct.unpack("<I", (await io(f"device {e['pos']}: sdo_read(0x1018, k)", t.sdo_read(0x1018, k)))[:4])[0])
        ident = tuple(ident)
        check(ident == (e["vendor"], e["product"], e["revision"]),
              f"device {e['pos']}: 0x1018 {ident}")
        rec["identity"] = list(ident)
        if e["device_name"] is not None:
            name = (await io(f"device {e['pos']}: sdo_read(0x1008, 0)", t.sdo_read(0x1008, 0))).rstrip(b"\0").decode("latin-1")
            check(name == e["device_name"], f"device {e['pos']}: 0x1008 {name!r}, ESI {e['device_name']!r}")
            rec["device_name"] = name
        if e["drive"]:
            await io(f"device {e['pos']}: sdo_write(struct.pack('<b', 8), 0x6060, 0)", t.sdo_write(struct.pack("<b", 8), 0x6060, 0))
            back = struct.unpack("<b", (await io(f"device {e['pos']}: sdo_read(0x6060, 0)", t.sdo_read(0x6060, 0)))[:1])[0]
            check(back == 8, f"device {e['pos']}: 0x6060 read back {back}")
        if e["complete_access"]:
            for assign, pdos in ((0x1C12, e["rx_pdos"]), (0x1C13, e["tx_pdos"])):
                img = await io(f"device {e['pos']}: sdo_read(assign)", t.sdo_read(assign))  # CA from sub-index 1: the entries only
                got = [v for (v,) in struct.iter_unpack("<H", img[: 2 * len(pdos)])]
                check(got == pdos, f"device {e['pos']}: CA {assign:#06x} = {img.hex()}, ESI {pdos}")
                try:
                    await io(f"device {e['pos']}: sdo_write(img, assign)", t.sdo_write(img, assign))  # CA download from sub-index 1
                except EtherCatError as err:  # ebpfcat 1.0.0: sub-index compared with None
                    rec[f"ca_write_{assign:04x}_raised"] = str(err)
                again = await io(f"device {e['pos']}: sdo_read(assign)", t.sdo_read(assign))
                check(again == img, f"device {e['pos']}: after CA download {assign:#06x}: {again.hex()}")
                rec[f"ca_{assign:04x}"] = img.hex()
        if e["sdo_info"] and "0x6041" in e["object_names"]:
            oe = await io(f"device {e['pos']}: read_object_entry(0x6041, 0)", t.read_object_entry(0x6041, 0))
            rec["sdo_info_6041"] = oe.name
            check(oe.bitLength == 16, f"device {e['pos']}: 0x6041 entry of {oe.bitLength} bits")
        step("sdo", **rec)

    drives = [(e, t) for e, t in zip(devices, terminals) if e["drive"]]
    axes = [Axis(t, e, spec["step_inc"]) for e, t in drives]
    for e, t in drives:  # CSP before the cycle starts; the touch probe by SDO
        if e["touch_probe"]:
            await io(f"device {e['pos']}: sdo_write(struct.pack('<H', 0x0011), 0x60B8, 0)", t.sdo_write(struct.pack("<H", 0x0011), 0x60B8, 0))
    sg = SyncGroup(ec, axes)
    sg.cycletime = 0.002
    task = sg.start()
    try:
        finals = await asyncio.wait_for(asyncio.gather(*[a.done for a in axes]), 30)
    except asyncio.TimeoutError:
        why = repr(task.exception()) if task.done() else "sync group running"
        raise CheckFailed(f"CSP ramp not done in 30 s ({why}): " + ", ".join(
            f"{a.e['pos']}: {a.phase} cw {a.cw} target {a.t}" for a in axes)) from None
    finally:
        task.cancel()
        try:
            await task
        except (asyncio.CancelledError, Exception):
            pass
    step("csp", actual={a.e["pos"]: p for a, p in zip(axes, finals)},
         statuswords={a.e["pos"]: a.trace for a in axes})

    latches = {}
    for e, t in drives:
        if not e["touch_probe"]:
            continue
        st = struct.unpack("<H", (await io(f"device {e['pos']}: sdo_read(0x60B9, 0)", t.sdo_read(0x60B9, 0)))[:2])[0]
        pos = struct.unpack("<i", (await io(f"device {e['pos']}: sdo_read(0x60BA, 0)", t.sdo_read(0x60BA, 0)))[:4])[0]
        check(st & 0x03 == 0x03, f"device {e['pos']}: 0x60B9 {st:#06x}")
        latches[e["pos"]] = {"status": st, "tp1_pos": pos, "surface": e["probe_inc"]}
    step("touch_probe", latches=latches)


def main():
    iface, spec = sys.argv[1], json.loads(sys.argv[2])
    try:
        asyncio.run(asyncio.wait_for(run(iface, spec), 50))
        RESULT["ok"] = True
    except BaseException as e:  # reported to the Rust test, which fails with it
        RESULT["error"] = f"{type(e).__name__}: {e}"
        RESULT["trace"] = traceback.format_exc()
    print("EBPFCAT_RESULT " + json.dumps(RESULT), flush=True)
    sys.exit(0 if RESULT["ok"] else 1)


if __name__ == "__main__":
    main()
