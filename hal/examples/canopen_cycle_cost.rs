//! Per-cycle CPU cost of the CANopen master for 8 CSP drives on the in-memory bus, side by
//! side with a bare loop that moves the same frames through the same bus (16 TPDOs in,
//! 8 RPDOs + SYNC out) without any protocol work. Issue 9's target: master ≤ 1.5× the bare
//! loop and ≤ 5 µs per cycle.
//!
//! `cargo run --release -p hytask-hal --example canopen_cycle_cost`

use hytask_hal::canopen::cia402::PowerRequest;
use hytask_hal::canopen::master::CspMaster;
use hytask_hal::canopen::pdo::CspLayout;
use hytask_hal::canopen::sync::SyncProducer;
use hytask_hal::canopen::NodeId;
use hytask_hal::sim::{SimCanBus, SimCanPort};
use hytask_hal::{CanBus, CanFrame, CanId};
use std::time::{Duration, Instant};

const DRIVES: usize = 8;
/// Cycles per timed block; each loop is timed in `BLOCKS` blocks, alternating with the
/// other loop, and the fastest block counts: on a shared, loaded host the minimum is the
/// cost of the code, the rest is other processes' time.
const CYCLES: u32 = 10_000;
const BLOCKS: usize = 40;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (_bus, mut ports) = SimCanBus::new(2, 256)?;
    let drives = ports.pop().ok_or("port")?;
    let master_port = ports.pop().ok_or("port")?;
    let mut master = CspMaster::<DRIVES>::new(SyncProducer::new());
    let mut tpdos = Vec::new();
    for n in 1..=DRIVES as u8 {
        let layout = CspLayout::new(NodeId::new(n)?, true)?;
        master.add(layout, Some(Duration::from_secs(3600)), Duration::ZERO)?;
        // Operation enabled, position n, velocity 0, CSP.
        tpdos.push(
            layout
                .tpdo1
                .mapping
                .encode(layout.tpdo1.can_id(), &[0x1237, i64::from(n)])?,
        );
        if let Some(t2) = layout.tpdo2 {
            tpdos.push(t2.mapping.encode(t2.can_id(), &[0, 8])?);
        }
    }
    master.request_all(PowerRequest::Enable);
    let blank = CanFrame::new(CanId::standard(0)?, &[])?;
    let rpdo = CanFrame::new(CanId::standard(0x201)?, &[0x0F, 0, 1, 0, 0, 0])?;
    let sync = CanFrame::new(CanId::standard(0x80)?, &[])?;

    let bare_loop = |p: &mut Ports| {
        for f in &tpdos {
            p.drives.try_send(f).expect("send");
        }
        let n = p.master.recv_into(&mut p.rx).expect("recv");
        std::hint::black_box(&p.rx[..n]);
        for _ in 0..DRIVES {
            p.master.try_send(&rpdo).expect("send");
        }
        p.master.try_send(&sync).expect("send");
        while p.drives.recv_into(&mut p.sink).expect("recv") > 0 {}
    };
    let mut now = Duration::ZERO;
    let mut master_loop = |p: &mut Ports| {
        now += Duration::from_millis(1);
        for f in &tpdos {
            p.drives.try_send(f).expect("send");
        }
        let n = p.master.recv_into(&mut p.rx).expect("recv");
        for f in &p.rx[..n] {
            std::hint::black_box(master.read_frame(f, now));
        }
        while master.check(now).is_some() {}
        for i in 0..DRIVES {
            if let Some(d) = master.drive_mut(i) {
                d.target += 1;
            }
        }
        master.write(&mut p.master).expect("write");
        while p.drives.recv_into(&mut p.sink).expect("recv") > 0 {}
    };
    let mut p = Ports {
        drives,
        master: master_port,
        rx: [blank; 64],
        sink: [blank; 64],
    };
    for _ in 0..1000 {
        bare_loop(&mut p);
        master_loop(&mut p);
    }
    let (mut bare, mut full) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..BLOCKS {
        bare = bare.min(time(|| bare_loop(&mut p)));
        full = full.min(time(|| master_loop(&mut p)));
    }
    println!("{DRIVES} drives, fastest of {BLOCKS} blocks of {CYCLES} cycles on SimCanBus");
    println!("bare frame loop : {:>7.3} µs/cycle", bare);
    println!(
        "CANopen master  : {:>7.3} µs/cycle ({:.2}× the bare loop, {:+.3} µs)",
        full,
        full / bare,
        full - bare
    );
    Ok(())
}

struct Ports {
    drives: SimCanPort,
    master: SimCanPort,
    rx: [CanFrame; 64],
    sink: [CanFrame; 64],
}

fn time(mut f: impl FnMut()) -> f64 {
    let t = Instant::now();
    for _ in 0..CYCLES {
        f();
    }
    t.elapsed().as_secs_f64() * 1e6 / f64::from(CYCLES)
}
