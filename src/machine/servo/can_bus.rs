//! The bus-owner tasks of one CAN interface, `can.<iface>.rx` and `can.<iface>.tx`, on the
//! servo thread in the order the CANopen master needs (see `hytask_hal::canopen::master`):
//!
//! 1. `can.<iface>.rx` runs first of all: the TPDOs, heartbeats and EMCYs received since the
//!    last SYNC go into each drive's shared image ([`DriveLink`](hytask_hal::canopen::axis::DriveLink));
//! 2. the machine's tasks run; the `axis.*` tasks of CANopen axes read and write that image
//!    through the HAL axis traits;
//! 3. `can.<iface>.tx` runs after the axis tasks: one RPDO per drive, then SYNC (and, for
//!    the in-process `sim` interface, the loopback drives answer that SYNC).
//!
//! So the axis tasks see positions one servo period old, and their targets take effect at
//! the SYNC of the same cycle. The tasks exchange nothing but the atomics of the links:
//! no lock, no allocation.

use crate::rt::prelude::*;
use hytask_hal::can::CanBus;
use hytask_hal::canopen::bus_health::BusErrorClass;
use hytask_hal::canopen::owner::{BusRx, BusTx, SimDrives};
use std::time::Duration;

/// The receiving half of a bus owner, whatever its bus.
pub trait RxHalf: Send {
    /// Start of the cycle at `now`.
    fn cycle_start(&mut self, now: Duration);
}

/// The transmitting half of a bus owner, whatever its bus.
pub trait TxHalf: Send {
    /// End of the cycle at `now`.
    fn cycle_end(&mut self, now: Duration);
}

impl<B: CanBus + Send> RxHalf for BusRx<B>
where
    B::Error: BusErrorClass,
{
    fn cycle_start(&mut self, now: Duration) {
        BusRx::cycle_start(self, now);
    }
}

impl<B: CanBus + Send> TxHalf for BusTx<B>
where
    B::Error: BusErrorClass,
{
    fn cycle_end(&mut self, _now: Duration) {
        BusTx::cycle_end(self);
    }
}

/// The tx half followed by the in-process loopback drives, which answer the SYNC at once.
pub struct SimTx<B: CanBus, D: CanBus> {
    /// The master's tx half.
    pub tx: BusTx<B>,
    /// The loopback drives.
    pub drives: SimDrives<D>,
}

impl<B: CanBus + Send, D: CanBus + Send> TxHalf for SimTx<B, D>
where
    B::Error: BusErrorClass,
{
    fn cycle_end(&mut self, now: Duration) {
        self.tx.cycle_end();
        self.drives.step(now);
    }
}

/// `can.<iface>.rx`.
pub struct CanRxTask(pub Box<dyn RxHalf>);

/// `can.<iface>.tx`.
pub struct CanTxTask(pub Box<dyn TxHalf>);

impl Task for CanRxTask {
    type Command = NoCommands;

    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        self.0.cycle_start(Duration::from_nanos(ctx.now_ns));
        Ok(())
    }
}

impl Task for CanTxTask {
    type Command = NoCommands;

    fn update(&mut self, ctx: &StepContext) -> Result<(), TaskError> {
        self.0.cycle_end(Duration::from_nanos(ctx.now_ns));
        Ok(())
    }
}
