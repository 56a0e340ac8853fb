//! End to end, sans-IO: the master's codecs and state machines against the loopback CiA 402
//! drive on the in-memory bus. Configuration over SDO, NMT start, the power state machine to
//! Operation enabled, CSP for some hundred cycles, then each injected fault (drive fault,
//! EMCY, heartbeat loss) reported by the master with node and cause.

use super::cia402::{DriveState, Mode, ModeRequest, PowerController, PowerRequest};
use super::emcy::{EmcyConsumer, EmcyEvent};
use super::heartbeat::{HeartbeatConsumer, HeartbeatEvent};
use super::nmt::{NmtCommand, NmtState};
use super::pdo::CspLayout;
use super::sdo::{SdoClient, SdoStep};
use super::slave::{od, DriveSlave, SlaveConfig};
use super::sync::SyncProducer;
use super::{CanOpenError, NodeId};
use crate::can::CanBus;
use crate::error::{Error, ErrorKind};
use crate::sim::{SimCanBus, SimCanPort};
use std::time::Duration;

struct Rig {
    node: NodeId,
    master: SimCanPort,
    slave_port: SimCanPort,
    slave: DriveSlave,
    now: Duration,
    sdo: SdoClient,
    hb: HeartbeatConsumer,
    emcy: EmcyConsumer,
    sync: SyncProducer,
    power: PowerController,
    layout: CspLayout,
    statusword: i64,
    position: i64,
    velocity: i64,
    mode_display: i64,
    target: i64,
    faults: Vec<CanOpenError>,
    cleared: Vec<NodeId>,
    boot_ups: Vec<NodeId>,
}

const MS: Duration = Duration::from_millis(1);

impl Rig {
    fn new() -> Rig {
        let node = NodeId::new(1).unwrap();
        let (_bus, mut ports) = SimCanBus::new(2, 64).unwrap();
        let slave_port = ports.pop().unwrap();
        let master = ports.pop().unwrap();
        Rig {
            node,
            master,
            slave_port,
            slave: DriveSlave::new(node, SlaveConfig::default()),
            now: Duration::ZERO,
            sdo: SdoClient::new(node),
            hb: HeartbeatConsumer::default(),
            emcy: EmcyConsumer::default(),
            sync: SyncProducer::new(),
            power: PowerController::default(),
            layout: CspLayout::new(node, true).unwrap(),
            statusword: 0,
            position: 0,
            velocity: 0,
            mode_display: 0,
            target: 0,
            faults: Vec::new(),
            cleared: Vec::new(),
            boot_ups: Vec::new(),
        }
    }

    fn pump_slave(&mut self) {
        self.slave.poll(&mut self.slave_port, self.now).unwrap();
    }

    /// Routes one received frame to the master's consumers.
    fn route(&mut self, f: &crate::can::CanFrame) {
        let l = &self.layout;
        let mut v = [0i64; 8];
        if f.id() == l.tpdo1.can_id() {
            l.tpdo1
                .mapping
                .decode(f.data(), &[false, true], &mut v)
                .unwrap();
            self.statusword = v[0];
            self.position = v[1];
        } else if l.tpdo2.is_some_and(|p| f.id() == p.can_id()) {
            let p = l.tpdo2.unwrap();
            p.mapping.decode(f.data(), &[true, true], &mut v).unwrap();
            self.velocity = v[0];
            self.mode_display = v[1];
        } else if let Some(ev) = self.hb.on_frame(f, self.now) {
            if let HeartbeatEvent::BootUp(n) = ev {
                self.boot_ups.push(n);
            }
        } else if let Some(ev) = self.emcy.on_frame(f) {
            match ev {
                EmcyEvent::Fault(e) => self.faults.push(e),
                EmcyEvent::Cleared(n) => self.cleared.push(n),
            }
        }
    }

    /// A confirmed SDO transfer on the non-realtime path: send, let the slave answer, feed
    /// the client, until done.
    fn sdo(&mut self, first: crate::can::CanFrame) -> SdoStep {
        let mut to_send = first;
        for _ in 0..200 {
            self.master.try_send(&to_send).unwrap();
            self.pump_slave();
            let mut next = None;
            while let Some(f) = self.master.try_recv().unwrap() {
                match self.sdo.on_frame(&f, self.now) {
                    SdoStep::Ignored => self.route(&f),
                    SdoStep::Send(f) => next = Some(f),
                    done => return done,
                }
            }
            match next {
                Some(f) => to_send = f,
                None => panic!("SDO server did not answer"),
            }
        }
        panic!("SDO transfer did not end")
    }

    fn read(&mut self, index: u16, sub: u8) -> Vec<u8> {
        let f = self.sdo.upload(index, sub, self.now).unwrap();
        match self.sdo(f) {
            SdoStep::Uploaded(v) => v,
            other => panic!("read {index:04X}:{sub}: {other:?}"),
        }
    }

    fn write(&mut self, index: u16, sub: u8, data: &[u8]) {
        let f = self.sdo.download(index, sub, data, self.now).unwrap();
        assert_eq!(self.sdo(f), SdoStep::Downloaded, "write {index:04X}:{sub}");
    }

    /// One servo cycle in the order: read what arrived since the last SYNC, run
    /// the tasks (power state machine, heartbeat check), write the RPDO, send SYNC; then
    /// the drive reacts (it answers the SYNC with its TPDOs, read next cycle).
    fn cycle(&mut self) {
        self.now += MS;
        while let Some(f) = self.master.try_recv().unwrap() {
            self.route(&f);
        }
        while let Some(e) = self.hb.check(self.now) {
            self.faults.push(e);
        }
        // Bits 0-3 and 7 only; the layout's u16 statusword cannot exceed u16.
        let sw = self.statusword as u16;
        if DriveState::from_statusword(sw).is_fault()
            && !self
                .faults
                .iter()
                .any(|e| matches!(e, CanOpenError::DriveFault { .. }))
        {
            self.faults.push(CanOpenError::DriveFault {
                node: self.node,
                statusword: sw,
            });
        }
        let cw = self.power.step(sw);
        let rpdo = self.layout.rpdo1;
        let f = rpdo
            .mapping
            .encode(rpdo.can_id(), &[i64::from(cw), self.target])
            .unwrap();
        self.master.try_send(&f).unwrap();
        self.master.try_send(&self.sync.next_frame()).unwrap();
        self.pump_slave();
    }

    fn state(&self) -> DriveState {
        DriveState::from_statusword(self.statusword as u16)
    }

    fn cycles_until(&mut self, max: usize, what: &str, done: impl Fn(&Rig) -> bool) -> usize {
        for i in 0..max {
            if done(self) {
                return i;
            }
            self.cycle();
        }
        panic!(
            "{what} not reached within {max} cycles (state {})",
            self.state()
        )
    }
}

#[test]
fn master_configures_enables_runs_csp_and_reports_each_injected_fault() {
    let mut r = Rig::new();
    r.pump_slave();
    while let Some(f) = r.master.try_recv().unwrap() {
        r.route(&f);
    }
    assert_eq!(r.boot_ups, [r.node], "boot-up detected");
    assert_eq!(r.hb.state(r.node), Some(NmtState::PreOperational));

    // Identity, device type, a segmented upload.
    assert_eq!(r.read(0x1000, 0), od::DEVICE_TYPE.to_le_bytes());
    assert_eq!(r.read(0x1008, 0), od::DEVICE_NAME.as_bytes());
    assert_eq!(r.read(0x1018, 2), od::PRODUCT_CODE.to_le_bytes());

    // PDO configuration over SDO: disable → clear → map → enable.
    for w in r.layout.sdo_writes() {
        r.write(w.index, w.sub, &w.data);
    }
    assert_eq!(r.read(0x1A01, 1), 0x606C_0020u32.to_le_bytes());
    r.write(0x1017, 0, &10u16.to_le_bytes());
    r.write(0x6060, 0, &[Mode::CyclicSyncPosition.code() as u8]);
    let mut mode = ModeRequest::new(Mode::CyclicSyncPosition);
    assert!(
        mode.on_display(r.read(0x6061, 0)[0] as i8),
        "mode confirmed by 0x6061"
    );

    r.hb.watch(r.node, Duration::from_millis(30), r.now);
    r.master
        .try_send(&NmtCommand::Start.frame(Some(r.node)))
        .unwrap();
    r.pump_slave();
    assert_eq!(r.slave.nmt_state(), Some(NmtState::Operational));

    // Power state machine to Operation enabled, one transition per cycle.
    r.power.request(PowerRequest::Enable);
    let n = r.cycles_until(20, "Operation enabled", |r| {
        r.state() == DriveState::OperationEnabled
    });
    assert!(n <= 6, "{n} cycles");
    assert_eq!(r.mode_display, 8, "TPDO2 shows CSP");

    // CSP: 20 counts per cycle (20 000 counts/s) for 500 cycles, then hold.
    let start = r.position;
    let mut max_lag = 0;
    for k in 1..=500 {
        r.target = start + 20 * k;
        r.cycle();
        if k > 100 {
            max_lag = max_lag.max((r.target - r.position).abs());
            assert!(
                (r.velocity - 20_000).abs() <= 1,
                "cycle {k}: velocity {}",
                r.velocity
            );
        }
    }
    // Lag 2 ms at 20 000 counts/s = 40 counts, plus one cycle of feedback delay.
    assert!((40..=61).contains(&max_lag), "following distance {max_lag}");
    r.cycles_until(200, "settled on target", |r| {
        r.position == r.target && r.velocity == 0
    });
    assert_eq!(r.position, start + 10_000);
    assert!(r.faults.is_empty(), "{:?}", r.faults);

    // 1. Drive fault: EMCY naming node and code, statusword Fault, then fault reset.
    r.write(od::INJECT, 1, &0x2310u16.to_le_bytes());
    // The machine's reaction to a fault: a controlled stop, no automatic reset.
    r.power.request(PowerRequest::Disable);
    r.cycles_until(50, "Fault", |r| r.state() == DriveState::Fault);
    let emcy = r
        .faults
        .iter()
        .find(|e| matches!(e, CanOpenError::Emergency { .. }))
        .unwrap();
    assert_eq!(emcy.kind(), ErrorKind::DeviceFault);
    let msg = emcy.to_string();
    assert!(
        msg.starts_with("node 1: emergency 0x2310 (current, device output side)"),
        "{msg}"
    );
    assert!(r
        .faults
        .iter()
        .any(|e| matches!(e, CanOpenError::DriveFault { node, .. } if *node == r.node)));
    assert_eq!(r.read(0x603F, 0), 0x2310u16.to_le_bytes());
    assert_eq!(r.read(0x1001, 0), [0x03], "generic + current");
    r.power.request(PowerRequest::Enable);
    r.cycles_until(20, "re-enabled after fault reset", |r| {
        r.state() == DriveState::OperationEnabled
    });
    assert_eq!(
        r.cleared,
        [r.node],
        "EMCY error reset after the fault reset"
    );
    r.faults.clear();

    // 2. An EMCY without a fault.
    r.write(od::INJECT, 3, &0x4210u16.to_le_bytes());
    r.cycle();
    assert!(
        matches!(&r.faults[..], [CanOpenError::Emergency { node, emcy }] if *node == r.node && emcy.code == 0x4210),
        "{:?}",
        r.faults
    );
    assert_eq!(r.state(), DriveState::OperationEnabled);
    r.faults.clear();

    // 3. Heartbeat loss.
    for _ in 0..40 {
        r.cycle();
    }
    assert!(r.faults.is_empty(), "heartbeat runs: {:?}", r.faults);
    r.write(od::INJECT, 2, &[1]);
    r.cycles_until(50, "heartbeat loss", |r| !r.faults.is_empty());
    let lost = &r.faults[0];
    assert_eq!(lost.kind(), ErrorKind::Timeout);
    assert!(
        lost.to_string().starts_with("node 1: heartbeat lost"),
        "{lost}"
    );
}

/// Configures `slave` with `layout` over SDO through `master` (non-realtime path).
fn configure(
    master: &mut SimCanPort,
    slave: &mut DriveSlave,
    port: &mut SimCanPort,
    writes: &[super::pdo::SdoWrite],
) {
    let mut sdo = SdoClient::new(slave.node());
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
                other => panic!("{:04X}:{}: {other:?}", w.index, w.sub),
            }
        }
    }
}

#[test]
fn csp_master_runs_three_drives_and_names_the_lost_and_rebooted_node() {
    use super::master::{CspMaster, MasterEvent};
    use super::pdo::SdoWrite;
    let (_bus, mut ports) = SimCanBus::new(4, 256).unwrap();
    let mut port = ports.remove(0);
    let mut slaves: Vec<DriveSlave> = (1..=3)
        .map(|n| {
            DriveSlave::new(
                NodeId::new(n).unwrap(),
                SlaveConfig {
                    heartbeat_ms: 10,
                    ..SlaveConfig::default()
                },
            )
        })
        .collect();
    let mut m = CspMaster::<8>::new(SyncProducer::with_counter(16));
    let mut now = Duration::ZERO;
    let mut events = Vec::new();
    for (s, p) in slaves.iter_mut().zip(ports.iter_mut()) {
        s.poll(p, now).unwrap();
    }
    while let Some(f) = port.try_recv().unwrap() {
        events.extend(m.read_frame(&f, now));
    }
    assert_eq!(events.len(), 3, "three boot-ups: {events:?}");
    for (s, p) in slaves.iter_mut().zip(ports.iter_mut()) {
        let layout = CspLayout::new(s.node(), true).unwrap();
        let mut writes = layout.sdo_writes();
        writes.push(SdoWrite {
            index: 0x6060,
            sub: 0,
            data: vec![8],
        });
        configure(&mut port, s, p, &writes);
        m.add(layout, Some(Duration::from_millis(30)), now).unwrap();
    }
    port.try_send(&NmtCommand::Start.frame(None)).unwrap();
    m.request_all(PowerRequest::Enable);
    events.clear();

    let run = |m: &mut CspMaster<8>,
               slaves: &mut [DriveSlave],
               ports: &mut [SimCanPort],
               port: &mut SimCanPort,
               now: &mut Duration,
               cycles: usize,
               events: &mut Vec<MasterEvent>| {
        for _ in 0..cycles {
            *now += MS;
            while let Some(f) = port.try_recv().unwrap() {
                events.extend(m.read_frame(&f, *now));
            }
            while let Some(e) = m.check(*now) {
                events.push(MasterEvent::Fault(e));
            }
            for i in 0..3 {
                let d = m.drive_mut(i).unwrap();
                if d.state() == DriveState::OperationEnabled {
                    d.target += 10 * (i as i32 + 1);
                }
            }
            m.write(port).unwrap();
            for (s, p) in slaves.iter_mut().zip(ports.iter_mut()) {
                s.poll(p, *now).unwrap();
            }
        }
    };
    run(
        &mut m,
        &mut slaves,
        &mut ports,
        &mut port,
        &mut now,
        300,
        &mut events,
    );
    assert!(events.is_empty(), "{events:?}");
    for i in 0..3 {
        let d = m.drive(i).unwrap();
        assert_eq!(d.state(), DriveState::OperationEnabled);
        assert_eq!(d.mode_display, 8);
        let speed = 10_000 * (i as i32 + 1);
        assert!((d.velocity - speed).abs() <= 1, "drive {i}: {}", d.velocity);
        assert!(
            (d.target - d.position).abs() < speed / 100 + 20 * (i as i32 + 1) + 2,
            "drive {i}"
        );
    }

    // Node 2 stops its heartbeat: the master names it, and only it.
    let mut out = super::Outbox::default();
    let stop = {
        let mut c = SdoClient::new(slaves[1].node());
        c.download(od::INJECT, 2, &[1], now).unwrap()
    };
    slaves[1].on_frame(&stop, now, &mut out);
    run(
        &mut m,
        &mut slaves,
        &mut ports,
        &mut port,
        &mut now,
        40,
        &mut events,
    );
    let lost: Vec<String> = events.iter().map(|e| format!("{e:?}")).collect();
    assert!(
        matches!(&events[..], [MasterEvent::Fault(CanOpenError::HeartbeatLost { node, .. })] if node.get() == 2),
        "{lost:?}"
    );
    events.clear();

    // Node 3 resets: an unexpected boot-up, a fault naming it.
    port.try_send(&NmtCommand::ResetNode.frame(Some(slaves[2].node())))
        .unwrap();
    run(
        &mut m,
        &mut slaves,
        &mut ports,
        &mut port,
        &mut now,
        3,
        &mut events,
    );
    assert!(
        events.iter().any(|e| matches!(e, MasterEvent::Fault(CanOpenError::UnexpectedBootUp { node }) if node.get() == 3)),
        "{events:?}"
    );
}
