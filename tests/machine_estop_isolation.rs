//! Two machines in one process (a cell, the test binaries): one machine's e-stop does not
//! cancel the other's job preparation. In a file of its own: its e-stops, hundreds in a
//! second and a half, are kept away from the other operator-API tests.
#![allow(clippy::unwrap_used)]

mod support;

use hytask::machine::api::{ApiError, JobSource, MachineApi, Mode};
use hytask::machine::Machine;
use std::sync::Arc;

fn sim_machine() -> (Arc<Machine>, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let config = support::sim_clock_config(dir.path(), 0, None);
    let m = Machine::deploy(hytask::config::load(&config).unwrap()).unwrap();
    (m, dir)
}

fn ready(m: &Machine) {
    m.estop_reset().unwrap();
    m.machine_on().unwrap();
    m.home(None).unwrap();
    support::wait_machine(m, "homed and idle", |s| {
        s.mode == Mode::Idle && s.axes.iter().all(|a| a.homed)
    });
}

fn shutdown(m: &Machine) {
    hytask::daemon::Deployed::shutdown(m).unwrap();
}

fn text(name: &str, program: &str) -> JobSource {
    JobSource {
        path: None,
        text: Some(program.into()),
        name: Some(name.into()),
    }
}

/// One machine's e-stop does not cancel another machine's preparation in the same process
/// (a cell, these tests): a runaway program loading on one mill ends at its own budget, not
/// "cancelled by an e-stop", while a second mill is e-stopped again and again. CI once
/// failed `machine_api::many_mdi_coolant_lines_each_apply_their_output_and_end` that way, on
/// the e-stop of that file's `estop` test running beside it.
#[test]
fn an_estop_cancels_only_its_own_machines_preparation() {
    let dir = tempfile::tempdir().unwrap();
    let config = support::sim_clock_config(dir.path(), 0, None);
    let toml = std::fs::read_to_string(&config).unwrap() + "\n[job]\nprepare_timeout_s = 1.5\n";
    std::fs::write(&config, toml).unwrap();
    let loading = Machine::deploy(hytask::config::load(&config).unwrap()).unwrap();
    let (other, _other_dir) = sim_machine();
    ready(&other);
    let runaway = text("runaway", "o1 while [1]\no1 endwhile\nM2\n");
    let t = std::thread::spawn({
        let loading = loading.clone();
        move || loading.job_load(&runaway)
    });
    let mut estops = 0;
    while !t.is_finished() {
        other.estop().unwrap();
        other.estop_reset().unwrap();
        estops += 1;
    }
    match t.join().unwrap() {
        Err(ApiError::Timeout(why)) => assert!(why.contains("1.5 s"), "{why}"),
        other => panic!("after {estops} e-stops of the other machine: {other:?}"),
    }
    assert!(estops > 0);
    shutdown(&loading);
    shutdown(&other);
}
