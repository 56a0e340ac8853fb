//! The README's example jobs, run as documented: `hytask run examples/jobs/<job>.ngc` with no
//! daemon reachable, so the embedded daemon starts on the built-in simulated mill, homes it,
//! runs the job in real time and prints a summary. The main command runs the demo plate; the
//! probing example touches off on the simulated plate (config/sim.toml).
#![allow(clippy::unwrap_used)]

use std::process::Command;

/// Runs `hytask run <job>` as a user would; returns (stdout, stderr) of a successful run.
fn run_example(job: &str) -> (String, String) {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hytask"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["run", job, "--socket"])
        .arg(dir.path().join("no-daemon-here.sock"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stdout}\n{stderr}");
    (stdout, stderr)
}

#[test]
fn the_readme_main_command_runs_the_demo_job_to_completion() {
    let (stdout, stderr) = run_example("examples/jobs/demo-plate.ngc");
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
    let (stdout, stderr) = run_example("examples/jobs/probe-touch-off.ngc");
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
