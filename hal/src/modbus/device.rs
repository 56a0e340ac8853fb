//! [`ModbusIo`]: the device the machine owns. It implements the I/O traits on top of the
//! [`Image`] only, so every call is a few atomic loads or stores: the realtime side never
//! waits for the link.
//!
//! An input whose last transaction failed reads as its last good value, unless it is
//! critical: then the read fails with [`ErrorKind::Disconnected`], which the I/O task turns
//! into stale cycles and the machine into "communication lost" (e-stop). Outputs are
//! queued in the image and always accepted; the poller writes them when the link is up.

use super::image::{Image, InputCell, OutputCell, Quality};
use crate::error::{Error, ErrorKind, ErrorType};
use crate::io::{AnalogInputs, AnalogOutputs, DigitalInputs, DigitalOutputs};
use std::sync::Arc;

/// Why an access to a Modbus I/O device failed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ModbusIoError {
    /// The channel index is beyond the device's channel count.
    #[error("{channel} index {index} out of range (device has {count})")]
    IndexOutOfRange {
        /// Which kind of channel.
        channel: &'static str,
        /// The requested index.
        index: usize,
        /// How many channels of that kind exist.
        count: usize,
    },
    /// A critical input has no good value (link down, timeout, exception).
    #[error("critical {channel} {index} has no good value (Modbus link fault)")]
    CriticalPointLost {
        /// Which kind of channel.
        channel: &'static str,
        /// Its index on the device.
        index: usize,
    },
    /// An analog value was NaN or infinite.
    #[error("analog value {0} is not finite")]
    NotFinite(f64),
}

impl Error for ModbusIoError {
    fn kind(&self) -> ErrorKind {
        match self {
            ModbusIoError::IndexOutOfRange { .. } | ModbusIoError::NotFinite(_) => {
                ErrorKind::InvalidArgument
            }
            ModbusIoError::CriticalPointLost { .. } => ErrorKind::Disconnected,
        }
    }
}

/// A Modbus I/O device as the machine sees it. Dropping it closes the image, which stops
/// the link's poller for this device.
#[derive(Debug)]
pub struct ModbusIo {
    image: Arc<Image>,
}

impl ModbusIo {
    /// The device over `image` (shared with its poller).
    pub fn new(image: Arc<Image>) -> ModbusIo {
        ModbusIo { image }
    }

    /// The shared image.
    pub fn image(&self) -> &Arc<Image> {
        &self.image
    }
}

impl Drop for ModbusIo {
    fn drop(&mut self) {
        self.image.close();
    }
}

fn cell<'a, T>(
    cells: &'a [T],
    channel: &'static str,
    index: usize,
) -> Result<&'a T, ModbusIoError> {
    cells.get(index).ok_or(ModbusIoError::IndexOutOfRange {
        channel,
        index,
        count: cells.len(),
    })
}

fn read(
    cells: &[InputCell],
    critical: &[bool],
    channel: &'static str,
    index: usize,
) -> Result<f64, ModbusIoError> {
    let s = cell(cells, channel, index)?.sample();
    let critical = critical.get(index).copied().unwrap_or(false);
    if critical && s.quality != Quality::Good {
        return Err(ModbusIoError::CriticalPointLost { channel, index });
    }
    Ok(s.value)
}

fn out<'a>(
    cells: &'a [OutputCell],
    channel: &'static str,
    index: usize,
) -> Result<&'a OutputCell, ModbusIoError> {
    cell(cells, channel, index)
}

impl ErrorType for ModbusIo {
    type Error = ModbusIoError;
}

impl DigitalInputs for ModbusIo {
    fn digital_input_count(&self) -> usize {
        self.image.di.len()
    }

    fn read_digital_input(&mut self, index: usize) -> Result<bool, ModbusIoError> {
        Ok(read(
            &self.image.di,
            &self.image.di_critical,
            "digital input",
            index,
        )? != 0.0)
    }
}

impl DigitalOutputs for ModbusIo {
    fn digital_output_count(&self) -> usize {
        self.image.dout.len()
    }

    fn write_digital_output(&mut self, index: usize, value: bool) -> Result<(), ModbusIoError> {
        out(&self.image.dout, "digital output", index)?.command(f64::from(u8::from(value)));
        Ok(())
    }

    fn digital_output(&mut self, index: usize) -> Result<bool, ModbusIoError> {
        Ok(out(&self.image.dout, "digital output", index)?.value() != 0.0)
    }
}

impl AnalogInputs for ModbusIo {
    fn analog_input_count(&self) -> usize {
        self.image.ai.len()
    }

    fn read_analog_input(&mut self, index: usize) -> Result<f64, ModbusIoError> {
        read(
            &self.image.ai,
            &self.image.ai_critical,
            "analog input",
            index,
        )
    }
}

impl AnalogOutputs for ModbusIo {
    fn analog_output_count(&self) -> usize {
        self.image.ao.len()
    }

    fn write_analog_output(&mut self, index: usize, value: f64) -> Result<(), ModbusIoError> {
        if !value.is_finite() {
            return Err(ModbusIoError::NotFinite(value));
        }
        out(&self.image.ao, "analog output", index)?.command(value);
        Ok(())
    }

    fn analog_output(&mut self, index: usize) -> Result<f64, ModbusIoError> {
        Ok(out(&self.image.ao, "analog output", index)?.value())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lost_critical_input_fails_and_a_lost_plain_one_keeps_its_value() {
        let img = Arc::new(Image::new(vec![true, false], vec![false], 1, 1));
        let mut io = ModbusIo::new(img.clone());
        let err = io.read_digital_input(0).unwrap_err();
        assert_eq!(err.kind(), ErrorKind::Disconnected);
        Image::publish(&img.di[0], 1.0, 1);
        Image::publish(&img.di[1], 1.0, 1);
        assert!(io.read_digital_input(0).unwrap());
        Image::mark_bad(&img.di[0]);
        Image::mark_bad(&img.di[1]);
        assert!(io
            .read_digital_input(0)
            .unwrap_err()
            .kind()
            .is_link_failure());
        assert!(io.read_digital_input(1).unwrap(), "last good value");
        assert_eq!(io.read_analog_input(0).unwrap(), 0.0);
        assert_eq!(
            io.read_digital_input(2).unwrap_err().kind(),
            ErrorKind::InvalidArgument
        );
    }

    #[test]
    fn outputs_are_queued_in_the_image() {
        let img = Arc::new(Image::new(vec![], vec![], 2, 1));
        let mut io = ModbusIo::new(img.clone());
        io.set_high(1).unwrap();
        assert!(io.digital_output(1).unwrap());
        assert_eq!(img.dout[1].pending().map(|p| p.1), Some(1.0));
        io.write_analog_output(0, 12.5).unwrap();
        assert_eq!(img.ao[0].value(), 12.5);
        assert!(io.write_analog_output(0, f64::NAN).is_err());
        drop(io);
        assert!(img.is_closed(), "dropping the device stops its poller");
    }
}
