//! One test file at a time: the tests of `tests/system` use network namespaces, veth pairs,
//! the SocketCAN guest, Python peers, cargo-fuzz and the wall clock. Each ran alone in its own
//! binary before the binaries were merged (issue 29); the gate keeps that: the tests of one
//! module may run side by side (as they did in their binary), a test of another module waits
//! until the running module's tests are done.

use std::sync::{Condvar, Mutex};

/// The module whose tests hold the gate, and how many of them run.
static HOLDER: Mutex<(Option<String>, usize)> = Mutex::new((None, 0));
static FREED: Condvar = Condvar::new();

/// Held by a running test; dropping it (also when the test panics) lets the next module in.
#[must_use = "the gate is held while the guard lives"]
pub struct Entered;

/// Wait until no other module's test runs, then hold the gate for `module_path` (the caller's
/// `module_path!()`: `system::MODULE[::…]`; tests of one MODULE share it).
pub fn enter(module_path: &str) -> Entered {
    let module = module_path
        .split("::")
        .nth(1)
        .unwrap_or(module_path)
        .to_owned();
    let mut h = HOLDER.lock().unwrap_or_else(|e| e.into_inner());
    loop {
        match &h.0 {
            None => {
                *h = (Some(module), 1);
                return Entered;
            }
            Some(m) if *m == module => {
                h.1 += 1;
                return Entered;
            }
            Some(_) => h = FREED.wait(h).unwrap_or_else(|e| e.into_inner()),
        }
    }
}

impl Drop for Entered {
    fn drop(&mut self) {
        let mut h = HOLDER.lock().unwrap_or_else(|e| e.into_inner());
        h.1 -= 1;
        if h.1 == 0 {
            h.0 = None;
            FREED.notify_all();
        }
    }
}
