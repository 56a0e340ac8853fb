//! The register map: where a channel lives on a Modbus device and how its raw registers
//! become a value.
//!
//! A digital channel is a coil, a discrete input, or one bit of a holding/input register.
//! An analog channel is one register (`u16`/`i16`) or two consecutive registers holding a
//! 32-bit integer or an IEEE float, in the word order the device uses (Modbus itself only
//! defines big-endian bytes inside a register). Scaling and offset to engineering units are
//! applied above the HAL, by the channel definition, the same for every backend.

use std::fmt;

/// The four Modbus data tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Table {
    /// Read/write bits (function codes 1, 5, 15).
    Coil,
    /// Read-only bits (function code 2).
    DiscreteInput,
    /// Read/write 16-bit registers (function codes 3, 6, 16, 22).
    HoldingRegister,
    /// Read-only 16-bit registers (function code 4).
    InputRegister,
}

impl Table {
    /// True for the bit tables.
    pub fn is_bits(self) -> bool {
        matches!(self, Table::Coil | Table::DiscreteInput)
    }

    /// True when the master may write the table.
    pub fn is_writable(self) -> bool {
        matches!(self, Table::Coil | Table::HoldingRegister)
    }

    /// Most items one read request may carry (Modbus application protocol 1.1b3, 6.1-6.4).
    pub fn max_read(self) -> u16 {
        if self.is_bits() {
            2000
        } else {
            125
        }
    }

    /// The name used in configuration and messages.
    pub fn as_str(self) -> &'static str {
        match self {
            Table::Coil => "coil",
            Table::DiscreteInput => "discrete_input",
            Table::HoldingRegister => "holding_register",
            Table::InputRegister => "input_register",
        }
    }
}

impl fmt::Display for Table {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// How a value is encoded in its registers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    /// One bit: a coil or discrete input.
    Bool,
    /// Bit `0..=15` of a register (0 = least significant).
    Bit(u8),
    /// Unsigned 16-bit register.
    U16,
    /// Signed 16-bit register.
    I16,
    /// Unsigned 32-bit value over two registers.
    U32,
    /// Signed 32-bit value over two registers.
    I32,
    /// IEEE 754 single over two registers.
    F32,
}

impl DataType {
    /// Registers (or bits) the value occupies.
    pub fn width(self) -> u16 {
        match self {
            DataType::U32 | DataType::I32 | DataType::F32 => 2,
            _ => 1,
        }
    }

    /// True for the single-bit types.
    pub fn is_digital(self) -> bool {
        matches!(self, DataType::Bool | DataType::Bit(_))
    }
}

/// Which register of a 32-bit value comes first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WordOrder {
    /// The high word at the lower address (big-endian, "ABCD"): most devices.
    #[default]
    HighFirst,
    /// The low word at the lower address ("CDAB").
    LowFirst,
}

/// One channel's place on the device.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointSpec {
    /// Data table.
    pub table: Table,
    /// Address (0-based protocol address) of the first register or bit.
    pub address: u16,
    /// Encoding.
    pub data_type: DataType,
    /// Word order of 32-bit values.
    pub word_order: WordOrder,
}

/// Why a point specification is not usable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MapError {
    /// The type does not fit the table (a float in a coil, a whole register in a bit table).
    #[error("type {data_type:?} does not fit table {table}")]
    TypeTable {
        /// The table.
        table: Table,
        /// The type.
        data_type: DataType,
    },
    /// A bit number above 15.
    #[error("bit {0} out of range 0..=15")]
    Bit(u8),
    /// The value runs past address 65535.
    #[error("address {address} + {width} registers runs past 65535")]
    Address {
        /// First address.
        address: u16,
        /// Registers needed.
        width: u16,
    },
    /// An output on a read-only table.
    #[error("{0} is read-only: outputs need a coil or a holding register")]
    ReadOnly(Table),
}

impl PointSpec {
    /// A point, checked: type fits table, bit in range, address span fits.
    pub fn new(
        table: Table,
        address: u16,
        data_type: DataType,
        word_order: WordOrder,
    ) -> Result<PointSpec, MapError> {
        let bits_ok = table.is_bits() == (data_type == DataType::Bool);
        if !bits_ok {
            return Err(MapError::TypeTable { table, data_type });
        }
        if let DataType::Bit(b) = data_type {
            if b > 15 {
                return Err(MapError::Bit(b));
            }
        }
        let width = data_type.width();
        if address.checked_add(width - 1).is_none() {
            return Err(MapError::Address { address, width });
        }
        Ok(PointSpec {
            table,
            address,
            data_type,
            word_order,
        })
    }

    /// Checks that the point can be written by the master.
    pub fn writable(self) -> Result<PointSpec, MapError> {
        if self.table.is_writable() {
            Ok(self)
        } else {
            Err(MapError::ReadOnly(self.table))
        }
    }

    /// Registers or bits occupied.
    pub fn width(&self) -> u16 {
        self.data_type.width()
    }

    /// Value from the raw items at this point's address (`raw.len() >= width`): bits as 0/1,
    /// registers as read. Digital points give 0.0 or 1.0.
    pub fn decode(&self, raw: &[u16]) -> f64 {
        let w = |i: usize| raw.get(i).copied().unwrap_or(0);
        let pair = || -> u32 {
            let (hi, lo) = match self.word_order {
                WordOrder::HighFirst => (w(0), w(1)),
                WordOrder::LowFirst => (w(1), w(0)),
            };
            (u32::from(hi) << 16) | u32::from(lo)
        };
        match self.data_type {
            DataType::Bool => f64::from(u8::from(w(0) != 0)),
            DataType::Bit(b) => f64::from((w(0) >> b) & 1),
            DataType::U16 => f64::from(w(0)),
            DataType::I16 => f64::from(w(0) as i16),
            DataType::U32 => f64::from(pair()),
            DataType::I32 => f64::from(pair() as i32),
            DataType::F32 => f64::from(f32::from_bits(pair())),
        }
    }

    /// Raw registers for `value`, rounded and saturated to the type's range (a bit point
    /// gives its mask in word 0 when `value` is non-zero: the caller merges it). Returns the
    /// words and how many of them are used.
    pub fn encode(&self, value: f64) -> ([u16; 2], usize) {
        let split = |v: u32| -> [u16; 2] {
            let (hi, lo) = ((v >> 16) as u16, v as u16);
            match self.word_order {
                WordOrder::HighFirst => [hi, lo],
                WordOrder::LowFirst => [lo, hi],
            }
        };
        // `as` from f64 saturates and maps NaN to 0: exactly the clamp wanted here.
        let r = value.round();
        match self.data_type {
            DataType::Bool => ([u16::from(value != 0.0), 0], 1),
            DataType::Bit(b) => ([u16::from(value != 0.0) << b, 0], 1),
            DataType::U16 => ([r as u16, 0], 1),
            DataType::I16 => ([r as i16 as u16, 0], 1),
            DataType::U32 => (split(r as u32), 2),
            DataType::I32 => (split(r as i32 as u32), 2),
            DataType::F32 => (split((value as f32).to_bits()), 2),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(table: Table, t: DataType, o: WordOrder) -> PointSpec {
        PointSpec::new(table, 10, t, o).unwrap()
    }

    #[test]
    fn thirty_two_bit_values_honour_the_word_order() {
        let hi = p(Table::HoldingRegister, DataType::U32, WordOrder::HighFirst);
        let lo = p(Table::HoldingRegister, DataType::U32, WordOrder::LowFirst);
        assert_eq!(hi.decode(&[0x0001, 0x0002]), 65538.0);
        assert_eq!(lo.decode(&[0x0002, 0x0001]), 65538.0);
        assert_eq!(hi.encode(65538.0), ([1, 2], 2));
        assert_eq!(lo.encode(65538.0), ([2, 1], 2));
        let f = p(Table::InputRegister, DataType::F32, WordOrder::HighFirst);
        let (w, n) = f.encode(-12.5);
        assert_eq!(n, 2);
        assert_eq!(f.decode(&w), -12.5);
        assert_eq!(w, [0xC148, 0x0000]);
        let i = p(Table::HoldingRegister, DataType::I32, WordOrder::LowFirst);
        assert_eq!(i.decode(&i.encode(-100_000.0).0), -100_000.0);
    }

    #[test]
    fn sixteen_bit_values_and_bits() {
        let s = p(Table::HoldingRegister, DataType::I16, WordOrder::HighFirst);
        assert_eq!(s.decode(&[0xFFFF]), -1.0);
        assert_eq!(s.encode(-2.0).0[0], 0xFFFE);
        assert_eq!(s.encode(1e9).0[0], i16::MAX as u16, "saturates");
        let u = p(Table::InputRegister, DataType::U16, WordOrder::HighFirst);
        assert_eq!(u.encode(-5.0).0[0], 0, "saturates at 0");
        assert_eq!(u.encode(f64::NAN).0[0], 0);
        let b = p(Table::InputRegister, DataType::Bit(3), WordOrder::HighFirst);
        assert_eq!(b.decode(&[0b1000]), 1.0);
        assert_eq!(b.decode(&[0b0111]), 0.0);
        assert_eq!(b.encode(1.0).0[0], 0b1000);
    }

    #[test]
    fn bad_specs_are_refused_with_the_reason() {
        assert!(matches!(
            PointSpec::new(Table::Coil, 0, DataType::F32, WordOrder::HighFirst),
            Err(MapError::TypeTable { .. })
        ));
        assert!(matches!(
            PointSpec::new(
                Table::HoldingRegister,
                0,
                DataType::Bool,
                WordOrder::HighFirst
            ),
            Err(MapError::TypeTable { .. })
        ));
        assert_eq!(
            PointSpec::new(
                Table::HoldingRegister,
                0,
                DataType::Bit(16),
                WordOrder::HighFirst
            ),
            Err(MapError::Bit(16))
        );
        assert!(matches!(
            PointSpec::new(
                Table::HoldingRegister,
                65535,
                DataType::U32,
                WordOrder::HighFirst
            ),
            Err(MapError::Address { .. })
        ));
        let di = PointSpec::new(
            Table::DiscreteInput,
            0,
            DataType::Bool,
            WordOrder::HighFirst,
        );
        assert_eq!(
            di.unwrap().writable(),
            Err(MapError::ReadOnly(Table::DiscreteInput))
        );
    }
}
