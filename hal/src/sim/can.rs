//! An in-memory CAN bus: a fixed set of ports on one simulated wire.
//!
//! A frame sent on one [`SimCanPort`] is delivered to every other port (not back to the
//! sender, as a CAN controller without self-reception). Each port is a [`CanBus`], so the
//! CANopen master (the bus owner, routing frames to node handles by COB-ID) and simulated
//! CiA 402 nodes can run against each other without hardware, exactly as they would on
//! SocketCAN.
//!
//! Each port's receive queue is a bounded lock-free queue ([`crossbeam_queue::ArrayQueue`]),
//! allocated once at construction: sending and receiving never lock or allocate. A full
//! receive queue drops the frame and counts it, like a controller overrun. The set of ports
//! is fixed at construction, which is what keeps delivery lock-free (no registry to guard).
//! [`SimCanBus::set_bus_off`] simulates the bus going away; [`SimCanBus::set_interface_down`],
//! [`SimCanBus::set_tx_queue_full`] and [`SimCanBus::error_frame`] the other failures a
//! SocketCAN interface reports.

use crate::can::{CanBus, CanFrame};
use crate::error::{Error, ErrorKind, ErrorType};
use crossbeam_queue::ArrayQueue;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

/// Why a simulated CAN access failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SimCanError {
    /// The bus is off (see [`SimCanBus::set_bus_off`]).
    #[error("simulated CAN bus is off")]
    BusOff,
    /// The interface is down (see [`SimCanBus::set_interface_down`]).
    #[error("simulated CAN interface is down")]
    InterfaceDown,
    /// The transmit queue is full (see [`SimCanBus::set_tx_queue_full`]).
    #[error("simulated CAN interface: transmit queue full")]
    TxQueueFull,
    /// An error frame was received (see [`SimCanBus::error_frame`]).
    #[error("simulated CAN interface: error frame")]
    ErrorFrame,
    /// A bus needs at least two ports and queues of at least one frame.
    #[error("simulated CAN bus needs >= 2 ports and a queue capacity >= 1")]
    InvalidSize,
}

impl Error for SimCanError {
    fn kind(&self) -> ErrorKind {
        match self {
            SimCanError::BusOff | SimCanError::InterfaceDown => ErrorKind::Disconnected,
            SimCanError::TxQueueFull => ErrorKind::WouldBlock,
            SimCanError::ErrorFrame => ErrorKind::Other,
            SimCanError::InvalidSize => ErrorKind::InvalidArgument,
        }
    }
}

#[derive(Debug)]
struct Shared {
    queues: Box<[ArrayQueue<CanFrame>]>,
    dropped: Box<[AtomicU64]>,
    bus_off: AtomicBool,
    down: AtomicBool,
    tx_full: AtomicBool,
    /// Per port: an error frame waits to be reported by its next receive.
    error_frame: Box<[AtomicBool]>,
}

impl Shared {
    fn link(&self) -> Result<(), SimCanError> {
        if self.down.load(Ordering::Acquire) {
            Err(SimCanError::InterfaceDown)
        } else if self.bus_off.load(Ordering::Acquire) {
            Err(SimCanError::BusOff)
        } else {
            Ok(())
        }
    }
}

/// The simulated wire: controls the bus as a whole (bus-off) and reports per-port drops.
#[derive(Debug, Clone)]
pub struct SimCanBus {
    shared: Arc<Shared>,
}

/// One attachment point on a [`SimCanBus`]; implements [`CanBus`].
#[derive(Debug)]
pub struct SimCanPort {
    shared: Arc<Shared>,
    index: usize,
}

impl SimCanBus {
    /// Creates a bus with `ports` attachment points, each buffering up to `queue_capacity`
    /// received frames. Returns the bus handle and the ports, in index order.
    pub fn new(
        ports: usize,
        queue_capacity: usize,
    ) -> Result<(SimCanBus, Vec<SimCanPort>), SimCanError> {
        if ports < 2 || queue_capacity == 0 {
            return Err(SimCanError::InvalidSize);
        }
        let shared = Arc::new(Shared {
            queues: (0..ports)
                .map(|_| ArrayQueue::new(queue_capacity))
                .collect(),
            dropped: (0..ports).map(|_| AtomicU64::new(0)).collect(),
            bus_off: AtomicBool::new(false),
            down: AtomicBool::new(false),
            tx_full: AtomicBool::new(false),
            error_frame: (0..ports).map(|_| AtomicBool::new(false)).collect(),
        });
        let handles = (0..ports)
            .map(|index| SimCanPort {
                shared: Arc::clone(&shared),
                index,
            })
            .collect();
        Ok((SimCanBus { shared }, handles))
    }

    /// Takes the bus off (every send and receive fails with
    /// [`ErrorKind::Disconnected`]) or back on.
    pub fn set_bus_off(&self, off: bool) {
        self.shared.bus_off.store(off, Ordering::Release);
    }

    /// Takes the interface down (every send and receive fails with
    /// [`SimCanError::InterfaceDown`]) or back up.
    pub fn set_interface_down(&self, down: bool) {
        self.shared.down.store(down, Ordering::Release);
    }

    /// Makes every send fail with [`SimCanError::TxQueueFull`] (or stops doing so).
    pub fn set_tx_queue_full(&self, full: bool) {
        self.shared.tx_full.store(full, Ordering::Release);
    }

    /// An error frame on the wire: the next receive of every port reports
    /// [`SimCanError::ErrorFrame`] once, as every SocketCAN socket with an error mask
    /// would.
    pub fn error_frame(&self) {
        for e in self.shared.error_frame.iter() {
            e.store(true, Ordering::Release);
        }
    }

    /// How many frames port `index` lost because its receive queue was full (0 for an index
    /// that does not exist).
    pub fn dropped(&self, index: usize) -> u64 {
        self.shared
            .dropped
            .get(index)
            .map_or(0, |d| d.load(Ordering::Relaxed))
    }
}

impl SimCanPort {
    /// This port's index on the bus.
    pub fn index(&self) -> usize {
        self.index
    }
}

impl ErrorType for SimCanPort {
    type Error = SimCanError;
}

impl CanBus for SimCanPort {
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), SimCanError> {
        self.shared.link()?;
        if self.shared.tx_full.load(Ordering::Acquire) {
            return Err(SimCanError::TxQueueFull);
        }
        for (i, (queue, dropped)) in self
            .shared
            .queues
            .iter()
            .zip(self.shared.dropped.iter())
            .enumerate()
        {
            if i != self.index && queue.push(*frame).is_err() {
                dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
        Ok(())
    }

    fn try_recv(&mut self) -> Result<Option<CanFrame>, SimCanError> {
        self.shared.link()?;
        if self
            .shared
            .error_frame
            .get(self.index)
            .is_some_and(|e| e.swap(false, Ordering::AcqRel))
        {
            return Err(SimCanError::ErrorFrame);
        }
        Ok(self.shared.queues.get(self.index).and_then(ArrayQueue::pop))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::CanId;

    fn frame(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new(CanId::standard(id).unwrap(), data).unwrap()
    }

    #[test]
    fn frames_reach_every_other_port_in_order() {
        let (_bus, mut ports) = SimCanBus::new(3, 8).unwrap();
        ports[0].try_send(&frame(0x80, &[])).unwrap();
        ports[0].try_send(&frame(0x201, &[1, 2])).unwrap();
        for p in &mut ports[1..] {
            assert_eq!(p.try_recv().unwrap(), Some(frame(0x80, &[])));
            assert_eq!(p.try_recv().unwrap(), Some(frame(0x201, &[1, 2])));
            assert_eq!(p.try_recv().unwrap(), None);
        }
        assert_eq!(ports[0].try_recv().unwrap(), None, "no self-reception");
    }

    #[test]
    fn recv_into_drains_without_allocating() {
        let (_bus, mut ports) = SimCanBus::new(2, 8).unwrap();
        for i in 0..3 {
            ports[1].try_send(&frame(0x181, &[i])).unwrap();
        }
        let mut buf = [frame(0, &[]); 2];
        assert_eq!(ports[0].recv_into(&mut buf).unwrap(), 2);
        assert_eq!(buf[1].data(), &[1]);
        assert_eq!(ports[0].recv_into(&mut buf).unwrap(), 1);
        assert_eq!(buf[0].data(), &[2]);
        assert_eq!(ports[0].recv_into(&mut buf).unwrap(), 0);
    }

    #[test]
    fn a_full_receive_queue_drops_and_counts() {
        let (bus, mut ports) = SimCanBus::new(2, 2).unwrap();
        for i in 0..5 {
            ports[0].try_send(&frame(0x181, &[i])).unwrap();
        }
        assert_eq!(bus.dropped(1), 3);
        assert_eq!(bus.dropped(0), 0);
        assert_eq!(ports[1].try_recv().unwrap().unwrap().data(), &[0]);
    }

    #[test]
    fn bus_off_is_a_link_failure() {
        let (bus, mut ports) = SimCanBus::new(2, 2).unwrap();
        bus.set_bus_off(true);
        let err = ports[0].try_send(&frame(1, &[])).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::Disconnected);
        assert!(ports[1].try_recv().is_err());
        bus.set_bus_off(false);
        assert!(ports[0].try_send(&frame(1, &[])).is_ok());
        assert_eq!(ports[1].try_recv().unwrap(), Some(frame(1, &[])));
    }

    #[test]
    fn degenerate_buses_are_refused() {
        assert_eq!(SimCanBus::new(1, 4).unwrap_err(), SimCanError::InvalidSize);
        assert_eq!(SimCanBus::new(2, 0).unwrap_err(), SimCanError::InvalidSize);
    }

    #[test]
    fn ports_work_across_threads() {
        let (_bus, mut ports) = SimCanBus::new(2, 4).unwrap();
        let mut rx = ports.pop().unwrap();
        let mut tx = ports.pop().unwrap();
        std::thread::spawn(move || tx.try_send(&frame(0x701, &[5])).unwrap())
            .join()
            .unwrap();
        assert_eq!(rx.try_recv().unwrap(), Some(frame(0x701, &[5])));
        assert_eq!(rx.index(), 1);
    }
}
