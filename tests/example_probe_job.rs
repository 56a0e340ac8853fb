//! The probing example, run as a user would: `hytask run examples/jobs/probe-touch-off.ngc`
//! on the built-in simulated mill, whose touch plate (config/sim.toml) puts the stock top at
//! machine Z-80. The job touches off twice, sets work Z0 from #5063 and faces the stock.
#![allow(clippy::unwrap_used)]

use std::process::Command;

#[test]
fn the_probing_example_finds_the_stock_top_and_faces_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hytask"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["run", "examples/jobs/probe-touch-off.ngc", "--socket"])
        .arg(dir.path().join("no-daemon-here.sock"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
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
