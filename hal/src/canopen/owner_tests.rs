//! The bus owner's halves and the start-up against loopback drives on the in-memory bus:
//! start-up configures and starts every node, a node that does not answer names itself,
//! and a cycle through the halves enables a drive and follows targets through its link.

use super::axis::{CanAxis, DriveLink, LinkCause};
use super::owner::{BusDrive, BusRx, BusTx, SimDrives};
use super::pdo::CspLayout;
use super::slave::{DriveSlave, SlaveConfig};
use super::startup::{start_nodes, NodePlan, StartupError};
use super::sync::SyncProducer;
use super::NodeId;
use crate::axis::{AxisDrive, AxisFeedback, DriveState};
use crate::sim::SimCanBus;
use crate::sim::SimCanPort;
use std::sync::Arc;
use std::time::Duration;

const MS: Duration = Duration::from_millis(1);

fn plan(node: u8) -> NodePlan {
    let node = NodeId::new(node).unwrap();
    NodePlan {
        node,
        layout: CspLayout::new(node, true).unwrap(),
        heartbeat_ms: 20,
        sdo_timeout: 50 * MS,
        homing: None,
    }
}

#[test]
fn a_node_that_does_not_boot_names_itself() {
    let (_wire, mut ports) = SimCanBus::new(2, 1024).unwrap();
    let slaves = ports.pop().unwrap();
    let mut master = ports.pop().unwrap();
    let mut sim = SimDrives::new(
        slaves,
        vec![DriveSlave::new(
            NodeId::new(1).unwrap(),
            SlaveConfig::default(),
        )],
    );
    let mut pass = || sim.step_by(MS);
    let err =
        start_nodes("sim", &mut master, &[plan(1), plan(2)], 200 * MS, &mut pass).unwrap_err();
    assert!(
        matches!(err, StartupError::NoBootUp { node, .. } if node.get() == 2),
        "{err}"
    );
    assert_eq!(
        err.to_string(),
        "sim: node 2 did not answer: no boot-up within 200 ms after NMT reset communication"
    );
}

#[test]
fn start_up_then_cycles_enable_a_drive_and_follow_targets_and_a_lost_heartbeat_names_the_node() {
    let (_wire, mut ports) = SimCanBus::new(4, 1024).unwrap();
    let slaves = ports.pop().unwrap();
    let mut cfg_port = ports.pop().unwrap();
    let tx_port = ports.pop().unwrap();
    let rx_port = ports.pop().unwrap();
    let node = NodeId::new(5).unwrap();
    let mut sim = SimDrives::new(slaves, vec![DriveSlave::new(node, SlaveConfig::default())]);
    let p = plan(5);
    let mut t = Duration::ZERO;
    {
        let mut pass = || {
            t = sim.step_by(MS);
            t
        };
        start_nodes(
            "sim",
            &mut cfg_port,
            std::slice::from_ref(&p),
            200 * MS,
            &mut pass,
        )
        .unwrap();
    }
    let link = DriveLink::new(node);
    let drives = [BusDrive {
        link: link.clone(),
        layout: p.layout,
        heartbeat_timeout: Some(50 * MS),
    }];
    let mut rx = BusRx::new(rx_port, &drives).unwrap();
    let mut tx = BusTx::new(tx_port, &drives, SyncProducer::new()).unwrap();
    let mut axis = CanAxis::new(link.clone(), 100.0);
    let mut cycle = |axis: &mut CanAxis, target: Option<f64>| {
        t += MS;
        rx.cycle_start(t);
        if let Some(x) = target {
            let _ = axis.set_target_position(x);
        }
        tx.cycle_end();
        sim.step(t);
    };
    axis.enable().unwrap();
    for _ in 0..10 {
        cycle(&mut axis, None);
    }
    assert_eq!(axis.drive_state().unwrap(), DriveState::OperationEnabled);
    for i in 0..400 {
        cycle(&mut axis, Some(f64::from(i.min(200)) * 0.01));
    }
    let _ = axis.actual_position();
    cycle(&mut axis, Some(2.0));
    let x = axis.actual_position().unwrap();
    assert!((x - 2.0).abs() < 1e-2, "at {x}");
    assert_eq!(axis.link_fault(), None);
    // The drive's heartbeat stops: the rx half names the node.
    let stop = super::sdo::SdoClient::new(node)
        .download(super::slave::od::INJECT, 2, &[1], Duration::ZERO)
        .unwrap();
    use crate::can::CanBus;
    cfg_port.try_send(&stop).unwrap();
    for _ in 0..100 {
        cycle(&mut axis, Some(2.0));
    }
    let f = axis.link_fault().unwrap();
    assert_eq!((f.node, f.cause), (5, LinkCause::HeartbeatLost));
}

/// Two loopback drives started on an in-memory bus named `iface`, with the bus owner's
/// halves and one axis per drive.
struct Rig {
    wire: SimCanBus,
    sim: SimDrives<SimCanPort>,
    rx: BusRx<SimCanPort>,
    tx: BusTx<SimCanPort>,
    links: Vec<Arc<DriveLink>>,
    t: Duration,
}

impl Rig {
    fn new(iface: &str) -> Rig {
        let (wire, mut ports) = SimCanBus::new(4, 1024).unwrap();
        let slaves = ports.pop().unwrap();
        let mut cfg_port = ports.pop().unwrap();
        let tx_port = ports.pop().unwrap();
        let rx_port = ports.pop().unwrap();
        let plans = [plan(1), plan(2)];
        let mut sim = SimDrives::new(
            slaves,
            plans
                .iter()
                .map(|p| DriveSlave::new(p.node, SlaveConfig::default()))
                .collect(),
        );
        let mut t = Duration::ZERO;
        let mut pass = || {
            t = sim.step_by(MS);
            t
        };
        start_nodes(iface, &mut cfg_port, &plans, 200 * MS, &mut pass).unwrap();
        let links: Vec<_> = plans
            .iter()
            .map(|p| DriveLink::on_bus(p.node, iface))
            .collect();
        let drives: Vec<_> = plans
            .iter()
            .zip(&links)
            .map(|(p, l)| BusDrive {
                link: l.clone(),
                layout: p.layout,
                heartbeat_timeout: Some(50 * MS),
            })
            .collect();
        Rig {
            rx: BusRx::new(rx_port, &drives).unwrap(),
            tx: BusTx::new(tx_port, &drives, SyncProducer::new()).unwrap(),
            wire,
            sim,
            links,
            t,
        }
    }

    fn cycles(&mut self, n: usize) {
        for _ in 0..n {
            self.t += MS;
            self.rx.cycle_start(self.t);
            self.tx.cycle_end();
            self.sim.step(self.t);
        }
    }
}

#[test]
fn each_bus_failure_is_a_fault_naming_the_interface_on_every_drive() {
    type Inject = fn(&SimCanBus);
    let cases: [(Inject, LinkCause, &str); 4] = [
        (
            |w| w.set_bus_off(true),
            LinkCause::BusOff,
            "can7: bus-off (error code 0x8140",
        ),
        (
            |w| w.error_frame(),
            LinkCause::ErrorFrame,
            "can7: error frame (error code 0x8120",
        ),
        (
            |w| w.set_interface_down(true),
            LinkCause::InterfaceDown,
            "can7: interface down (error code 0x8100",
        ),
        (
            |w| w.set_tx_queue_full(true),
            LinkCause::TxQueueFull,
            "can7: transmit queue full (error code 0x8110",
        ),
    ];
    for (inject, cause, text) in cases {
        let mut rig = Rig::new("can7");
        rig.cycles(20);
        assert!(rig.links.iter().all(|l| l.fault().is_none()), "{text}");
        inject(&rig.wire);
        rig.cycles(2);
        for l in &rig.links {
            let f = l.fault().unwrap();
            assert_eq!(f.cause, cause);
            assert!(f.to_string().starts_with(text), "{f}");
            assert!(!f.to_string().contains("node"), "names the interface: {f}");
        }
    }
}
