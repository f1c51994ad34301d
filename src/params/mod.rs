//! Parameters of the seeds (P-AXIS-*, P-CHAN-*, P-MANU-*).
