//! SII EEPROM images (ETG.1000.6 §5.4, ETG.2010): build from a device description, decode real
//! images.
