//! The realtime rule for the CANopen layer, checked with a counting allocator: one servo
//! cycle of the master for 8 CiA 402 drives (read TPDOs, heartbeat and EMCY consumers, power
//! state machine, encode RPDOs, SYNC) allocates nothing, and neither does the loopback
//! drive's SYNC/PDO path. SDO configuration runs before the measurement (it may allocate).
#![allow(clippy::unwrap_used)]

use hytask_hal::canopen::cia402::{PowerController, PowerRequest, State402};
use hytask_hal::canopen::emcy::EmcyConsumer;
use hytask_hal::canopen::heartbeat::HeartbeatConsumer;
use hytask_hal::canopen::nmt::NmtCommand;
use hytask_hal::canopen::pdo::CspLayout;
use hytask_hal::canopen::sdo::{SdoClient, SdoStep};
use hytask_hal::canopen::slave::{DriveSlave, SlaveConfig};
use hytask_hal::canopen::sync::SyncProducer;
use hytask_hal::canopen::NodeId;
use hytask_hal::sim::{SimCanBus, SimCanPort};
use hytask_hal::{CanBus, CanFrame};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::time::Duration;

struct Counting;

thread_local! {
    static MEASURING: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

fn note() {
    let _ = MEASURING.try_with(|m| {
        if m.get() {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        }
    });
}

// SAFETY: forwards to the system allocator unchanged; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

fn allocations_during(f: impl FnOnce()) -> usize {
    COUNT.with(|c| c.set(0));
    MEASURING.with(|m| m.set(true));
    f();
    MEASURING.with(|m| m.set(false));
    COUNT.with(Cell::get)
}

#[test]
fn the_allocator_counts() {
    let n = allocations_during(|| drop(std::hint::black_box(vec![1u8; 16])));
    assert_eq!(n, 1, "the test would be blind otherwise");
}

const DRIVES: usize = 8;

struct Axis {
    layout: CspLayout,
    power: PowerController,
    statusword: i64,
    position: i64,
    target: i64,
}

fn configure(
    master: &mut SimCanPort,
    slave: &mut DriveSlave,
    port: &mut SimCanPort,
    layout: &CspLayout,
) {
    let mut sdo = SdoClient::new(slave.node());
    for w in layout.sdo_writes() {
        let mut f = sdo
            .download(w.index, w.sub, &w.data, Duration::ZERO)
            .unwrap();
        loop {
            master.try_send(&f).unwrap();
            slave.poll(port, Duration::ZERO).unwrap();
            let reply = master.try_recv().unwrap().unwrap();
            match sdo.on_frame(&reply, Duration::ZERO) {
                SdoStep::Send(next) => f = next,
                SdoStep::Downloaded => break,
                other => panic!("{other:?}"),
            }
        }
    }
    let mut sdo = SdoClient::new(slave.node());
    let f = sdo.download(0x6060, 0, &[8], Duration::ZERO).unwrap();
    master.try_send(&f).unwrap();
    slave.poll(port, Duration::ZERO).unwrap();
    assert!(matches!(
        sdo.on_frame(&master.try_recv().unwrap().unwrap(), Duration::ZERO),
        SdoStep::Downloaded
    ));
}

#[test]
fn a_servo_cycle_with_8_canopen_drives_does_not_allocate() {
    let (_bus, mut ports) = SimCanBus::new(DRIVES + 1, 256).unwrap();
    let mut master = ports.remove(0);
    let mut slaves: Vec<DriveSlave> = (1..=DRIVES)
        .map(|n| {
            DriveSlave::new(
                NodeId::new(n as u8).unwrap(),
                SlaveConfig {
                    heartbeat_ms: 10,
                    ..SlaveConfig::default()
                },
            )
        })
        .collect();
    for (s, p) in slaves.iter_mut().zip(ports.iter_mut()) {
        s.poll(p, Duration::ZERO).unwrap();
    }
    while master.try_recv().unwrap().is_some() {}
    let mut axes: Vec<Axis> = slaves
        .iter()
        .map(|s| Axis {
            layout: CspLayout::new(s.node(), false).unwrap(),
            power: PowerController::default(),
            statusword: 0,
            position: 0,
            target: 0,
        })
        .collect();
    for ((s, p), a) in slaves.iter_mut().zip(ports.iter_mut()).zip(&axes) {
        configure(&mut master, s, p, &a.layout);
    }
    master.try_send(&NmtCommand::Start.frame(None)).unwrap();
    let mut hb = HeartbeatConsumer::default();
    for s in &slaves {
        hb.watch(s.node(), Duration::from_millis(30), Duration::ZERO);
    }
    let mut emcy = EmcyConsumer::default();
    let mut sync = SyncProducer::with_counter(240);
    for a in &mut axes {
        a.power.request(PowerRequest::Enable);
    }
    let mut rx = [CanFrame::new(hytask_hal::CanId::standard(0).unwrap(), &[]).unwrap(); 64];
    let mut faults = 0usize;
    let mut now = Duration::ZERO;

    let mut cycle = |axes: &mut [Axis], master: &mut SimCanPort, now: Duration| {
        let n = master.recv_into(&mut rx).unwrap();
        for f in &rx[..n] {
            let mut v = [0i64; 8];
            if let Some(a) = axes.iter_mut().find(|a| f.id() == a.layout.tpdo1.can_id()) {
                a.layout
                    .tpdo1
                    .mapping
                    .decode(f.data(), &[false, true], &mut v)
                    .unwrap();
                a.statusword = v[0];
                a.position = v[1];
            } else if hb.on_frame(f, now).is_none() && emcy.on_frame(f).is_some() {
                faults += 1;
            }
        }
        while hb.check(now).is_some() {
            faults += 1;
        }
        for a in axes.iter_mut() {
            let cw = a.power.step(a.statusword as u16);
            a.target += 5;
            let r = a.layout.rpdo1;
            master
                .try_send(
                    &r.mapping
                        .encode(r.can_id(), &[i64::from(cw), a.target])
                        .unwrap(),
                )
                .unwrap();
        }
        master.try_send(&sync.next_frame()).unwrap();
    };

    // Warm up to Operation enabled, outside the measurement.
    for _ in 0..20 {
        now += Duration::from_millis(1);
        cycle(&mut axes, &mut master, now);
        for (s, p) in slaves.iter_mut().zip(ports.iter_mut()) {
            s.poll(p, now).unwrap();
        }
    }
    assert!(axes
        .iter()
        .all(|a| State402::from_statusword(a.statusword as u16) == State402::OperationEnabled));

    let mut master_allocs = 0;
    let mut slave_allocs = 0;
    for _ in 0..200 {
        now += Duration::from_millis(1);
        master_allocs += allocations_during(|| cycle(&mut axes, &mut master, now));
        slave_allocs += allocations_during(|| {
            for (s, p) in slaves.iter_mut().zip(ports.iter_mut()) {
                s.poll(p, now).unwrap();
            }
        });
    }
    assert_eq!(master_allocs, 0, "master cycle allocated");
    assert_eq!(slave_allocs, 0, "loopback drive SYNC/PDO path allocated");
    assert_eq!(faults, 0);
    assert!(
        axes.iter().all(|a| a.position > 500),
        "drives follow the target"
    );
}
