//! CiA 402 drive model.
