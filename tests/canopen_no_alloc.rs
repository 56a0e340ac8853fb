//! The realtime rule with CANopen axes: a whole servo cycle of the machine on
//! `config/vcan.toml` (interface switched to the in-process `sim` bus) allocates nothing in
//! steady state: `can.sim.rx` (TPDOs, heartbeats, EMCY, checks), the machine's tasks, the
//! three `axis.*` tasks on CANopen axes through the erased HAL traits, `can.sim.tx` (RPDOs,
//! SYNC) and the loopback drives answering the SYNC. The cycles run on the stepped runtime
//! on this thread, under a counting allocator, through a feed move and an e-stop (quick
//! stop over the controlword). Start-up (SDO, allowed to allocate) runs before.
#![allow(clippy::unwrap_used)]

use hytask::gcode::SourceLoc;
use hytask::machine::servo::machine_task::MachineCmd;
use hytask::machine::servo::QueueItem;
use std::sync::Arc;

mod counting_alloc;

use counting_alloc::so_far as allocations;

mod machine_rig;

#[test]
fn a_servo_cycle_with_canopen_axes_allocates_nothing() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("config/vcan.toml"))
        .unwrap()
        .replace("interface = \"vcan0\"", "interface = \"sim\"");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("canopen-sim.toml");
    std::fs::write(&path, text).unwrap();
    let cfg = hytask::config::load(&path).unwrap();
    let h = machine_rig::homed_with(&cfg, |app| {
        let names: Vec<String> = app.tasks().iter().map(|t| t.name().to_string()).collect();
        assert_eq!(
            names.first().map(String::as_str),
            Some("can.sim.rx"),
            "{names:?}"
        );
        let tx = names.iter().position(|n| n == "can.sim.tx").unwrap();
        assert!(
            names[tx - 1].starts_with("axis.") && names[tx + 1] == "monitor",
            "{names:?}"
        );
    });
    let machine_rig::Homed {
        mut rt,
        machine,
        queue,
        motion_cfg,
        sim_io,
        mut fb,
        start,
    } = h;
    let mut end = start;
    end[..3].copy_from_slice(&[40.0, 30.0, -10.0]);
    let loc = SourceLoc {
        file: Arc::from("t"),
        line: 1,
        col: 1,
    };
    let plan = hytask::motion::plan_straight_feed(start, end, 3000.0, loc, &motion_cfg).unwrap();
    for &item in &plan.items {
        queue.try_push(QueueItem { job: 1, item }).unwrap();
    }
    let run = MachineCmd::Run {
        job: 1,
        items: plan.items.len() as u64,
        manual: false,
    };
    let _running = machine.send(run).unwrap();
    rt.run_cycles(50); // warm-up: the first cycles of a job touch everything once
    let estop = sim_io[0].clone().unwrap();

    let before = allocations();
    rt.run_cycles(400);
    estop.set_digital_input(0, true).unwrap();
    rt.run_cycles(300);
    let during = allocations() - before;

    let x = fb[0].latest().unwrap();
    assert!(x.actual > start[0] + 1.0, "the machine moved: {x:?}");
    assert!(x.link.is_none() && x.valid, "{x:?}");
    assert_eq!(during, 0, "{during} allocations in 700 servo cycles");
}
