#!/usr/bin/env python3
"""An independent CiA 402 node on durand (PyPI, a pure-Python CiA 301 node stack) for our
master (tests/system/canopen_independent_node.rs).

  durand_cia402_node.py --channel GROUP --port PORT --node 1 --surface 1=1000000 --seconds 90

durand gives the CiA 301 node: NMT slave with boot-up, SDO server, RPDOs / TPDOs with the
mapping the master writes, SYNC consumer, heartbeat producer (0x1017), EMCY producer and
0x1001. The CiA 402 behaviour is written here from CiA 402 itself (IEC 61800-7-201), not from
fieldprobe's emulator:

* power state machine (CiA 402 §6.2 figure "state machine", §6.3 controlword command coding,
  statusword coding): NOT READY TO SWITCH ON -> (1) SWITCH ON DISABLED -> (2) READY TO SWITCH ON
  -> (3) SWITCHED ON -> (4) OPERATION ENABLED, back by 5, 6, 7, 8, 9, 10, 12; quick stop 11
  (QUICK STOP ACTIVE, then 12 when the axis stands, as quick stop option code 2); FAULT REACTION
  ACTIVE -> (14) FAULT -> (15) on the rising edge of controlword bit 7. A controlword acts when
  it is written (SDO or RPDO).
* modes 0x6060 / 0x6061: only cyclic synchronous position (8); 0x6061 shows the mode the drive
  runs, 0 (none) for a mode it does not have.
* CSP: at each SYNC the target 0x607A taken over with the synchronous RPDO becomes the set-point
  the axis reaches at the next SYNC, moving linearly in between (an ideal position loop); 0x6064
  is the position at the SYNC, so a TPDO sent at SYNC k+1 shows the target of SYNC k.
* touch probe 1 (CiA 402 0x60B8 / 0x60B9 / 0x60BA / 0x60BB; the bits as ETG.6010 §12 and
  CiA 402 describe them): 0x60B8 bit 0 enable, bit 1 continuous (else first event), bits 2-3
  trigger source (00 = touch probe input 1, the only one here), bit 4 / bit 5 latch on the
  positive / negative edge. 0x60B9 bit 0 enabled, bit 1 positive-edge value stored, bit 2
  negative-edge value stored; enabling (bit 0 rising) clears the stored bits. The input is a
  probe surface at a configured position: the stylus is deflected (input 1) while the axis is at
  or below the surface. The latched value is the position at the crossing, interpolated within
  the SYNC interval from the SYNC timestamps: crossing time t = t0 + (S - p0) / (p1 - p0) * dt,
  value = p0 + (p1 - p0) * (t - t0) / dt.

Frames only on the bus given (udp_multicast in a private namespace). Prints READY once the
nodes exist, one line per NMT / CiA 402 state change to stderr, and exits after --seconds.

durand 0.5.0 notes (see the Rust test): one CANBusNetwork keeps one subscriber per COB-ID, so
each node gets its own bus and network; the SyncScheduler runs in a thread (the default
AsyncScheduler needs a running asyncio loop); MinimalNode keeps 4 + 4 PDOs.
"""
import argparse
import logging
import sys
import threading
import time

import can
import durand
from durand import MinimalNode, CANBusNetwork, Variable
from durand.datatypes import DatatypeEnum as DT
from durand.scheduler import SyncScheduler
from durand.services.nmt import StateEnum

VENDOR_ID = 0x00000D4D
PRODUCT_CODE = 0x00000402
REVISION = 0x00010000
DEVICE_TYPE = 0x00020192  # CiA 402 (0x0192), servo drive (0x0002)
MODE_CSP = 8

# Statusword patterns (CiA 402 statusword coding; bits 0-3, 5, 6).
NOT_READY, SOD, RTSO, SO, OE, QSA, FRA, FAULT = (
    "NOT READY TO SWITCH ON", "SWITCH ON DISABLED", "READY TO SWITCH ON", "SWITCHED ON",
    "OPERATION ENABLED", "QUICK STOP ACTIVE", "FAULT REACTION ACTIVE", "FAULT")
SW_BITS = {
    NOT_READY: 0x0000, SOD: 0x0040, RTSO: 0x0021, SO: 0x0023, OE: 0x0027,
    QSA: 0x0007, FRA: 0x000F, FAULT: 0x0008,
}
SW_VOLTAGE_ENABLED = 0x0010
SW_REMOTE = 0x0200
SW_TARGET_REACHED = 0x0400
SW_FOLLOWS_COMMAND = 0x1000  # CSP: bit 12 "drive follows the command value"


def command(cw):
    """Controlword command (CiA 402 §6.3 table): bits 7, 3, 2, 1, 0."""
    if cw & 0x0002 == 0:
        return "disable voltage"          # xxxx xx0x
    if cw & 0x0004 == 0:
        return "quick stop"               # xxxx x01x
    if cw & 0x0001 == 0:
        return "shutdown"                 # xxxx x110
    if cw & 0x0008 == 0:
        return "switch on"                # xxxx 0111 (also: disable operation)
    return "enable operation"             # xxxx 1111


class Cia402Drive:
    """One axis behind a durand node (module documentation)."""

    def __init__(self, node, surface, log):
        self.node = node
        self.od = node.object_dictionary
        self.surface = surface
        self.log = log
        self.lock = threading.Lock()
        self.state = NOT_READY
        self.prev_cw = 0
        self.position = 0.0       # at the last SYNC, increments
        self.setpoint = 0.0       # reached at the next SYNC
        self.last_sync = None
        self.tp_func = 0
        self.tp_status = 0
        self.tp_pos = 0
        self.tp_neg = 0
        self.steps = 0
        self._objects()
        self.od.update_callbacks[(0x6040, 0)].add(self._controlword_written)
        self.od.update_callbacks[(0x60B8, 0)].add(self._probe_function_written)
        node.nmt.state_callbacks.add(self._nmt_state)
        node.sync.callbacks.add(self._on_sync)
        # Transition 1 (self test passed) after power-up.
        with self.lock:
            self._set_state(SOD)

    def _objects(self):
        od = self.od
        od[0x1000] = Variable(DT.UNSIGNED32, "ro", DEVICE_TYPE, name="Device type")
        od[0x1008] = Variable(DT.VISIBLE_STRING, "ro", b"durand CiA 402 test node",
                              name="Manufacturer device name")
        ident = od[0x1018]
        for sub, v in ((1, VENDOR_ID), (2, PRODUCT_CODE), (3, REVISION),
                       (4, self.node.node_id)):
            ident[sub] = Variable(DT.UNSIGNED32, "ro", v, name=ident[sub].name)
        for index, dt, acc, name in (
            (0x603F, DT.UNSIGNED16, "ro", "Error code"),
            (0x6040, DT.UNSIGNED16, "rw", "Controlword"),
            (0x6041, DT.UNSIGNED16, "ro", "Statusword"),
            (0x6060, DT.INTEGER8, "rw", "Modes of operation"),
            (0x6061, DT.INTEGER8, "ro", "Modes of operation display"),
            (0x6064, DT.INTEGER32, "ro", "Position actual value"),
            (0x607A, DT.INTEGER32, "rw", "Target position"),
            (0x60B8, DT.UNSIGNED16, "rw", "Touch probe function"),
            (0x60B9, DT.UNSIGNED16, "ro", "Touch probe status"),
            (0x60BA, DT.INTEGER32, "ro", "Touch probe 1 positive edge"),
            (0x60BB, DT.INTEGER32, "ro", "Touch probe 1 negative edge"),
        ):
            od[index] = Variable(dt, acc, 0, name=name)
        od.write(0x1017, 0, 100)  # heartbeat producer on from power-up, 100 ms

    # --- CiA 402 power state machine -------------------------------------------------------

    def _set_state(self, state):
        if state != self.state:
            self.log(f"node {self.node.node_id}: {self.state} -> {state}")
            if state == OE:
                # Start following from where the axis is (no jump to an old target).
                self.setpoint = self.position
        self.state = state
        self._publish_status()

    def _publish_status(self):
        sw = SW_BITS[self.state] | SW_REMOTE
        if self.state != NOT_READY:
            sw |= SW_VOLTAGE_ENABLED
        if self.state == OE and self._mode() == MODE_CSP:
            sw |= SW_FOLLOWS_COMMAND
            if round(self.position) == self.od.read(0x607A, 0):
                sw |= SW_TARGET_REACHED
        self.od.write(0x6041, 0, sw)
        self.od.write(0x6061, 0, self._mode())

    def _mode(self):
        return MODE_CSP if self.od.read(0x6060, 0) == MODE_CSP else 0

    def _apply(self, cw):
        edge = bool(cw & 0x80) and not (self.prev_cw & 0x80)
        self.prev_cw = cw
        s = self.state
        if s == FAULT:
            if edge:
                self._set_state(SOD)                         # 15
            return
        if s == FRA:
            return  # 14 is automatic, at the next SYNC
        if cw & 0x80:
            return  # fault reset bit set outside FAULT: no command
        c = command(cw)
        nxt = s
        if s == SOD and c == "shutdown":
            nxt = RTSO                                       # 2
        elif s == RTSO:
            if c in ("switch on", "enable operation"):
                nxt = SO                                     # 3
            elif c in ("disable voltage", "quick stop"):
                nxt = SOD                                    # 7
        elif s == SO:
            if c == "enable operation":
                nxt = OE                                     # 4
            elif c == "shutdown":
                nxt = RTSO                                   # 6
            elif c in ("disable voltage", "quick stop"):
                nxt = SOD                                    # 10
        elif s == OE:
            if c == "switch on":
                nxt = SO                                     # 5 (disable operation)
            elif c == "shutdown":
                nxt = RTSO                                   # 8
            elif c == "disable voltage":
                nxt = SOD                                    # 9
            elif c == "quick stop":
                nxt = QSA                                    # 11
        elif s == QSA:
            if c == "disable voltage":
                nxt = SOD                                    # 12
            elif c == "enable operation":
                nxt = OE                                     # 16
        self._set_state(nxt)
        # A "switch on + enable operation" from READY TO SWITCH ON goes on to OPERATION
        # ENABLED (3, then 4).
        if nxt == SO and s == RTSO and c == "enable operation":
            self._set_state(OE)

    def _controlword_written(self, cw):
        with self.lock:
            self._apply(cw)

    # --- touch probe -------------------------------------------------------------------------

    def _probe_function_written(self, func):
        with self.lock:
            if func & 0x01 and not self.tp_func & 0x01:
                self.tp_status = 0x01                        # enabled, nothing stored
            if not func & 0x01:
                self.tp_status = 0
            if not func & 0x10:
                self.tp_status &= ~0x02
            if not func & 0x20:
                self.tp_status &= ~0x04
            self.tp_func = func
            self.od.write(0x60B9, 0, self.tp_status)

    def _input(self, position):
        """Touch probe input 1: the stylus touches at or below the surface."""
        return self.surface is not None and position <= self.surface

    def _latch(self, rising, value):
        f = self.tp_func
        if not f & 0x01 or (f >> 2) & 0x3 != 0:
            return
        bit, enable, index = (0x02, 0x10, 0x60BA) if rising else (0x04, 0x20, 0x60BB)
        if not f & enable:
            return
        continuous = bool(f & 0x02)
        if self.tp_status & bit and not continuous:
            return  # first event: only the first edge after enabling
        self.tp_status |= bit
        self.od.write(index, 0, value)
        self.od.write(0x60B9, 0, self.tp_status)
        self.log(f"node {self.node.node_id}: touch probe 1 {'positive' if rising else 'negative'}"
                 f" edge at {value}")

    # --- SYNC: move one interval ---------------------------------------------------------

    def _nmt_state(self, state):
        if state == StateEnum.OPERATIONAL:
            # Step after durand's own SYNC work (TPDOs sent with the values sampled at the
            # previous SYNC, synchronous RPDOs taken over): re-register last.
            cbs = self.node.sync.callbacks
            if self._on_sync in cbs:
                cbs.remove(self._on_sync)
            cbs.add(self._on_sync)
        self.log(f"node {self.node.node_id}: NMT {state.name}")

    def _on_sync(self):
        now = time.monotonic()
        with self.lock:
            dt = None if self.last_sync is None else now - self.last_sync
            self.last_sync = now
            self.steps += 1
            if self.state == FRA:
                self._set_state(FAULT)                       # 14
            elif self.state == QSA:
                self.setpoint = self.position                # stop where it is, then 12
                self._set_state(SOD)
            p0, p1 = self.position, self.setpoint
            # Edges of the probe input between the two SYNCs, by the linear motion p0 -> p1.
            before, after = self._input(p0), self._input(p1)
            if before != after and p1 != p0:
                frac = (self.surface - p0) / (p1 - p0)
                t_cross = (dt or 0.0) * frac             # since the previous SYNC
                value = p0 + (p1 - p0) * (t_cross / dt if dt else frac)
                self._latch(after, round(value))
            self.position = p1
            self.od.write(0x6064, 0, round(self.position))
            # The set-point of this SYNC (CSP), reached at the next one.
            if self.state == OE and self._mode() == MODE_CSP:
                self.setpoint = float(self.od.read(0x607A, 0))
            else:
                self.setpoint = self.position
            self._publish_status()


def parse_surfaces(items):
    out = {}
    for it in items:
        node, pos = it.split("=", 1)
        out[int(node)] = float(pos)
    return out


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--interface", default="udp_multicast")
    ap.add_argument("--channel", required=True)
    ap.add_argument("--port", type=int, default=43113)
    ap.add_argument("--node", type=int, action="append", required=True)
    ap.add_argument("--surface", action="append", default=[],
                    help="NODE=INCREMENTS: probe surface of that node's axis")
    ap.add_argument("--seconds", type=float, default=60.0)
    a = ap.parse_args(argv[1:])
    surfaces = parse_surfaces(a.surface)

    def log(msg):
        print(f"{time.monotonic():.3f} {msg}", file=sys.stderr, flush=True)

    # durand swallows exceptions of callbacks with a debug log (FailMode.IGNORE): show them.
    logging.basicConfig(stream=sys.stderr, level=logging.WARNING)
    logging.getLogger("durand.callback_handler").setLevel(logging.DEBUG)

    sched = SyncScheduler()
    durand.set_scheduler(sched)
    threading.Thread(target=sched.run, daemon=True).start()
    buses, drives = [], []
    for node_id in a.node:
        kw = {"port": a.port} if a.interface == "udp_multicast" else {}
        bus = can.Bus(interface=a.interface, channel=a.channel, **kw)
        net = CANBusNetwork(bus)
        node = MinimalNode(net, node_id)
        drives.append(Cia402Drive(node, surfaces.get(node_id), log))
        buses.append((bus, net))
    print("READY", flush=True)
    try:
        time.sleep(a.seconds)
    finally:
        sched.stop()
        for bus, net in buses:
            net.stop()
            bus.shutdown()
        log(f"exit after {a.seconds} s; SYNC steps {[d.steps for d in drives]}")


if __name__ == "__main__":
    main(sys.argv)
