//! The selection state machine shipped as a script (config/scripts/selection.st) compiles
//! with the script engine and binds to the cell's deployed robot and camera tasks and their
//! events: every operation and event name it uses exists; a broken one refuses the cell's
//! deployment with its file:line:col.
#![allow(clippy::unwrap_used)]

use hytask::cell::config::CellConfig;
use hytask::cell::deploy::deploy;
use hytask::cell::names;
use hytask::script::{compile, Bindings};
use std::sync::atomic::AtomicU64;
use std::sync::Arc;

#[test]
fn shipped_selection_script_compiles_and_binds_to_the_cell() {
    let path = "config/scripts/selection.st";
    let src = std::fs::read_to_string(path).unwrap();
    let script = match compile(path, &src) {
        Ok(s) => s,
        Err(e) => panic!("{e}"),
    };
    let cell = deploy(&CellConfig::with_seed(1)).unwrap();
    let mut b = Bindings::default();
    b.peer_task(cell.robot.info()).peer_task(cell.camera.info());
    let grabbed = names::OBJECT_GRABBED_EVENT;
    b.event(
        grabbed,
        cell.deployment.event::<()>(grabbed).unwrap().counter(),
    );
    for e in ["operation_n_done", "error_detected"] {
        b.emit(e, Arc::new(AtomicU64::new(0)));
    }
    if let Err(e) = script.bind(&b) {
        panic!("{e}");
    }
}

/// A selection script with an error refuses the cell's deployment, naming file:line:col.
#[test]
fn a_broken_selection_script_refuses_the_deployment_with_its_place() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.st");
    let src = std::fs::read_to_string("config/scripts/selection.st")
        .unwrap()
        .replace(
            "DO camera.start_detection();",
            "DO camera.start_detecting();",
        );
    std::fs::write(&path, &src).unwrap();
    let line = src
        .lines()
        .position(|l| l.contains("start_detecting"))
        .unwrap()
        + 1;
    let mut cfg = CellConfig::with_seed(1);
    cfg.selection.script = Some(path.clone());
    let e = match deploy(&cfg) {
        Ok(_) => panic!("deployed a broken script"),
        Err(e) => e.to_string(),
    };
    let place = format!("{}:{line}:", path.display());
    assert!(e.contains(&place), "{e}");
    assert!(e.contains("start_detecting"), "{e}");
}
