//! Simulated digital and analog I/O.
//!
//! [`SimIo`] is the device the machine owns (it implements [`DigitalInputs`],
//! [`DigitalOutputs`], [`AnalogInputs`] and [`AnalogOutputs`]); [`SimIoHandle`] is the
//! outside world: tests and the control socket press the e-stop or trip the probe by setting
//! inputs, and watch coolant or spindle outputs. Both share one block of atomics (analog
//! values as `f64` bits in `AtomicU64`), so neither side ever blocks the other and the
//! servo thread never allocates.

use crate::error::{Error, ErrorKind, ErrorType};
use crate::io::{AnalogInputs, AnalogOutputs, DigitalInputs, DigitalOutputs};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

/// Why a simulated I/O access failed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SimIoError {
    /// The channel index is beyond the device's channel count.
    #[error("{channel} index {index} out of range (device has {count})")]
    IndexOutOfRange {
        /// Which kind of channel ("digital input", ...).
        channel: &'static str,
        /// The requested index.
        index: usize,
        /// How many channels of that kind exist.
        count: usize,
    },
    /// An analog value was NaN or infinite.
    #[error("analog value {0} is not finite")]
    NotFinite(f64),
    /// The simulated link is cut (see [`SimIoHandle::set_disconnected`]).
    #[error("link to the simulated I/O device is down")]
    Disconnected,
}

impl Error for SimIoError {
    fn kind(&self) -> ErrorKind {
        match self {
            SimIoError::IndexOutOfRange { .. } | SimIoError::NotFinite(_) => {
                ErrorKind::InvalidArgument
            }
            SimIoError::Disconnected => ErrorKind::Disconnected,
        }
    }
}

#[derive(Debug)]
struct Shared {
    digital_inputs: Box<[AtomicBool]>,
    digital_outputs: Box<[AtomicBool]>,
    analog_inputs: Box<[AtomicU64]>,
    analog_outputs: Box<[AtomicU64]>,
    disconnected: AtomicBool,
}

fn bools(n: usize) -> Box<[AtomicBool]> {
    (0..n).map(|_| AtomicBool::new(false)).collect()
}

fn floats(n: usize) -> Box<[AtomicU64]> {
    (0..n).map(|_| AtomicU64::new(0.0f64.to_bits())).collect()
}

fn slot<'a, T>(slots: &'a [T], channel: &'static str, index: usize) -> Result<&'a T, SimIoError> {
    slots.get(index).ok_or(SimIoError::IndexOutOfRange {
        channel,
        index,
        count: slots.len(),
    })
}

fn finite(value: f64) -> Result<f64, SimIoError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(SimIoError::NotFinite(value))
    }
}

impl Shared {
    fn link(&self) -> Result<(), SimIoError> {
        if self.disconnected.load(Ordering::Acquire) {
            Err(SimIoError::Disconnected)
        } else {
            Ok(())
        }
    }
}

/// A simulated I/O device with fixed channel counts, owned by the machine.
#[derive(Debug)]
pub struct SimIo {
    shared: Arc<Shared>,
}

/// The outside view of a [`SimIo`]: sets inputs, reads outputs. Cheap to clone, usable from
/// any thread, never blocks.
#[derive(Debug, Clone)]
pub struct SimIoHandle {
    shared: Arc<Shared>,
}

impl SimIo {
    /// A device with the given numbers of channels; inputs start low / at 0.0.
    pub fn new(
        digital_inputs: usize,
        digital_outputs: usize,
        analog_inputs: usize,
        analog_outputs: usize,
    ) -> SimIo {
        SimIo {
            shared: Arc::new(Shared {
                digital_inputs: bools(digital_inputs),
                digital_outputs: bools(digital_outputs),
                analog_inputs: floats(analog_inputs),
                analog_outputs: floats(analog_outputs),
                disconnected: AtomicBool::new(false),
            }),
        }
    }

    /// The handle through which the outside world drives this device's inputs.
    pub fn handle(&self) -> SimIoHandle {
        SimIoHandle {
            shared: Arc::clone(&self.shared),
        }
    }
}

impl SimIoHandle {
    /// Sets digital input `index` (e.g. releases the e-stop chain, triggers the probe).
    pub fn set_digital_input(&self, index: usize, value: bool) -> Result<(), SimIoError> {
        slot(&self.shared.digital_inputs, "digital input", index)?.store(value, Ordering::Release);
        Ok(())
    }

    /// Sets analog input `index`.
    pub fn set_analog_input(&self, index: usize, value: f64) -> Result<(), SimIoError> {
        let value = finite(value)?;
        slot(&self.shared.analog_inputs, "analog input", index)?
            .store(value.to_bits(), Ordering::Release);
        Ok(())
    }

    /// The level the machine last wrote to digital output `index`.
    pub fn digital_output(&self, index: usize) -> Result<bool, SimIoError> {
        Ok(slot(&self.shared.digital_outputs, "digital output", index)?.load(Ordering::Acquire))
    }

    /// The value the machine last wrote to analog output `index`.
    pub fn analog_output(&self, index: usize) -> Result<f64, SimIoError> {
        let bits =
            slot(&self.shared.analog_outputs, "analog output", index)?.load(Ordering::Acquire);
        Ok(f64::from_bits(bits))
    }

    /// Cuts or restores the simulated link: while cut, the device side fails every access
    /// with [`ErrorKind::Disconnected`]; this handle keeps working.
    pub fn set_disconnected(&self, disconnected: bool) {
        self.shared
            .disconnected
            .store(disconnected, Ordering::Release);
    }
}

impl ErrorType for SimIo {
    type Error = SimIoError;
}

impl DigitalInputs for SimIo {
    fn digital_input_count(&self) -> usize {
        self.shared.digital_inputs.len()
    }

    fn read_digital_input(&mut self, index: usize) -> Result<bool, SimIoError> {
        self.shared.link()?;
        Ok(slot(&self.shared.digital_inputs, "digital input", index)?.load(Ordering::Acquire))
    }
}

impl DigitalOutputs for SimIo {
    fn digital_output_count(&self) -> usize {
        self.shared.digital_outputs.len()
    }

    fn write_digital_output(&mut self, index: usize, value: bool) -> Result<(), SimIoError> {
        self.shared.link()?;
        slot(&self.shared.digital_outputs, "digital output", index)?
            .store(value, Ordering::Release);
        Ok(())
    }

    fn digital_output(&mut self, index: usize) -> Result<bool, SimIoError> {
        self.shared.link()?;
        Ok(slot(&self.shared.digital_outputs, "digital output", index)?.load(Ordering::Acquire))
    }
}

impl AnalogInputs for SimIo {
    fn analog_input_count(&self) -> usize {
        self.shared.analog_inputs.len()
    }

    fn read_analog_input(&mut self, index: usize) -> Result<f64, SimIoError> {
        self.shared.link()?;
        let bits = slot(&self.shared.analog_inputs, "analog input", index)?.load(Ordering::Acquire);
        Ok(f64::from_bits(bits))
    }
}

impl AnalogOutputs for SimIo {
    fn analog_output_count(&self) -> usize {
        self.shared.analog_outputs.len()
    }

    fn write_analog_output(&mut self, index: usize, value: f64) -> Result<(), SimIoError> {
        self.shared.link()?;
        let value = finite(value)?;
        slot(&self.shared.analog_outputs, "analog output", index)?
            .store(value.to_bits(), Ordering::Release);
        Ok(())
    }

    fn analog_output(&mut self, index: usize) -> Result<f64, SimIoError> {
        self.shared.link()?;
        let bits =
            slot(&self.shared.analog_outputs, "analog output", index)?.load(Ordering::Acquire);
        Ok(f64::from_bits(bits))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_set_through_the_handle_are_read_by_the_device() {
        let mut io = SimIo::new(2, 0, 1, 0);
        let h = io.handle();
        assert!(io.is_low(1).unwrap());
        h.set_digital_input(1, true).unwrap();
        assert!(io.is_high(1).unwrap());
        assert!(!io.read_digital_input(0).unwrap());
        h.set_analog_input(0, 2.5).unwrap();
        assert_eq!(io.read_analog_input(0).unwrap(), 2.5);
    }

    #[test]
    fn outputs_written_by_the_device_are_seen_by_the_handle() {
        let mut io = SimIo::new(0, 3, 0, 1);
        let h = io.handle();
        io.set_high(2).unwrap();
        assert!(h.digital_output(2).unwrap());
        assert!(io.digital_output(2).unwrap());
        io.toggle(2).unwrap();
        assert!(!h.digital_output(2).unwrap());
        io.set_high(0).unwrap();
        io.set_low(0).unwrap();
        assert!(!h.digital_output(0).unwrap());
        io.write_analog_output(0, -10.0).unwrap();
        assert_eq!(h.analog_output(0).unwrap(), -10.0);
        assert_eq!(io.analog_output(0).unwrap(), -10.0);
    }

    #[test]
    fn counts_are_reported() {
        let io = SimIo::new(4, 3, 2, 1);
        assert_eq!(io.digital_input_count(), 4);
        assert_eq!(io.digital_output_count(), 3);
        assert_eq!(io.analog_input_count(), 2);
        assert_eq!(io.analog_output_count(), 1);
    }

    #[test]
    fn out_of_range_indices_are_invalid_arguments() {
        let mut io = SimIo::new(1, 1, 1, 1);
        let err = io.read_digital_input(1).unwrap_err();
        assert_eq!(
            err,
            SimIoError::IndexOutOfRange {
                channel: "digital input",
                index: 1,
                count: 1
            }
        );
        assert_eq!(err.kind(), ErrorKind::InvalidArgument);
        assert!(io.write_digital_output(5, true).is_err());
        assert!(io.read_analog_input(9).is_err());
        assert!(io.write_analog_output(9, 1.0).is_err());
        assert!(io.handle().set_digital_input(3, true).is_err());
    }

    #[test]
    fn non_finite_analog_values_are_refused() {
        let mut io = SimIo::new(0, 0, 1, 1);
        assert_eq!(
            io.write_analog_output(0, f64::INFINITY).unwrap_err().kind(),
            ErrorKind::InvalidArgument
        );
        assert!(io.handle().set_analog_input(0, f64::NAN).is_err());
    }

    #[test]
    fn a_cut_link_fails_device_accesses_as_disconnected() {
        let mut io = SimIo::new(1, 1, 0, 0);
        let h = io.handle();
        h.set_disconnected(true);
        let err = io.read_digital_input(0).unwrap_err();
        assert!(err.kind().is_link_failure());
        assert!(io.write_digital_output(0, true).is_err());
        h.set_disconnected(false);
        assert!(io.write_digital_output(0, true).is_ok());
    }

    #[test]
    fn handle_works_from_another_thread() {
        let mut io = SimIo::new(1, 0, 0, 0);
        let h = io.handle();
        std::thread::spawn(move || h.set_digital_input(0, true).unwrap())
            .join()
            .unwrap();
        assert!(io.is_high(0).unwrap());
    }
}
