//! Coordinate frames: PCS, offsets, #CS.
