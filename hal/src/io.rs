//! Indexed digital and analog I/O: one trait per direction and signal type.
//!
//! A device exposes a fixed number of channels of each kind, addressed by index `0..count`.
//! The machine configuration gives channels names (`estop`, `coolant_flood`) and maps them to
//! indices; the traits stay free of names so that a Modbus register map, an EtherCAT
//! terminal or a simulator implement them the same way. Reads and writes are non-blocking:
//! a backend behind a slow link (Modbus TCP) serves them from a process image exchanged by
//! its own non-realtime thread. An index out of range is an
//! [`ErrorKind::InvalidArgument`](crate::ErrorKind::InvalidArgument).

use crate::error::ErrorType;

/// Digital inputs (switches, e-stop chain, probe).
pub trait DigitalInputs: ErrorType {
    /// How many digital inputs the device has.
    fn digital_input_count(&self) -> usize;

    /// Reads input `index`: `true` is high. This is the electrical level the device reports;
    /// the inversion of normally-closed contacts is configuration, applied above the HAL.
    fn read_digital_input(&mut self, index: usize) -> Result<bool, Self::Error>;

    /// True when input `index` is high.
    fn is_high(&mut self, index: usize) -> Result<bool, Self::Error> {
        self.read_digital_input(index)
    }

    /// True when input `index` is low.
    fn is_low(&mut self, index: usize) -> Result<bool, Self::Error> {
        Ok(!self.read_digital_input(index)?)
    }
}

/// Digital outputs (coolant valves, spindle enable, lamps). Stateful: the commanded level can
/// be read back, like `embedded-hal`'s `StatefulOutputPin`.
pub trait DigitalOutputs: ErrorType {
    /// How many digital outputs the device has.
    fn digital_output_count(&self) -> usize;

    /// Sets output `index` to `value`.
    fn write_digital_output(&mut self, index: usize, value: bool) -> Result<(), Self::Error>;

    /// The level last commanded on output `index`.
    fn digital_output(&mut self, index: usize) -> Result<bool, Self::Error>;

    /// Sets output `index` high.
    fn set_high(&mut self, index: usize) -> Result<(), Self::Error> {
        self.write_digital_output(index, true)
    }

    /// Sets output `index` low.
    fn set_low(&mut self, index: usize) -> Result<(), Self::Error> {
        self.write_digital_output(index, false)
    }

    /// Inverts output `index`.
    fn toggle(&mut self, index: usize) -> Result<(), Self::Error> {
        let v = self.digital_output(index)?;
        self.write_digital_output(index, !v)
    }
}

/// Analog inputs, in engineering units (the backend applies its scaling).
pub trait AnalogInputs: ErrorType {
    /// How many analog inputs the device has.
    fn analog_input_count(&self) -> usize;

    /// Reads input `index`.
    fn read_analog_input(&mut self, index: usize) -> Result<f64, Self::Error>;
}

/// Analog outputs, in engineering units (e.g. a spindle speed reference in volts or rpm).
pub trait AnalogOutputs: ErrorType {
    /// How many analog outputs the device has.
    fn analog_output_count(&self) -> usize;

    /// Sets output `index` to `value`. Non-finite values are refused.
    fn write_analog_output(&mut self, index: usize, value: f64) -> Result<(), Self::Error>;

    /// The value last commanded on output `index`.
    fn analog_output(&mut self, index: usize) -> Result<f64, Self::Error>;
}
