//! The README's main command, run as documented: `hytask run examples/jobs/demo-plate.ngc`
//! with no daemon reachable, so the embedded daemon starts on the built-in simulated mill,
//! homes it, runs the demo job in real time and prints a summary.
#![allow(clippy::unwrap_used)]

use std::process::Command;

#[test]
fn the_readme_main_command_runs_the_demo_job_to_completion() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hytask"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["run", "examples/jobs/demo-plate.ngc", "--socket"])
        .arg(dir.path().join("no-daemon-here.sock"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("running on the embedded machine 'sim-mill'"),
        "{stderr}"
    );
    assert!(stderr.contains("homing X Y Z"), "{stderr}");
    assert!(stderr.contains("progress 100.0%"), "{stderr}");
    assert!(
        stderr.contains("hytask demo: plate with pocket"),
        "{stderr}"
    );
    assert!(stdout.contains("result:     done"), "{stdout}");
    // The job ends with G53 G0 X0 Y0 after G53 G0 Z0.
    assert!(
        stdout.contains("final position (machine): X 0.00"),
        "{stdout}"
    );
}
