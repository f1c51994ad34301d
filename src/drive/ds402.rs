//! CiA 402 master-side adapter.
