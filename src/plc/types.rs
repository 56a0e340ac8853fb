//! Elementary data types and the typing rules of expressions: which implicit conversions
//! are allowed (IEC 61131-3 ed.3 table 11, widening only), the common type of a binary
//! operation, and the value ranges of the integer types. Independent of POUs so other
//! front ends (issue 12) can type-check expressions with it.

/// The integer and bit-string types. All are held in an `i64` cell: signed ones sign-
/// extended, unsigned ones zero-extended (ULINT/LWORD reinterpret the bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum IntKind {
    /// 8-bit signed
    SInt,
    /// 16-bit signed
    Int,
    /// 32-bit signed
    DInt,
    /// 64-bit signed
    LInt,
    /// 8-bit unsigned
    USInt,
    /// 16-bit unsigned
    UInt,
    /// 32-bit unsigned
    UDInt,
    /// 64-bit unsigned
    ULInt,
    /// 8-bit string
    Byte,
    /// 16-bit string
    Word,
    /// 32-bit string
    DWord,
    /// 64-bit string
    LWord,
}

impl IntKind {
    /// Every kind, for name lookup.
    pub const ALL: [IntKind; 12] = [
        IntKind::SInt,
        IntKind::Int,
        IntKind::DInt,
        IntKind::LInt,
        IntKind::USInt,
        IntKind::UInt,
        IntKind::UDInt,
        IntKind::ULInt,
        IntKind::Byte,
        IntKind::Word,
        IntKind::DWord,
        IntKind::LWord,
    ];
    /// Width in bits.
    pub fn bits(self) -> u32 {
        use IntKind::*;
        match self {
            SInt | USInt | Byte => 8,
            Int | UInt | Word => 16,
            DInt | UDInt | DWord => 32,
            LInt | ULInt | LWord => 64,
        }
    }
    /// Two's complement signed.
    pub fn signed(self) -> bool {
        matches!(
            self,
            IntKind::SInt | IntKind::Int | IntKind::DInt | IntKind::LInt
        )
    }
    /// BYTE, WORD, DWORD, LWORD.
    pub fn bitstring(self) -> bool {
        matches!(
            self,
            IntKind::Byte | IntKind::Word | IntKind::DWord | IntKind::LWord
        )
    }
    /// The IEC name.
    pub fn name(self) -> &'static str {
        use IntKind::*;
        match self {
            SInt => "SINT",
            Int => "INT",
            DInt => "DINT",
            LInt => "LINT",
            USInt => "USINT",
            UInt => "UINT",
            UDInt => "UDINT",
            ULInt => "ULINT",
            Byte => "BYTE",
            Word => "WORD",
            DWord => "DWORD",
            LWord => "LWORD",
        }
    }
    /// Wraps a value to this type's width (two's complement, as CODESYS and TwinCAT do on
    /// overflow; the standard leaves overflow to the implementation).
    #[inline(always)]
    pub fn wrap(self, v: i64) -> i64 {
        // Branch-free (a shift pair by a per-kind amount, 0 for 64 bits): inlined into every
        // fused integer instruction, where a branch on the kind would be a second dispatch.
        let sh = 64 - self.bits();
        let signed = (v << sh) >> sh;
        let unsigned = ((v as u64) << sh >> sh) as i64;
        if self.signed() {
            signed
        } else {
            unsigned
        }
    }
    /// Smallest value.
    pub fn min(self) -> i128 {
        if self.signed() {
            -(1i128 << (self.bits() - 1))
        } else {
            0
        }
    }
    /// Largest value.
    pub fn max(self) -> i128 {
        if self.signed() {
            (1i128 << (self.bits() - 1)) - 1
        } else {
            (1i128 << self.bits()) - 1
        }
    }
}

/// A type as the compiler sees it. Derived types are indices into the compiler's tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Ty {
    /// BOOL
    Bool,
    /// An integer or bit string.
    Int(IntKind),
    /// REAL (f32 semantics: every result is rounded to single precision).
    Real,
    /// LREAL
    LReal,
    /// TIME, held in nanoseconds.
    Time,
    /// An enumeration (index).
    Enum(u32),
    /// An array (index).
    Array(u32),
    /// A structure (index).
    Struct(u32),
    /// A function block type (index).
    Fb(u32),
    /// No value (a function without result, an erroneous expression).
    Void,
}

impl Ty {
    /// An elementary type held in one cell.
    pub fn scalar(self) -> bool {
        matches!(
            self,
            Ty::Bool | Ty::Int(_) | Ty::Real | Ty::LReal | Ty::Time | Ty::Enum(_)
        )
    }
    /// REAL or LREAL.
    pub fn float(self) -> bool {
        matches!(self, Ty::Real | Ty::LReal)
    }
    /// Any integer or bit string.
    pub fn int(self) -> Option<IntKind> {
        match self {
            Ty::Int(k) => Some(k),
            _ => None,
        }
    }
    /// Numeric: integers (not bit strings) and reals.
    pub fn numeric(self) -> bool {
        self.float() || self.int().is_some_and(|k| !k.bitstring())
    }
}

/// The elementary type named `name` (upper case), if it is one.
pub fn elementary(name: &str) -> Option<Ty> {
    Some(match name {
        "BOOL" => Ty::Bool,
        "REAL" => Ty::Real,
        "LREAL" => Ty::LReal,
        "TIME" | "LTIME" => Ty::Time,
        _ => Ty::Int(IntKind::ALL.into_iter().find(|k| k.name() == name)?),
    })
}

/// Whether a value of `from` may be used where `to` is expected without a conversion
/// function: the widening conversions of IEC 61131-3 ed.3 table 11 (no loss of value).
/// CODESYS is laxer (it warns on narrowing); the standard's rule catches real bugs.
pub fn implicit(from: Ty, to: Ty) -> bool {
    if from == to {
        return true;
    }
    match (from, to) {
        (Ty::Int(a), Ty::Int(b)) => {
            if a.bitstring() || b.bitstring() {
                a.bitstring() && b.bitstring() && a.bits() < b.bits()
            } else if a.signed() == b.signed() {
                a.bits() < b.bits()
            } else {
                !a.signed() && b.signed() && a.bits() < b.bits()
            }
        }
        (Ty::Int(a), Ty::Real) => !a.bitstring() && a.bits() <= 16,
        (Ty::Int(a), Ty::LReal) => !a.bitstring() && a.bits() <= 32,
        (Ty::Real, Ty::LReal) => true,
        _ => false,
    }
}

/// The type both operands of a binary operation convert to, if there is one.
pub fn common(a: Ty, b: Ty) -> Option<Ty> {
    if implicit(a, b) {
        Some(b)
    } else if implicit(b, a) {
        Some(a)
    } else {
        // e.g. SINT and USINT: both widen to INT.
        [
            Ty::Int(IntKind::Int),
            Ty::Int(IntKind::DInt),
            Ty::Int(IntKind::LInt),
            Ty::Real,
            Ty::LReal,
        ]
        .into_iter()
        .find(|&t| implicit(a, t) && implicit(b, t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The branch-free wrap is the value modulo 2^bits, read signed or unsigned, for every
    /// kind (64-bit kinds unchanged).
    #[test]
    fn wrap_is_the_value_modulo_the_width() {
        let vals = [
            0i64, 1, -1, 127, 128, -129, 255, 256, 32_767, 32_768, -32_769, 65_535,
        ];
        let more = [
            65_536,
            1 << 31,
            -(1 << 31) - 1,
            (1 << 32) + 5,
            i64::MIN,
            i64::MAX,
        ];
        for k in IntKind::ALL {
            for v in vals.iter().chain(&more).copied() {
                let m = 1i128 << k.bits();
                let mut r = (v as i128).rem_euclid(m);
                if k.signed() && r >= m / 2 {
                    r -= m;
                }
                let want = if k.bits() == 64 { v } else { r as i64 };
                assert_eq!(k.wrap(v), want, "{k:?} {v}");
            }
        }
    }

    #[test]
    fn wrap_is_twos_complement() {
        assert_eq!(IntKind::Int.wrap(32768), -32768);
        assert_eq!(IntKind::UInt.wrap(-1), 65535);
        assert_eq!(IntKind::SInt.wrap(200), -56);
        assert_eq!(IntKind::LInt.wrap(i64::MIN), i64::MIN);
    }

    #[test]
    fn widening_only() {
        let int = Ty::Int(IntKind::Int);
        let dint = Ty::Int(IntKind::DInt);
        assert!(implicit(int, dint));
        assert!(!implicit(dint, int));
        assert!(implicit(int, Ty::Real));
        assert!(!implicit(dint, Ty::Real));
        assert!(!implicit(Ty::Int(IntKind::Word), int));
        assert_eq!(
            common(Ty::Int(IntKind::SInt), Ty::Int(IntKind::USInt)),
            Some(int)
        );
    }
}
