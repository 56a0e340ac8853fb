//! The realtime rule for the CANopen layer, checked with a counting allocator: one servo
//! cycle of the [`CspMaster`] for 8 CiA 402 drives (read TPDOs, heartbeat and EMCY
//! consumers, drive-fault check, power state machine, encode RPDOs, SYNC) allocates nothing, and neither does the loopback
//! drive's SYNC/PDO path. SDO configuration runs before the measurement (it may allocate).
#![allow(clippy::unwrap_used)]

use hytask_hal::canopen::cia402::{PowerRequest, State402};
use hytask_hal::canopen::master::CspMaster;
use hytask_hal::canopen::nmt::NmtCommand;
use hytask_hal::canopen::pdo::{CspLayout, SdoWrite};
use hytask_hal::canopen::sdo::{SdoClient, SdoStep};
use hytask_hal::canopen::slave::{DriveSlave, SlaveConfig};
use hytask_hal::canopen::sync::SyncProducer;
use hytask_hal::canopen::NodeId;
use hytask_hal::sim::{SimCanBus, SimCanPort};
use hytask_hal::{CanBus, CanFrame, CanId};
use std::time::Duration;

mod counting_alloc;

use counting_alloc::allocations_during;

const DRIVES: usize = 8;

fn configure(
    master: &mut SimCanPort,
    slave: &mut DriveSlave,
    port: &mut SimCanPort,
    layout: &CspLayout,
) {
    let mut sdo = SdoClient::new(slave.node());
    let mut writes = layout.sdo_writes();
    writes.push(SdoWrite {
        index: 0x6060,
        sub: 0,
        data: vec![8],
    });
    for w in writes {
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
}

#[test]
fn a_servo_cycle_with_8_canopen_drives_does_not_allocate() {
    let (_bus, mut ports) = SimCanBus::new(DRIVES + 1, 1024).unwrap();
    let mut port = ports.remove(0);
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
    let mut master = CspMaster::<DRIVES>::new(SyncProducer::with_counter(240));
    for (s, p) in slaves.iter_mut().zip(ports.iter_mut()) {
        s.poll(p, Duration::ZERO).unwrap();
    }
    while port.try_recv().unwrap().is_some() {}
    for (s, p) in slaves.iter_mut().zip(ports.iter_mut()) {
        let layout = CspLayout::new(s.node(), true).unwrap();
        configure(&mut port, s, p, &layout);
        master
            .add(layout, Some(Duration::from_millis(30)), Duration::ZERO)
            .unwrap();
    }
    port.try_send(&NmtCommand::Start.frame(None)).unwrap();
    master.request_all(PowerRequest::Enable);
    let mut rx = [CanFrame::new(CanId::standard(0).unwrap(), &[]).unwrap(); 64];
    let mut events = 0usize;
    let mut now = Duration::ZERO;

    let mut cycle = |master: &mut CspMaster<DRIVES>, port: &mut SimCanPort, now: Duration| {
        let n = port.recv_into(&mut rx).unwrap();
        for f in &rx[..n] {
            if master.read_frame(f, now).is_some() {
                events += 1;
            }
        }
        while master.check(now).is_some() {
            events += 1;
        }
        for i in 0..DRIVES {
            let d = master.drive_mut(i).unwrap();
            if d.state() == State402::OperationEnabled {
                d.target += 5;
            }
        }
        master.write(port).unwrap();
    };

    // Warm up to Operation enabled, outside the measurement.
    for _ in 0..20 {
        now += Duration::from_millis(1);
        cycle(&mut master, &mut port, now);
        for (s, p) in slaves.iter_mut().zip(ports.iter_mut()) {
            s.poll(p, now).unwrap();
        }
    }
    assert!((0..DRIVES).all(|i| master.drive(i).unwrap().state() == State402::OperationEnabled));

    let mut master_allocs = 0;
    let mut slave_allocs = 0;
    for _ in 0..200 {
        now += Duration::from_millis(1);
        master_allocs += allocations_during(|| cycle(&mut master, &mut port, now));
        slave_allocs += allocations_during(|| {
            for (s, p) in slaves.iter_mut().zip(ports.iter_mut()) {
                s.poll(p, now).unwrap();
            }
        });
    }
    assert_eq!(master_allocs, 0, "master cycle allocated");
    assert_eq!(slave_allocs, 0, "loopback drive SYNC/PDO path allocated");
    assert_eq!(events, 0);
    assert!(
        (0..DRIVES).all(|i| master.drive(i).unwrap().velocity == 5000),
        "drives follow the target"
    );
}

/// The loopback drive's SDO server path: expedited and segmented upload and download, and
/// a block upload, answered by [`DriveSlave::poll`] without allocating (the server's value
/// buffer and the drive's domain are reserved when they are made). The client side, which
/// allocates its payloads, runs outside the measurement.
#[test]
fn the_loopback_drives_sdo_server_does_not_allocate() {
    let (_bus, mut ports) = SimCanBus::new(2, 4096).unwrap();
    let mut drive_port = ports.pop().unwrap();
    let mut port = ports.pop().unwrap();
    let node = NodeId::new(4).unwrap();
    let mut slave = DriveSlave::new(node, SlaveConfig::default());
    slave.poll(&mut drive_port, Duration::ZERO).unwrap();
    while port.try_recv().unwrap().is_some() {}
    let mut allocs = 0;
    let mut now = Duration::ZERO;
    // One transfer to its end: the slave's polls are measured, the client's work is not.
    let mut transfer = |client: &mut SdoClient, first: CanFrame| -> Vec<u8> {
        port.try_send(&first).unwrap();
        loop {
            now += Duration::from_millis(1);
            allocs += allocations_during(|| slave.poll(&mut drive_port, now).unwrap());
            while let Some(f) = port.try_recv().unwrap() {
                match client.on_frame(&f, now) {
                    SdoStep::Ignored => {}
                    SdoStep::Send(next) => port.try_send(&next).unwrap(),
                    SdoStep::SendBlock(frames) => {
                        frames.iter().for_each(|f| port.try_send(f).unwrap())
                    }
                    SdoStep::Downloaded => return Vec::new(),
                    SdoStep::Uploaded(v) => return v,
                    SdoStep::BlockUploaded { value, confirm } => {
                        port.try_send(&confirm).unwrap();
                        allocs += allocations_during(|| slave.poll(&mut drive_port, now).unwrap());
                        return value;
                    }
                    other => panic!("{other:?}"),
                }
            }
        }
    };
    let t = Duration::ZERO;
    let domain: Vec<u8> = (0..300u16).map(|i| i as u8).collect();
    for _ in 0..2 {
        let mut c = SdoClient::new(node).with_block_threshold(None);
        let sw = c.upload(0x6041, 0, t).unwrap();
        assert_eq!(transfer(&mut c, sw).len(), 2, "expedited upload");
        let w = c.download(0x6065, 0, &1000u32.to_le_bytes(), t).unwrap();
        transfer(&mut c, w);
        let name = c.upload(0x1008, 0, t).unwrap();
        assert!(transfer(&mut c, name).len() > 4, "segmented upload");
        let d = c.download(0x2001, 0, &domain, t).unwrap();
        transfer(&mut c, d);
        let mut b = SdoClient::new(node);
        let up = b.upload_block(0x2001, 0, t).unwrap();
        assert_eq!(transfer(&mut b, up), domain, "block upload");
    }
    assert_eq!(allocs, 0, "the loopback drive's SDO server allocated");
}
