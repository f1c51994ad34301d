#!/usr/bin/env python3
"""python-canopen 2.4.1 as CANopen master against `fieldprobe sim canopen` (tests/system/canopen_interop.rs).

  canopen_master.py GROUP PORT NODE_ID RAMP_END_INC   (or socketcan:IF 0 NODE_ID RAMP_END_INC)

Talks to one emulated CiA 402 node over python-can's udp_multicast bus and prints ONE JSON line
with what it observed (the Rust test judges it; this script asserts nothing about values):
boot-up after an NMT reset, heartbeat states, SDO expedited / segmented / block transfers, an
abort code, a PDO remap read back, the CiA 402 state reached with BaseNode402, and the touch
probe status / latch after ramping the target position 0 -> RAMP_END_INC in lockstep with SYNC.

The object dictionary of the remote node is written out here (only what the master touches),
so the master does not share an EDS or any code with the emulator.

Self-echo (notes canopen.md §3.3): python-can's udp_multicast bus hears its own frames, so
the master unsubscribes its own RPDO COB-IDs after BaseNode402 set up its PDO pointers;
otherwise PdoMap.on_message sees the echoes, marks the RPDO periodic and the controlword
setter stops transmitting.
"""
import json
import sys
import threading
import time
import traceback

import canopen
from canopen import objectdictionary as odm
from canopen.sdo.exceptions import SdoAbortedError

U8, U16, U32 = odm.UNSIGNED8, odm.UNSIGNED16, odm.UNSIGNED32
I8, I32 = odm.INTEGER8, odm.INTEGER32


def var(name, index, sub, data_type, access="rw"):
    v = odm.ODVariable(name, index, sub)
    v.data_type = data_type
    v.access_type = access
    return v


def record(name, index, members):
    r = odm.ODRecord(name, index)
    for sub, (n, dt, acc) in enumerate(members):
        r.add_member(var(n, index, sub, dt, acc))
    return r


def remote_od():
    """CiA 301 / CiA 402 objects the master uses (types from CiA 301 / CiA 402)."""
    od = odm.ObjectDictionary()
    od.add_object(var("Device type", 0x1000, 0, U32, "ro"))
    od.add_object(var("Error register", 0x1001, 0, U8, "ro"))
    errors = odm.ODArray("Pre-defined error field", 0x1003)
    errors.add_member(var("Number of errors", 0x1003, 0, U8, "rw"))
    for k in range(1, 9):
        errors.add_member(var(f"Standard error field {k}", 0x1003, k, U32, "ro"))
    od.add_object(errors)
    od.add_object(var("Device name", 0x1008, 0, odm.VISIBLE_STRING, "ro"))
    od.add_object(var("Producer heartbeat time", 0x1017, 0, U16))
    for k in range(4):
        od.add_object(record(f"RPDO{k + 1} comm", 0x1400 + k,
                             [("n", U8, "ro"), ("COB-ID", U32, "rw"), ("type", U8, "rw")]))
        od.add_object(record(f"RPDO{k + 1} map", 0x1600 + k,
                             [("n", U8, "rw")] + [(f"m{j}", U32, "rw") for j in range(1, 9)]))
        od.add_object(record(f"TPDO{k + 1} comm", 0x1800 + k,
                             [("n", U8, "ro"), ("COB-ID", U32, "rw"), ("type", U8, "rw")]))
        od.add_object(record(f"TPDO{k + 1} map", 0x1A00 + k,
                             [("n", U8, "rw")] + [(f"m{j}", U32, "rw") for j in range(1, 9)]))
    for index, name, dt, acc in [
        (0x6040, "Controlword", U16, "rw"),
        (0x6041, "Statusword", U16, "ro"),
        (0x6060, "Modes of operation", I8, "rw"),
        (0x6061, "Modes of operation display", I8, "ro"),
        (0x6064, "Position actual value", I32, "ro"),
        (0x6065, "Following error window", U32, "rw"),
        (0x6066, "Following error timeout", U16, "rw"),
        (0x607A, "Target position", I32, "rw"),
        (0x60B8, "Touch probe function", U16, "rw"),
        (0x60B9, "Touch probe status", U16, "ro"),
        (0x60BA, "Touch probe 1 positive edge", I32, "ro"),
    ]:
        od.add_object(var(name, index, 0, dt, acc))
    return od


class Frames:
    """Every frame of one COB-ID range, with the time seen (for boot-up and heartbeat)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.items = []

    def __call__(self, can_id, data, timestamp):
        with self.lock:
            self.items.append((can_id, bytes(data), time.monotonic()))

    def wait_for(self, pred, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self.lock:
                hit = [f for f in self.items if pred(f)]
            if hit:
                return hit[0]
            time.sleep(0.01)
        return None


def lockstep(net, tpdo, timeout=1.0):
    """Send SYNC and wait for `tpdo` of that SYNC (no race: the lock is held until wait())."""
    with tpdo.receive_condition:
        tpdo.is_received = False
        net.sync.transmit()
        ok = tpdo.receive_condition.wait_for(lambda: tpdo.is_received, timeout)
    return ok


def connect(net, group, port):
    """GROUP PORT of python-can's udp_multicast bus, or `socketcan:IF` (PORT ignored)."""
    if group.startswith("socketcan:"):
        net.connect(interface="socketcan", channel=group[len("socketcan:"):])
    else:
        net.connect(interface="udp_multicast", channel=group, port=port)


def main(argv):
    group, port, node_id, ramp_end = argv[1], int(argv[2]), int(argv[3]), int(argv[4])
    out = {"steps": []}
    net = canopen.Network()
    connect(net, group, port)
    try:
        run(net, node_id, ramp_end, out)
        out["ok"] = True
    except Exception as e:  # report, the Rust side decides
        out["ok"] = False
        out["error"] = f"{type(e).__name__}: {e}"
        out["traceback"] = traceback.format_exc()
    finally:
        try:
            net.sync.stop()
        except Exception:
            pass
        net.disconnect()
    print(json.dumps(out), flush=True)


def run(net, node_id, ramp_end, out):
    step = out["steps"].append
    hb = Frames()
    net.subscribe(0x700 + node_id, hb)
    node = canopen.BaseNode402(node_id, remote_od())
    net.add_node(node)

    # --- NMT reset -> boot-up, then heartbeats in PRE-OPERATIONAL
    t_reset = time.monotonic()
    node.nmt.send_command(0x81)
    boot = hb.wait_for(lambda f: f[2] >= t_reset and f[1] == b"\x00", 5.0)
    out["bootup"] = boot is not None
    pre = hb.wait_for(lambda f: f[2] >= t_reset and f[1] == b"\x7f", 5.0)
    out["heartbeat_preop"] = pre[1][0] if pre else None
    step("nmt reset / boot-up")

    # --- SDO: expedited and segmented upload, expedited and segmented download, block upload
    sdo = node.sdo
    out["device_type"] = sdo[0x1000].raw                       # expedited upload
    out["device_name"] = sdo.upload(0x1008, 0).decode("ascii", "replace")  # segmented
    sdo[0x6066].raw = 25                                       # expedited download
    out["readback_6066"] = sdo[0x6066].raw
    sdo.download(0x6065, 0, (123456).to_bytes(4, "little"), force_segment=True)
    out["readback_6065"] = int.from_bytes(sdo.upload(0x6065, 0), "little")
    with sdo.open(0x2000, 0, "rb", block_transfer=True) as f:  # block upload
        block = f.read()
    out["block_len"] = len(block)
    out["block_hex"] = block.hex()
    out["block_equals_segmented"] = block == sdo.upload(0x2000, 0)
    try:
        sdo.upload(0x5FFF, 0)
        out["abort_missing"] = None
    except SdoAbortedError as e:
        out["abort_missing"] = e.code
    step("sdo")

    # --- PDO remap (PRE-OPERATIONAL), CiA 301 procedure as python-canopen does it
    node.tpdo.read()
    node.rpdo.read()
    r1, r2 = node.rpdo[1], node.rpdo[2]
    r1.clear(); r1.add_variable(0x6040); r1.add_variable(0x607A)
    r2.clear(); r2.add_variable(0x60B8); r2.add_variable(0x6060)
    for m, cob in ((r1, 0x200), (r2, 0x300)):
        m.cob_id = cob + node_id
        m.trans_type = 255  # event-driven: BaseNode402's controlword setter transmits
        m.enabled = True
    for k in (3, 4):
        node.rpdo[k].clear()
        node.rpdo[k].enabled = False
    t1, t2 = node.tpdo[1], node.tpdo[2]
    t1.clear(); t1.add_variable(0x6041); t1.add_variable(0x6064)
    t2.clear(); t2.add_variable(0x60B9); t2.add_variable(0x60BA)
    for m, cob in ((t1, 0x180), (t2, 0x280)):
        m.cob_id = cob + node_id
        m.trans_type = 1  # every SYNC
        m.enabled = True
    for k in (3, 4):
        node.tpdo[k].clear()
        node.tpdo[k].enabled = False
    node.rpdo.save()
    node.tpdo.save()
    out["map_readback"] = {
        "1600": [sdo[0x1600][j].raw for j in range(0, 3)],
        "1601": [sdo[0x1601][j].raw for j in range(0, 3)],
        "1a00": [sdo[0x1A00][j].raw for j in range(0, 3)],
        "1a01": [sdo[0x1A01][j].raw for j in range(0, 3)],
        "1402_cob": sdo[0x1402][1].raw,
        "1802_cob": sdo[0x1802][1].raw,
    }
    step("pdo remap")

    node.setup_402_state_machine(read_pdos=False)
    for m in (r1, r2):
        net.unsubscribe(m.cob_id)  # own RPDO echoes (notes §3.3)

    # --- NMT start -> heartbeat 0x05
    t_start = time.monotonic()
    node.nmt.state = "OPERATIONAL"
    op = hb.wait_for(lambda f: f[2] >= t_start and f[1] == b"\x05", 5.0)
    out["heartbeat_op"] = op[1][0] if op else None
    step("nmt start")

    # --- CiA 402 state machine with BaseNode402 (SYNC running)
    target, opmode, tp_func = r1[1], r2[1], r2[0]
    target.raw = 0
    opmode.raw = 8  # cyclic synchronous position
    tp_func.raw = 0
    r1.transmit()
    r2.transmit()
    net.sync.start(0.005)
    time.sleep(0.05)
    node.state = "OPERATION ENABLED"
    out["state"] = node.state
    net.sync.stop()
    time.sleep(0.05)
    step("operation enabled")

    # --- arm touch probe 1 (enable, first event, TP1 input, positive edge) in the RPDO
    tp_func.raw = 0x0011
    r2.transmit()
    # The RPDO takes effect at a SYNC and the status comes with a later one (CiA 301 sync
    # PDOs); in a slow guest a TPDO can miss lockstep's wait, so up to 20 SYNCs.
    for _ in range(20):
        lockstep(net, t2)
        if t2[0].raw & 0x0001:
            break
    out["tp_status_armed"] = t2[0].raw
    step("probe armed")

    # --- ramp the target position across the surface, one step per SYNC
    inc = 200
    pos = 0
    latched_at = None
    positions = []
    timeouts = 0
    n = 0
    while n < 5000:
        n += 1
        pos = min(pos + inc, ramp_end)
        target.raw = pos
        r1.transmit()
        if not lockstep(net, t2):
            timeouts += 1
            if timeouts > 20:
                break
        positions.append(t1[1].raw)
        if latched_at is None and t2[0].raw & 0x0002:
            latched_at = n
        if pos == ramp_end and latched_at is not None and n > latched_at + 5:
            break
    out["ramp_syncs"] = n
    out["ramp_timeouts"] = timeouts
    out["latched_at_sync"] = latched_at
    out["position_first"] = positions[0] if positions else None
    out["position_last"] = positions[-1] if positions else None
    out["tp_status_tpdo"] = t2[0].raw
    out["tp_latch_tpdo"] = t2[1].raw
    out["tp_status_sdo"] = sdo[0x60B9].raw
    out["tp_latch_sdo"] = sdo[0x60BA].raw
    step("ramp")

    errors_after_fault(net, node, sdo, r1, t1, out)
    step("fault and fault reset")

    node.nmt.state = "PRE-OPERATIONAL"


def errors_after_fault(net, node, sdo, r1, t1, out):
    """CiA 301 error objects and EMCY: 0x1001 / 0x1003 before a fault, a following error
    provoked (window 0x6065 = 10 increments, the target running away), 0x1001 / 0x1003 and
    python-canopen's EMCY consumer in FAULT, then a fault reset by controlword bit 7 and the
    EMCY consumer again; 0x1003 cleared by writing 0, another value refused."""
    emcys = Frames()
    net.subscribe(0x80 + node.id, emcys)  # raw EMCY frames, besides node.emcy's own view
    out["err_1001_before"] = sdo[0x1001].raw
    out["err_1003_0_before"] = sdo[0x1003][0].raw
    sdo[0x6065].raw = 10  # following error window, increments
    control, target = r1[0], r1[1]
    pos = target.raw
    faulted = False
    for _ in range(200):
        pos += 5000
        target.raw = pos
        r1.transmit()
        lockstep(net, t1)
        if t1[0].raw & 0x4F == 0x08:  # CiA 402 FAULT
            faulted = True
            break
    out["faulted"] = faulted
    end = time.monotonic() + 2.0  # the EMCY may come before or after the TPDO showing FAULT
    while time.monotonic() < end and not any(e.code == 0x8611 for e in node.emcy.log):
        time.sleep(0.02)
    out["emcy_log_in_fault"] = [e.code for e in node.emcy.log]
    out["emcy_active_in_fault"] = [e.code for e in node.emcy.active]
    out["err_1001_in_fault"] = sdo[0x1001].raw
    out["err_1003_0_in_fault"] = sdo[0x1003][0].raw
    out["err_1003_1_in_fault"] = sdo[0x1003][1].raw
    # Fault reset: controlword 0, then 0x80 (rising edge of bit 7), in the event-driven RPDO1.
    t_reset = time.monotonic()
    for cw in (0x00, 0x80):
        control.raw = cw
        r1.transmit()
        time.sleep(0.05)
    end = time.monotonic() + 3.0
    while time.monotonic() < end and (node.emcy.active or sdo[0x6041].raw & 0x4F == 0x08):
        time.sleep(0.02)
    out["statusword_after_reset"] = sdo[0x6041].raw
    out["emcy_active_after_reset"] = [e.code for e in node.emcy.active]
    with emcys.lock:
        out["emcy_frames"] = [d.hex() for (_, d, _) in emcys.items]
        out["emcy_frames_after_reset"] = [d.hex() for (_, d, t) in emcys.items if t >= t_reset]
    out["err_1001_after_reset"] = sdo[0x1001].raw
    out["err_1003_0_after_reset"] = sdo[0x1003][0].raw
    out["err_1003_1_after_reset"] = sdo[0x1003][1].raw
    try:
        sdo[0x1003][0].raw = 1
        out["err_1003_write_1"] = None
    except SdoAbortedError as e:
        out["err_1003_write_1"] = e.code
    sdo[0x1003][0].raw = 0
    out["err_1003_0_cleared"] = sdo[0x1003][0].raw
    try:
        sdo[0x1003][1].raw
        out["err_1003_1_cleared"] = None
    except SdoAbortedError as e:
        out["err_1003_1_cleared"] = e.code


if __name__ == "__main__":
    main(sys.argv)
