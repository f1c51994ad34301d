//! EtherCAT Slave Information (ETG.2000 XML) → device description, and the SII EEPROM image
//! ([`sii`]).

pub mod sii;
