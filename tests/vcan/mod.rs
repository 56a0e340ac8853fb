//! Shared by the `vcan_*` test binaries: the interface to test on. Include with `mod vcan;`.
//!
//! These tests need a real SocketCAN vcan0, which the build machines' kernel cannot make:
//! `tests/vcan/run` runs them on the host's vcan0 where it exists, else inside a qemu VM, and
//! sets `HYTASK_VCAN`. Run anywhere else (a plain `cargo test`), each test says why and
//! returns; the harness is where they run, and under CI=true it fails when it cannot.
#![allow(dead_code)]

/// The interface to test on, or `None` (with the reason printed) outside the harness.
pub fn iface(test: &str) -> Option<String> {
    match std::env::var("HYTASK_VCAN") {
        Ok(i) if !i.is_empty() => Some(i),
        _ => {
            eprintln!(
                "{test}: HYTASK_VCAN is unset, so this test does not run here: it needs a real \
                 vcan0 and runs under tests/vcan/run (which boots a VM when the host kernel \
                 has no CAN)"
            );
            None
        }
    }
}
