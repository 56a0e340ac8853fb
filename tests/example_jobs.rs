//! The README's example jobs, run as documented: `hytask run examples/jobs/<job>.ngc` with no
//! daemon reachable, so the embedded daemon starts on the built-in simulated mill, homes it,
//! runs the job and prints a summary. The main command runs the demo plate; the probing
//! example touches off on the simulated plate (config/sim.toml). Both check what the job
//! does, not its timing, so they run the built-in mill on a simulated clock (`--config` with
//! `clock = "simulated"`, see `tests/support/mod.rs`): a loaded host can neither trip an
//! overrun nor stretch the demo's minute of machine time. One real-time smoke test runs the
//! embedded daemon on its real-time servo thread with a short job.
#![allow(clippy::unwrap_used)]

use std::process::Command;

/// Runs `hytask run <job> [extra]` as a user would; returns (stdout, stderr) of a successful
/// run.
fn run_example(job: &str, extra: &[&std::ffi::OsStr]) -> (String, String) {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hytask"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["run", job, "--socket"])
        .arg(dir.path().join("no-daemon-here.sock"))
        .args(extra)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stdout}\n{stderr}");
    (stdout, stderr)
}

/// config/sim.toml (the built-in mill) on a simulated clock, cycles back to back.
fn builtin_sim_on_a_simulated_clock(dir: &std::path::Path) -> std::path::PathBuf {
    let base = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim.toml");
    let text = std::fs::read_to_string(base).unwrap();
    let thread = "[[thread]]\n";
    assert_eq!(text.matches(thread).count(), 2, "config/sim.toml changed");
    let path = dir.join("sim-clock.toml");
    std::fs::write(
        &path,
        text.replace(thread, &format!("{thread}clock = \"simulated\"\n")),
    )
    .unwrap();
    path
}

#[test]
fn the_readme_main_command_runs_the_demo_job_to_completion() {
    let dir = tempfile::tempdir().unwrap();
    let config = builtin_sim_on_a_simulated_clock(dir.path());
    let (stdout, stderr) = run_example(
        "examples/jobs/demo-plate.ngc",
        &["--config".as_ref(), config.as_os_str()],
    );
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

/// The probing example: touches off twice on the simulated plate at machine Z-80, sets work
/// Z0 from #5063 and faces the stock.
#[test]
fn the_probing_example_finds_the_stock_top_and_faces_it() {
    let dir = tempfile::tempdir().unwrap();
    let config = builtin_sim_on_a_simulated_clock(dir.path());
    let (stdout, stderr) = run_example(
        "examples/jobs/probe-touch-off.ngc",
        &["--config".as_ref(), config.as_os_str()],
    );
    // The DEBUG line prints the measured height: the slow touch at F30 (0.5 mm/s) finds the
    // plate within a micrometre or two.
    let line = stderr
        .lines()
        .find(|l| l.contains("stock top at machine Z"))
        .unwrap_or_else(|| panic!("no measurement in {stderr}"));
    let z: f64 = line.rsplit(' ').next().unwrap().parse().unwrap();
    assert!((-80.003..=-80.0).contains(&z), "{line}");
    assert!(stdout.contains("result:     done"), "{stdout}");
    assert!(
        stdout.contains("final position (machine): X 165.0000  Y 120.0000"),
        "{stdout}"
    );
}

/// Real-time smoke test: the embedded daemon on its real-time servo thread (the fast-homing
/// test mill) runs a short job to the end.
#[test]
fn the_embedded_daemon_runs_a_short_job_in_real_time() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = root.join("tests/fixtures/sim-fast.toml");
    let (stdout, stderr) = run_example(
        "tests/fixtures/jobs/square.ngc",
        &["--config".as_ref(), config.as_os_str()],
    );
    assert!(
        stderr.contains("running on the embedded machine 'sim-mill-fast-home'"),
        "{stderr}"
    );
    assert!(stderr.contains("progress 100.0%"), "{stderr}");
    assert!(stdout.contains("result:     done"), "{stdout}");
}
