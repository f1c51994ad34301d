//! Helpers shared by the integration-test binaries (`tests/it`, `tests/system`). Each is
//! compiled once per binary; a helper that runs the `fieldprobe` binary or needs a bus's
//! crates is built with the feature that provides them.

#![allow(dead_code)] // each binary and feature set uses its own subset

#[cfg(feature = "cli")]
pub mod canopen_peers;
#[cfg(feature = "cli")]
pub mod cli;
#[cfg(feature = "ethercat")]
pub mod esi_dict;
#[cfg(feature = "ethercat")]
pub mod esi_xml;
pub mod measuring;
#[cfg(feature = "cli")]
pub mod netns;
pub mod seed004;
pub mod test_data;
pub mod vendor_esi;
#[cfg(feature = "cli")]
pub mod vendor_spec;
#[cfg(feature = "cli")]
pub mod veth;
#[cfg(feature = "sim")]
pub mod wire;

/// The full libtest name (`MODULE::name`) of the running test whose function is `name`, for
/// re-running it alone (`--exact`) in a namespace or a guest: libtest runs every test on a
/// thread named after it.
pub fn full_test_name(name: &str) -> String {
    match std::thread::current().name() {
        Some(full) if full == name || full.ends_with(&format!("::{name}")) => full.to_owned(),
        other => panic!("full_test_name({name}) called outside that test (thread {other:?})"),
    }
}
