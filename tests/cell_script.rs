//! The selection state machine shipped as a script (config/scripts/selection.st) compiles
//! with the script engine and binds to the cell's deployed robot and camera tasks and their
//! events: every operation and event name it uses exists.
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
