//! SDO client and server (CiA 301 §7.2.4), sans-IO.
