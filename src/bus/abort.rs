//! CiA 301 SDO abort codes (CiA 301, "Protocol SDO abort transfer", table of SDO abort codes)
//! and emergency error codes (CiA 301 Table 21), shared by the CANopen SDO client and server
//! and the CoE mailbox client: CoE (CANopen over EtherCAT, ETG.1000.6 SDO and emergency
//! services) carries the same codes.

/// CiA 301 SDO abort code in words.
pub fn abort_text(code: u32) -> &'static str {
    match code {
        0x0503_0000 => "toggle bit not alternated",
        0x0504_0000 => "SDO protocol timed out",
        0x0504_0001 => "client/server command specifier not valid or unknown",
        0x0504_0002 => "invalid block size (block mode only)",
        0x0504_0003 => "invalid sequence number (block mode only)",
        0x0504_0004 => "CRC error (block mode only)",
        0x0504_0005 => "out of memory",
        0x0601_0000 => "unsupported access to an object",
        0x0601_0001 => "attempt to read a write-only object",
        0x0601_0002 => "attempt to write a read-only object",
        0x0602_0000 => "object does not exist in the object dictionary",
        0x0604_0041 => "object cannot be mapped to the PDO",
        0x0604_0042 => "number and length of mapped objects exceed PDO length",
        0x0604_0043 => "general parameter incompatibility",
        0x0604_0047 => "general internal incompatibility in the device",
        0x0606_0000 => "access failed due to a hardware error",
        0x0607_0010 => "data type does not match, length of service parameter does not match",
        0x0607_0012 => "data type does not match, length of service parameter too high",
        0x0607_0013 => "data type does not match, length of service parameter too low",
        0x0609_0011 => "subindex does not exist",
        0x0609_0030 => "value range of parameter exceeded",
        0x0609_0031 => "value of parameter written too high",
        0x0609_0032 => "value of parameter written too low",
        0x0609_0036 => "maximum value is less than minimum value",
        0x060A_0023 => "resource not available: SDO connection",
        0x0800_0000 => "general error",
        0x0800_0020 => "data cannot be transferred or stored to the application",
        0x0800_0021 => "data cannot be transferred because of local control",
        0x0800_0022 => "data cannot be transferred because of the present device state",
        0x0800_0023 => "object dictionary not present or dynamic generation failed",
        0x0800_0024 => "no data available",
        _ => "unknown abort code",
    }
}

/// An emergency error code in words (CiA 301 Table 21 classes, CiA 402 codes the drives use);
/// the same codes travel in CoE emergencies over EtherCAT.
pub fn emergency_text(code: u16) -> &'static str {
    match code {
        0x0000 => "error reset or no error",
        0x8611 => "following error (CiA 402)",
        0x8612 => "reference limit (CiA 402)",
        0x8100 => "communication",
        0x8110 => "CAN overrun (objects lost)",
        0x8120 => "CAN in error passive mode",
        0x8130 => "life guard or heartbeat error",
        0x8140 => "recovered from bus off",
        0x8210 => "PDO not processed due to length error",
        0x8220 => "PDO length exceeded",
        0x3220 => "DC link under-voltage",
        c => match c & 0xF000 {
            0x1000 => "generic error",
            0x2000 => "current",
            0x3000 => "voltage",
            0x4000 => "temperature",
            0x5000 => "device hardware",
            0x6000 => "device software",
            0x7000 => "additional modules",
            0x8000 => "monitoring",
            0x9000 => "external error",
            0xF000 => "additional functions",
            0xFF00 => "device specific",
            _ => "unknown error code",
        },
    }
}
