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
use hytask_hal::sim::SimCanBus;
use hytask_hal::{CanBus, CanFrame, CanId};
use std::time::{Duration, Instant};

const DRIVES: usize = 8;
const CYCLES: u32 = 200_000;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (_bus, mut ports) = SimCanBus::new(2, 256)?;
    let mut drives = ports.pop().ok_or("port")?;
    let mut master_port = ports.pop().ok_or("port")?;
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
    let mut rx = [blank; 64];
    let mut sink = [blank; 64];
    let rpdo = CanFrame::new(CanId::standard(0x201)?, &[0x0F, 0, 1, 0, 0, 0])?;
    let sync = CanFrame::new(CanId::standard(0x80)?, &[])?;

    let bare = time(|| {
        for f in &tpdos {
            drives.try_send(f).expect("send");
        }
        let n = master_port.recv_into(&mut rx).expect("recv");
        std::hint::black_box(&rx[..n]);
        for _ in 0..DRIVES {
            master_port.try_send(&rpdo).expect("send");
        }
        master_port.try_send(&sync).expect("send");
        while drives.recv_into(&mut sink).expect("recv") > 0 {}
    });
    let mut now = Duration::ZERO;
    let full = time(|| {
        now += Duration::from_millis(1);
        for f in &tpdos {
            drives.try_send(f).expect("send");
        }
        let n = master_port.recv_into(&mut rx).expect("recv");
        for f in &rx[..n] {
            std::hint::black_box(master.read_frame(f, now));
        }
        while master.check(now).is_some() {}
        for i in 0..DRIVES {
            if let Some(d) = master.drive_mut(i) {
                d.target += 1;
            }
        }
        master.write(&mut master_port).expect("write");
        while drives.recv_into(&mut sink).expect("recv") > 0 {}
    });
    println!("{DRIVES} drives, {CYCLES} cycles on SimCanBus");
    println!("bare frame loop : {:>7.3} µs/cycle", bare);
    println!(
        "CANopen master  : {:>7.3} µs/cycle ({:.2}× the bare loop, {:+.3} µs)",
        full,
        full / bare,
        full - bare
    );
    Ok(())
}

fn time(mut f: impl FnMut()) -> f64 {
    for _ in 0..1000 {
        f();
    }
    let t = Instant::now();
    for _ in 0..CYCLES {
        f();
    }
    t.elapsed().as_secs_f64() * 1e6 / f64::from(CYCLES)
}
