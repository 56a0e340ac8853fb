//! `hytask run`, `home`, `mdi` and `jog` driven as a person drives them: the real binary on a
//! pseudo-terminal (`tests/cli_pty`), Ctrl-C sent as SIGINT to its process group. The
//! machine is the fast-homing sim mill on a simulated clock (`tests/support`), so what the
//! machine does does not depend on the host's load; every wait is a hang guard.
#![allow(clippy::unwrap_used)]

mod cli_pty;
mod support;

use cli_pty::PtyChild;
use std::ffi::OsStr;
use support::*;

/// `hytask run` on the embedded machine: the first Ctrl-C holds the job and says how to go
/// on, the second aborts it; the embedded daemon stops the axes and the command exits with
/// 130 (interrupted) and a one-line summary, never "Broken pipe".
#[test]
fn ctrl_c_holds_then_aborts_a_run_on_the_embedded_machine() {
    let dir = tempfile::tempdir().unwrap();
    let config = sim_clock_config(dir.path(), SIM_SPEED, None);
    let job = fixture("jobs/long.ngc");
    let missing = dir.path().join("no-daemon.sock");
    let mut p = PtyChild::spawn(&[
        OsStr::new("run"),
        job.as_os_str(),
        OsStr::new("--config"),
        config.as_os_str(),
        OsStr::new("--socket"),
        missing.as_os_str(),
    ]);
    p.expect("running on the embedded machine");
    // The job is moving once its progress shows a line of the program.
    p.expect("line 6/");
    p.ctrl_c();
    let held = p.expect("Ctrl-C again aborts");
    assert!(held.contains("feed hold"), "{held}");
    p.ctrl_c();
    let (status, out) = p.wait();
    assert!(!out.contains("Broken pipe"), "{out}");
    assert_eq!(status.code(), Some(130), "{out}");
    assert!(out.contains("aborted by Ctrl-C"), "{out}");
    assert!(out.contains("axes stopped"), "{out}");
}
