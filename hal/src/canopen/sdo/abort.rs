//! SDO abort codes (CiA 301 table 22), each a named variant with its code and text.

use crate::error::{Error, ErrorKind};
use core::fmt;

macro_rules! abort_codes {
    ($( $(#[$m:meta])* $name:ident = $code:literal, $text:literal, $kind:ident; )*) => {
        /// An SDO abort code. [`SdoAbortCode::Unknown`] keeps codes outside CiA 301 (e.g.
        /// manufacturer codes) with their raw value.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum SdoAbortCode {
            $( $(#[$m])* #[doc = $text] $name, )*
            /// A code CiA 301 does not define.
            Unknown(u32),
        }

        impl SdoAbortCode {
            /// Every CiA 301 code, for tests and tables.
            pub const ALL: &'static [SdoAbortCode] = &[$(SdoAbortCode::$name),*];

            /// The 32-bit code on the wire.
            pub fn code(self) -> u32 {
                match self {
                    $( SdoAbortCode::$name => $code, )*
                    SdoAbortCode::Unknown(c) => c,
                }
            }

            /// The variant of a code.
            pub fn from_code(code: u32) -> SdoAbortCode {
                match code {
                    $( $code => SdoAbortCode::$name, )*
                    c => SdoAbortCode::Unknown(c),
                }
            }

            /// The CiA 301 description.
            pub fn text(self) -> &'static str {
                match self {
                    $( SdoAbortCode::$name => $text, )*
                    SdoAbortCode::Unknown(_) => "abort code not defined by CiA 301",
                }
            }

            /// The HAL error kind: a timeout is a link failure, a refusal is the device's.
            pub fn kind(self) -> ErrorKind {
                match self {
                    $( SdoAbortCode::$name => ErrorKind::$kind, )*
                    SdoAbortCode::Unknown(_) => ErrorKind::Other,
                }
            }
        }
    };
}

abort_codes! {
    ToggleBitNotAlternated = 0x0503_0000, "toggle bit not alternated", Other;
    ProtocolTimedOut = 0x0504_0000, "SDO protocol timed out", Timeout;
    InvalidCommandSpecifier = 0x0504_0001, "client/server command specifier not valid or unknown", Unsupported;
    InvalidBlockSize = 0x0504_0002, "invalid block size (block mode only)", InvalidArgument;
    InvalidSequenceNumber = 0x0504_0003, "invalid sequence number (block mode only)", Other;
    CrcError = 0x0504_0004, "CRC error (block mode only)", Other;
    OutOfMemory = 0x0504_0005, "out of memory", Other;
    UnsupportedAccess = 0x0601_0000, "unsupported access to an object", Unsupported;
    WriteOnly = 0x0601_0001, "attempt to read a write only object", Unsupported;
    ReadOnly = 0x0601_0002, "attempt to write a read only object", Unsupported;
    ObjectDoesNotExist = 0x0602_0000, "object does not exist in the object dictionary", Unsupported;
    NotMappable = 0x0604_0041, "object cannot be mapped to the PDO", InvalidArgument;
    PdoLengthExceeded = 0x0604_0042, "the number and length of the objects to be mapped would exceed PDO length", InvalidArgument;
    ParameterIncompatibility = 0x0604_0043, "general parameter incompatibility reason", InvalidArgument;
    InternalIncompatibility = 0x0604_0047, "general internal incompatibility in the device", DeviceFault;
    HardwareError = 0x0606_0000, "access failed due to a hardware error", DeviceFault;
    LengthMismatch = 0x0607_0010, "data type does not match, length of service parameter does not match", InvalidArgument;
    LengthTooHigh = 0x0607_0012, "data type does not match, length of service parameter too high", InvalidArgument;
    LengthTooLow = 0x0607_0013, "data type does not match, length of service parameter too low", InvalidArgument;
    SubIndexDoesNotExist = 0x0609_0011, "sub-index does not exist", Unsupported;
    InvalidValue = 0x0609_0030, "invalid value for parameter (download only)", InvalidArgument;
    ValueTooHigh = 0x0609_0031, "value of parameter written too high (download only)", InvalidArgument;
    ValueTooLow = 0x0609_0032, "value of parameter written too low (download only)", InvalidArgument;
    MaxLessThanMin = 0x0609_0036, "maximum value is less than minimum value", InvalidArgument;
    ResourceNotAvailable = 0x060A_0023, "resource not available: SDO connection", WouldBlock;
    GeneralError = 0x0800_0000, "general error", Other;
    CannotStore = 0x0800_0020, "data cannot be transferred or stored to the application", DeviceFault;
    CannotStoreLocalControl = 0x0800_0021, "data cannot be transferred or stored to the application because of local control", NotReady;
    CannotStoreDeviceState = 0x0800_0022, "data cannot be transferred or stored to the application because of the present device state", NotReady;
    NoObjectDictionary = 0x0800_0023, "object dictionary dynamic generation fails or no object dictionary is present", DeviceFault;
    NoDataAvailable = 0x0800_0024, "no data available", NotReady;
}

impl fmt::Display for SdoAbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "abort 0x{:08X}: {}", self.code(), self.text())
    }
}

impl std::error::Error for SdoAbortCode {}

impl Error for SdoAbortCode {
    fn kind(&self) -> ErrorKind {
        SdoAbortCode::kind(*self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_code_round_trips_and_has_text() {
        assert_eq!(SdoAbortCode::ALL.len(), 31);
        for &a in SdoAbortCode::ALL {
            assert_eq!(SdoAbortCode::from_code(a.code()), a);
            assert!(!a.text().is_empty());
        }
        assert_eq!(
            SdoAbortCode::from_code(0x0602_0000),
            SdoAbortCode::ObjectDoesNotExist
        );
        assert_eq!(
            SdoAbortCode::ObjectDoesNotExist.to_string(),
            "abort 0x06020000: object does not exist in the object dictionary"
        );
        assert_eq!(
            SdoAbortCode::from_code(0x1234_5678),
            SdoAbortCode::Unknown(0x1234_5678)
        );
    }

    #[test]
    fn timeout_is_a_link_failure_refusals_are_not() {
        assert!(SdoAbortCode::ProtocolTimedOut.kind().is_link_failure());
        assert!(!SdoAbortCode::ReadOnly.kind().is_link_failure());
        assert_eq!(
            SdoAbortCode::CannotStoreDeviceState.kind(),
            ErrorKind::NotReady
        );
    }
}
