//! The loss of the master on the node's own clock (issue 28 item 3) and NMT reset node / reset
//! communication (item 4), on virtual time: no SYNC and no frame at all after the master
//! stops, only the node's time-driven work ([`EmulatedNode::poll`]) at 1 ms steps, as `sim
//! canopen` runs it.

use super::*;

/// Statusword state bits of FAULT (CiA 402 Table "state coding", mask 0x4F).
const SW_FAULT: u16 = 0x0008;
/// Statusword of QUICK STOP ACTIVE (mask 0x6F).
const SW_QUICK_STOP_ACTIVE: u16 = 0x0007;
/// 0x1006 the "master" writes, µs.
const PERIOD_US: u32 = 1000;

/// A node started with RPDO1 = controlword (synchronous), 0x1006 = 1 ms, enabled by SDO and
/// then served 5 SYNCs (t = 1 … 5 ms) as a master's cycle would: the master is "gone" after
/// t = 5 ms.
fn enabled_then_master_gone(abort_connection: Option<i16>) -> Bench {
    let mut b = Bench::built_in();
    b.map_pdo1(Direction::Rx, &[0x6040_0010], 1, 0, 0);
    b.write(0x1006, 0, &PERIOD_US.to_le_bytes()).unwrap();
    if let Some(code) = abort_connection {
        b.write(0x6007, 0, &code.to_le_bytes()).unwrap();
    }
    b.nmt(NmtCommand::Start);
    for cw in [6u16, 7, 0xF] {
        b.write(0x6040, 0, &cw.to_le_bytes()).unwrap();
    }
    for ms in 1..=5 {
        b.at_ms(ms);
        b.send(&[CanFrame::new(0x205, &0xFu16.to_le_bytes()).unwrap()]);
        b.sync();
    }
    assert_eq!(b.statusword() & SW_MASK, SW_OPERATION_ENABLED);
    b
}

/// Poll at 1 ms steps from 6 ms to `until_ms`; the first time the statusword is out of
/// OPERATION ENABLED (read directly from the model: an SDO is a frame), with every frame sent.
fn first_out_of_operation_enabled(b: &mut Bench, until_ms: u64) -> (Option<u64>, Vec<CanFrame>) {
    let mut all = Vec::new();
    for ms in 6..=until_ms {
        all.extend(b.at_ms(ms));
        let state = b.node().model().state();
        if state != crate::drive::PowerState::OperationEnabled {
            return (Some(ms), all);
        }
    }
    (None, all)
}

#[test]
fn sync_loss_faults_the_drive_on_the_nodes_own_clock_with_no_frame_at_all() {
    let mut b = enabled_then_master_gone(None);
    assert_eq!(b.read(0x6007, 0), Ok(1), "0x6007 default: fault signal");
    let (at, out) = first_out_of_operation_enabled(&mut b, 100);
    // Last SYNC at 5 ms; the watch fires at the first poll more than 5 × 0x1006 later.
    assert_eq!(at, Some(11), "out of OPERATION ENABLED at {at:?} ms");
    assert_eq!(b.node().master_lost_at(), Some(Nanos(11_000_000)));
    assert_eq!(b.node().model().state(), crate::drive::PowerState::Fault);
    assert!(
        emcys(&out).iter().any(|e| e.0 == SYNC_TIMEOUT_EMCY),
        "{out:?}"
    );
    // Still no SYNC: the statusword the SDO server reads is FAULT, 0x603F the SYNC time-out.
    assert_eq!(b.statusword() & 0x4F, SW_FAULT);
    assert_eq!(b.read(0x603F, 0), Ok(u32::from(SYNC_TIMEOUT_EMCY)));
    // A new master: fault reset (rising edge of bit 7) brings it to SWITCH ON DISABLED.
    b.write(0x6040, 0, &0x80u16.to_le_bytes()).unwrap();
    assert_eq!(b.statusword() & 0x4F, SW_SWITCH_ON_DISABLED);
}

#[test]
fn rpdo_event_timer_loss_faults_the_drive_without_sync_or_any_frame() {
    let mut b = Bench::built_in();
    // Event-driven RPDO1 = controlword, event-timer 3 ms; no 0x1006, so no SYNC watch.
    b.map_pdo1(Direction::Rx, &[0x6040_0010], 255, 0, 0);
    b.write(0x1400, 5, &3u16.to_le_bytes()).unwrap();
    b.nmt(NmtCommand::Start);
    for (ms, cw) in [(1u64, 6u16), (2, 7), (3, 0xF), (4, 0xF), (5, 0xF)] {
        b.at_ms(ms);
        b.send(&[CanFrame::new(0x205, &cw.to_le_bytes()).unwrap()]);
    }
    assert_eq!(b.statusword() & SW_MASK, SW_OPERATION_ENABLED);
    let (at, out) = first_out_of_operation_enabled(&mut b, 100);
    // Last RPDO at 5 ms, event-timer 3 ms: the first poll after 8 ms.
    assert_eq!(at, Some(9));
    assert!(
        emcys(&out).iter().any(|e| e.0 == RPDO_TIMEOUT_EMCY),
        "{out:?}"
    );
    assert_eq!(b.statusword() & 0x4F, SW_FAULT);
}

#[test]
fn abort_connection_option_code_chooses_the_reaction() {
    // 2: disable voltage → SWITCH ON DISABLED; 3: quick stop → QUICK STOP ACTIVE.
    for (code, mask, want) in [
        (2i16, 0x4Fu16, SW_SWITCH_ON_DISABLED),
        (3, SW_MASK, SW_QUICK_STOP_ACTIVE),
        (-1, 0x4F, SW_FAULT),
    ] {
        let mut b = enabled_then_master_gone(Some(code));
        let (at, _) = first_out_of_operation_enabled(&mut b, 100);
        assert_eq!(at, Some(11), "0x6007 = {code}");
        assert_eq!(b.statusword() & mask, want, "0x6007 = {code}");
        // A late SYNC with nothing new does not enable the drive again (the RPDO image has
        // the reaction's controlword).
        b.at_ms(20);
        b.sync();
        assert_ne!(
            b.statusword() & SW_MASK,
            SW_OPERATION_ENABLED,
            "0x6007 = {code}"
        );
    }
    // 0: no action — the drive stays enabled, the EMCY still goes out.
    let mut b = enabled_then_master_gone(Some(0));
    let (at, out) = first_out_of_operation_enabled(&mut b, 30);
    assert_eq!(at, None);
    assert!(emcys(&out).iter().any(|e| e.0 == SYNC_TIMEOUT_EMCY));
    // Out of range for INTEGER16 is refused by size.
    assert_eq!(b.write(0x6007, 0, &[1, 0, 0, 0]), Err(0x0607_0010));
}

#[test]
fn reset_node_brings_a_drive_left_enabled_back_to_its_power_on_state() {
    let mut b = enabled_then_master_gone(Some(0));
    b.write(0x6065, 0, &1234u32.to_le_bytes()).unwrap();
    b.write(0x605E, 0, &1i16.to_le_bytes()).unwrap();
    let before = b.read(0x6064, 0).unwrap();
    // The master crashed: no SYNC, the drive stays enabled (0x6007 = 0) …
    b.at_ms(50);
    assert_eq!(b.statusword() & SW_MASK, SW_OPERATION_ENABLED);
    // … and the next master resets the node.
    b.at_ms(51);
    let out = b.nmt(NmtCommand::ResetNode);
    assert_eq!(
        on(&out, 0x700 + u32::from(NODE)),
        vec![vec![0x00]],
        "boot-up"
    );
    assert_eq!(b.node().state(), NmtState::PreOperational);
    assert_eq!(b.statusword(), SW_AFTER_START_UP);
    assert_eq!(b.read(0x6040, 0), Ok(0));
    assert_eq!(b.read(0x603F, 0), Ok(0));
    let mut fresh = Bench::built_in();
    assert_eq!(
        b.read(0x6065, 0),
        fresh.read(0x6065, 0),
        "0x6065 power-on value"
    );
    assert_ne!(b.read(0x6065, 0), Ok(1234));
    assert_eq!(b.read(0x6007, 0), Ok(1));
    assert_eq!(
        b.read(0x605E, 0),
        Ok(u32::from(FAULT_REACTION_DEFAULT as u16))
    );
    assert_eq!(b.read(0x1006, 0), Ok(0));
    // The axis did not move with the reset.
    assert_eq!(b.read(0x6064, 0), Ok(before));
    // A faulted drive is power-on clean after reset node as well.
    let mut b = enabled_then_master_gone(None);
    first_out_of_operation_enabled(&mut b, 100);
    assert_eq!(b.statusword() & 0x4F, SW_FAULT);
    b.nmt(NmtCommand::ResetNode);
    b.at_ms(101);
    assert_eq!(b.statusword(), SW_AFTER_START_UP);
    assert_eq!(b.read(0x603F, 0), Ok(0));
    assert_eq!(b.node().error_register(), 0);
}

#[test]
fn leaving_operational_with_the_drive_disabled_is_no_reaction_enabled_is_one() {
    // Disabled first (fieldprobe's end of a run): enter pre-operational changes nothing.
    let mut b = enabled_then_master_gone(None);
    b.write(0x6040, 0, &6u16.to_le_bytes()).unwrap();
    b.nmt(NmtCommand::EnterPreOperational);
    assert_eq!(b.statusword() & SW_MASK, SW_READY_TO_SWITCH_ON);
    assert_eq!(b.node().master_lost_at(), None);
    // Still enabled (a master that died between its NMT command and the disable): FAULT.
    let mut b = enabled_then_master_gone(None);
    b.nmt(NmtCommand::Stop);
    assert_eq!(b.node().model().state(), crate::drive::PowerState::Fault);
}

#[test]
fn reset_communication_restores_the_communication_area_and_keeps_the_application() {
    let mut b = enabled_then_master_gone(Some(3));
    b.write(0x6065, 0, &1234u32.to_le_bytes()).unwrap();
    b.at_ms(6);
    let out = b.nmt(NmtCommand::ResetCommunication);
    assert_eq!(
        on(&out, 0x700 + u32::from(NODE)),
        vec![vec![0x00]],
        "boot-up"
    );
    assert_eq!(b.node().state(), NmtState::PreOperational);
    // Communication area: boot defaults.
    assert_eq!(b.read(0x1006, 0), Ok(0));
    let mut fresh = Bench::built_in();
    assert_eq!(b.read(0x1600, 1), fresh.read(0x1600, 1));
    // Application area: as the master left it.
    assert_eq!(b.read(0x6007, 0), Ok(3));
    assert_eq!(b.read(0x6065, 0), Ok(1234));
    // The node left OPERATIONAL with its drive enabled: the abort connection reaction (3,
    // quick stop) at once.
    assert_eq!(b.statusword() & SW_MASK, SW_QUICK_STOP_ACTIVE);
    assert_eq!(b.node().master_lost_at(), Some(Nanos(6_000_000)));
    // The SYNC watch is not armed in PRE-OPERATIONAL: a new master configures and starts the
    // node; the drive is usable (disable voltage, shutdown, switch on, enable by SDO).
    b.at_ms(100);
    for cw in [0u16, 6, 7, 0xF] {
        b.write(0x6040, 0, &cw.to_le_bytes()).unwrap();
    }
    assert_eq!(b.statusword() & SW_MASK, SW_OPERATION_ENABLED);
}
