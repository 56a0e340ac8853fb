//! Backend erasure: one error type for every backend, so that backends chosen by
//! configuration can sit behind one trait object (`Box<dyn Axis<Error = HalError>>`).
//!
//! Each backend's error type differs, and a trait object must name one. [`Erased`] wraps
//! any device and converts its errors into [`HalError`]: the [`ErrorKind`] (for the error
//! policy) plus the backend's message, formatted into a fixed inline buffer. No allocation
//! happens, not even on the error path, so an erased device keeps the realtime rules.

use crate::axis::{
    AxisDrive, AxisFeedback, AxisSwitches, DriveState, FaultCode, Homing, HomingParams,
    HomingStatus,
};
use crate::can::{CanBus, CanFrame};
use crate::error::{Error, ErrorKind, ErrorType};
use crate::io::{AnalogInputs, AnalogOutputs, DigitalInputs, DigitalOutputs};
use core::fmt::{self, Write};

/// Capacity of [`HalError`]'s message buffer; longer messages are cut and end in `...`.
/// Small enough that `Result<_, HalError>` stays cheap to return every cycle.
pub const MESSAGE_CAPACITY: usize = 112;

/// A backend error with its kind and message, of fixed size and `Copy`.
#[derive(Clone, Copy)]
pub struct HalError {
    kind: ErrorKind,
    /// Bytes used in `buf` (<= MESSAGE_CAPACITY, which fits in a u8).
    len: u8,
    buf: [u8; MESSAGE_CAPACITY],
}

impl HalError {
    /// Captures `error`'s kind and message.
    pub fn from_error<E: Error + ?Sized>(error: &E) -> HalError {
        let mut e = HalError {
            kind: error.kind(),
            len: 0,
            buf: [0; MESSAGE_CAPACITY],
        };
        if write!(e, "{error}").is_err() {
            // Truncated: end with an ellipsis, at a character boundary.
            let mut cut = MESSAGE_CAPACITY - 3;
            while !e.message_prefix_is_boundary(cut) {
                cut -= 1;
            }
            e.buf[cut..cut + 3].copy_from_slice(b"...");
            e.set_len(cut + 3);
        }
        e
    }

    /// The generic kind.
    pub fn kind(&self) -> ErrorKind {
        self.kind
    }

    /// The backend's message (possibly cut to [`MESSAGE_CAPACITY`] bytes).
    pub fn message(&self) -> &str {
        // Only whole UTF-8 characters are ever copied in, so this cannot fail; fall back to
        // the kind's name rather than panic.
        core::str::from_utf8(&self.buf[..self.len()]).unwrap_or("(message unavailable)")
    }

    fn len(&self) -> usize {
        usize::from(self.len)
    }

    fn set_len(&mut self, len: usize) {
        // Callers never exceed MESSAGE_CAPACITY (112), so this cannot saturate.
        self.len = u8::try_from(len).unwrap_or(u8::MAX);
    }

    fn message_prefix_is_boundary(&self, at: usize) -> bool {
        at == 0 || at >= self.len() || (self.buf[at] & 0xC0) != 0x80
    }
}

impl Write for HalError {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let used = self.len();
        let room = MESSAGE_CAPACITY - used;
        if s.len() <= room {
            self.buf[used..used + s.len()].copy_from_slice(s.as_bytes());
            self.set_len(used + s.len());
            Ok(())
        } else {
            let mut take = room;
            while !s.is_char_boundary(take) {
                take -= 1;
            }
            self.buf[used..used + take].copy_from_slice(&s.as_bytes()[..take]);
            self.set_len(used + take);
            Err(fmt::Error)
        }
    }
}

impl fmt::Debug for HalError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("HalError")
            .field("kind", &self.kind)
            .field("message", &self.message())
            .finish()
    }
}

impl fmt::Display for HalError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.message())
    }
}

impl PartialEq for HalError {
    fn eq(&self, other: &Self) -> bool {
        self.kind == other.kind && self.message() == other.message()
    }
}

impl std::error::Error for HalError {}

impl Error for HalError {
    fn kind(&self) -> ErrorKind {
        self.kind
    }
}

/// Wraps a device so that its errors become [`HalError`]. Implements every capability
/// trait the wrapped device implements.
#[derive(Debug)]
pub struct Erased<T>(pub T);

impl<T> Erased<T> {
    /// The wrapped device (for backend-specific calls such as a simulator's `tick`).
    pub fn inner(&mut self) -> &mut T {
        &mut self.0
    }
}

/// Any axis backend behind one type, as the machine holds axes chosen by configuration.
pub type DynAxis = Box<dyn crate::Axis<Error = HalError> + Send>;

/// Boxes `axis` as a [`DynAxis`].
pub fn dyn_axis<T: crate::Axis + Send + 'static>(axis: T) -> DynAxis {
    Box::new(Erased(axis))
}

fn e<T, E: Error>(r: Result<T, E>) -> Result<T, HalError> {
    r.map_err(|err| HalError::from_error(&err))
}

impl<T: ErrorType> ErrorType for Erased<T> {
    type Error = HalError;
}

impl<T: AxisDrive> AxisDrive for Erased<T> {
    fn enable(&mut self) -> Result<(), HalError> {
        e(self.0.enable())
    }
    fn disable(&mut self) -> Result<(), HalError> {
        e(self.0.disable())
    }
    fn set_target_position(&mut self, position: f64) -> Result<(), HalError> {
        e(self.0.set_target_position(position))
    }
    fn quick_stop(&mut self) -> Result<(), HalError> {
        e(self.0.quick_stop())
    }
    fn fault_reset(&mut self) -> Result<(), HalError> {
        e(self.0.fault_reset())
    }
}

impl<T: AxisFeedback> AxisFeedback for Erased<T> {
    fn actual_position(&mut self) -> Result<f64, HalError> {
        e(self.0.actual_position())
    }
    fn actual_velocity(&mut self) -> Result<f64, HalError> {
        e(self.0.actual_velocity())
    }
    fn drive_state(&mut self) -> Result<DriveState, HalError> {
        e(self.0.drive_state())
    }
    fn fault_code(&mut self) -> Result<Option<FaultCode>, HalError> {
        e(self.0.fault_code())
    }
    fn switches(&mut self) -> Result<AxisSwitches, HalError> {
        e(self.0.switches())
    }
}

impl<T: Homing> Homing for Erased<T> {
    fn start_homing(&mut self, params: &HomingParams) -> Result<(), HalError> {
        e(self.0.start_homing(params))
    }
    fn homing_status(&mut self) -> Result<HomingStatus, HalError> {
        e(self.0.homing_status())
    }
    fn abort_homing(&mut self) -> Result<(), HalError> {
        e(self.0.abort_homing())
    }
}

impl<T: DigitalInputs> DigitalInputs for Erased<T> {
    fn digital_input_count(&self) -> usize {
        self.0.digital_input_count()
    }
    fn read_digital_input(&mut self, index: usize) -> Result<bool, HalError> {
        e(self.0.read_digital_input(index))
    }
}

impl<T: DigitalOutputs> DigitalOutputs for Erased<T> {
    fn digital_output_count(&self) -> usize {
        self.0.digital_output_count()
    }
    fn write_digital_output(&mut self, index: usize, value: bool) -> Result<(), HalError> {
        e(self.0.write_digital_output(index, value))
    }
    fn digital_output(&mut self, index: usize) -> Result<bool, HalError> {
        e(self.0.digital_output(index))
    }
}

impl<T: AnalogInputs> AnalogInputs for Erased<T> {
    fn analog_input_count(&self) -> usize {
        self.0.analog_input_count()
    }
    fn read_analog_input(&mut self, index: usize) -> Result<f64, HalError> {
        e(self.0.read_analog_input(index))
    }
}

impl<T: AnalogOutputs> AnalogOutputs for Erased<T> {
    fn analog_output_count(&self) -> usize {
        self.0.analog_output_count()
    }
    fn write_analog_output(&mut self, index: usize, value: f64) -> Result<(), HalError> {
        e(self.0.write_analog_output(index, value))
    }
    fn analog_output(&mut self, index: usize) -> Result<f64, HalError> {
        e(self.0.analog_output(index))
    }
}

impl<T: CanBus> CanBus for Erased<T> {
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), HalError> {
        e(self.0.try_send(frame))
    }
    fn try_recv(&mut self) -> Result<Option<CanFrame>, HalError> {
        e(self.0.try_recv())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{SimAxis, SimAxisConfig, SimIo};

    #[derive(Debug, thiserror::Error)]
    #[error("{0}")]
    struct Long(String);

    impl Error for Long {
        fn kind(&self) -> ErrorKind {
            ErrorKind::Other
        }
    }

    #[test]
    fn keeps_kind_and_message_of_the_backend_error() {
        let mut axis = dyn_axis(SimAxis::new(SimAxisConfig::default()).unwrap());
        let err = axis.set_target_position(1.0).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::NotReady);
        assert_eq!(
            err.message(),
            "drive is not operational (state: not ready to switch on)"
        );
        assert_eq!(err.to_string(), err.message());
    }

    #[test]
    fn long_messages_are_cut_at_a_character_boundary() {
        let msg = "é".repeat(100); // 200 bytes
        let err = HalError::from_error(&Long(msg));
        assert!(err.message().len() <= MESSAGE_CAPACITY);
        assert!(err.message().ends_with("..."));
        assert!(err.message().starts_with("éé"));
    }

    #[test]
    fn io_devices_can_be_erased_too() {
        let io = SimIo::new(1, 1, 0, 0);
        let h = io.handle();
        let mut io = Erased(io);
        io.set_high(0).unwrap();
        assert!(h.digital_output(0).unwrap());
        let err = io.read_digital_input(7).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::InvalidArgument);
        assert!(err.message().contains("index 7"), "{err}");
    }

    #[test]
    fn different_backends_share_one_trait_object_type() {
        let axes: Vec<DynAxis> = vec![
            dyn_axis(SimAxis::new(SimAxisConfig::default()).unwrap()),
            Box::new(Erased(Erased(
                SimAxis::new(SimAxisConfig::default()).unwrap(),
            ))),
        ];
        for mut axis in axes {
            assert_eq!(axis.drive_state().unwrap(), DriveState::NotReadyToSwitchOn);
            assert_eq!(
                axis.enable().map_err(|e| e.kind()),
                Ok(()),
                "commands reach the wrapped backend"
            );
        }
    }
}
