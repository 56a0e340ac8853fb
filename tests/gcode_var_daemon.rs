//! The daemon's var file (`[gcode] var_file`, issue 13): loaded at deploy, committed and
//! saved when a job has run to its end, so the next job (and the next daemon) starts from
//! the offsets the last one left.
//!
//! Simulated clock, unpaced; the waits are hang guards of a minute, never timings.
#![allow(clippy::unwrap_used)]

mod support;

use hytask::machine::api::{JobSource, MachineApi, Mode, Status};
use hytask::machine::Machine;
use std::sync::Arc;

fn wait(m: &Machine, what: &str, pred: impl Fn(&Status) -> bool) -> Status {
    support::wait_machine(m, what, pred)
}

fn deploy(config: &std::path::Path) -> Arc<Machine> {
    support::deploy_homed(config)
}

fn run(m: &Machine, program: &str) {
    m.job_load(&JobSource {
        path: None,
        text: Some(program.into()),
        name: Some("v.ngc".into()),
    })
    .unwrap();
    m.job_run().unwrap();
    wait(m, "the job's end", |s| {
        s.job.state == "done" && s.mode == Mode::Idle
    });
}

fn value(file: &std::path::Path, n: u16) -> Option<String> {
    let text = std::fs::read_to_string(file).unwrap();
    text.lines()
        .find_map(|l| l.strip_prefix(&format!("{n}\t")).map(str::to_string))
}

#[test]
fn a_finished_job_saves_its_offsets_and_the_next_daemon_starts_from_them() {
    let dir = tempfile::tempdir().unwrap();
    let config = support::sim_clock_config(dir.path(), 0, None);
    let mut text = std::fs::read_to_string(&config).unwrap();
    text.push_str("\n[gcode]\nvar_file = \"m.var\"\n");
    std::fs::write(&config, text).unwrap();
    let var = dir.path().join("m.var");
    std::fs::write(&var, "100\t4\n5220\t1\n").unwrap();

    let m = deploy(&config);
    run(
        &m,
        "G21 G90\nG10 L2 P2 X12.5\n#100 = [#100 + 1]\nG0 X1 Y1\nM2\n",
    );
    assert_eq!(value(&var, 5241).as_deref(), Some("12.500000"));
    assert_eq!(value(&var, 100).as_deref(), Some("5.000000"));
    hytask::daemon::Deployed::shutdown(&*m).unwrap();

    // A new daemon reads the file: G55's offset is there.
    let m = deploy(&config);
    run(
        &m,
        "G21 G90 G55\n#100 = [#100 + 1]\nG0 X[#5241 * 2] Y1\nM2\n",
    );
    assert_eq!(value(&var, 100).as_deref(), Some("6.000000"));
    hytask::daemon::Deployed::shutdown(&*m).unwrap();
    assert_eq!(value(&var, 5241).as_deref(), Some("12.500000"));
}

/// A probing job runs piece by piece with the measured probe results; its dry run (before
/// motion) used rs274's simulated probe, which trips at the end of the move. The var file
/// must hold what the program computed from the measurement, not from the dry run.
#[test]
fn a_probing_job_saves_the_offsets_it_measured_not_those_of_its_dry_run() {
    let dir = tempfile::tempdir().unwrap();
    // The touch plate's top is at Z-10; the probe move goes to Z-20.
    let config = support::sim_clock_config(dir.path(), 0, Some(-10.0));
    let mut text = std::fs::read_to_string(&config).unwrap();
    text.push_str("\n[gcode]\nvar_file = \"m.var\"\n");
    std::fs::write(&config, text).unwrap();
    let var = dir.path().join("m.var");
    std::fs::write(&var, "5220\t1\n").unwrap();

    let m = deploy(&config);
    // Touch off: G54's Z zero becomes the plate's top (G10 L20 sets the offset so that the
    // current position is Z0), then move clear above it.
    run(
        &m,
        "G21 G90\nG0 X20 Y20 Z-2\nG38.2 Z-20 F300\nG10 L20 P1 Z0\nG0 Z5\nM2\n",
    );
    let z: f64 = value(&var, 5223).unwrap().parse().unwrap();
    assert!(
        (-11.0..=-10.0).contains(&z),
        "G54 Z offset {z}: the plate is at -10, the probe stops a little past it (the dry \
         run's probe ends near -20)"
    );
    hytask::daemon::Deployed::shutdown(&*m).unwrap();
    let z: f64 = value(&var, 5223).unwrap().parse().unwrap();
    assert!((-11.0..=-10.0).contains(&z), "after shutdown: {z}");
}
