//! A thread-safe handle for injecting faults into a running simulated axis.
//!
//! The axis itself is owned by the servo thread; tests and the control socket hold a
//! [`SimAxisHandle`] instead. Requests travel through atomics that the axis reads on its
//! next tick, so the handle never blocks the servo thread and the axis never allocates.

use crate::axis::FaultCode;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Arc;

/// Marks a pending fault request in [`Shared::fault_request`]; the low 16 bits are the code.
const FAULT_PENDING: u32 = 1 << 16;

#[derive(Debug, Default)]
pub(super) struct Shared {
    /// `FAULT_PENDING | code` while a fault injection waits for the next tick, else 0.
    fault_request: AtomicU32,
    stalled: AtomicBool,
    disconnected: AtomicBool,
}

impl Shared {
    /// Takes the pending fault request, if any.
    pub(super) fn take_fault(&self) -> Option<FaultCode> {
        let v = self.fault_request.swap(0, Ordering::AcqRel);
        // The mask keeps the low 16 bits, so the cast cannot truncate.
        (v & FAULT_PENDING != 0).then_some(FaultCode((v & 0xFFFF) as u16))
    }

    pub(super) fn stalled(&self) -> bool {
        self.stalled.load(Ordering::Acquire)
    }

    pub(super) fn disconnected(&self) -> bool {
        self.disconnected.load(Ordering::Acquire)
    }
}

/// Injects faults into a [`SimAxis`](super::SimAxis) from any thread. Cheap to clone.
#[derive(Debug, Clone)]
pub struct SimAxisHandle {
    pub(super) shared: Arc<Shared>,
}

impl SimAxisHandle {
    /// Makes the drive fault with `code` on its next tick (as a real drive reporting, say,
    /// an over-current).
    pub fn inject_fault(&self, code: FaultCode) {
        self.shared
            .fault_request
            .store(FAULT_PENDING | u32::from(code.0), Ordering::Release);
    }

    /// Stalls the motor (a crash, a seized ball screw): while set, the position stops
    /// following and the following error grows. The drive itself faults only if it has a
    /// following-error window configured.
    pub fn set_stalled(&self, stalled: bool) {
        self.shared.stalled.store(stalled, Ordering::Release);
    }

    /// Cuts or restores the simulated link: while cut, every call on the axis fails with
    /// [`ErrorKind::Disconnected`](crate::ErrorKind::Disconnected) but the motor keeps
    /// running its last command, as a real drive does when its bus goes silent.
    pub fn set_disconnected(&self, disconnected: bool) {
        self.shared
            .disconnected
            .store(disconnected, Ordering::Release);
    }
}
