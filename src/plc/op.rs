//! The PLC's instruction set: the instructions ([`Op`]) the compiler emits and the peephole
//! passes fuse, the operators they carry, the faults a scan can end in, and [`Code`], a
//! sequence checked once so that control never leaves it. Apart from the interpreter
//! ([`super::vm`]) so that the compiler and the fusion passes read the instruction set
//! without the interpreter's loop beside it.

use super::stdfb::StdFb;
use super::types::IntKind;

/// Comparison operators. Each discriminant is the set of outcomes for which the comparison
/// holds (bit 0 less, 1 equal, 2 greater, 3 unordered), so [`Cmp::test`] is a shift and a
/// mask instead of a jump on the operator: a fused instruction's comparison then costs no
/// second branch beside its own dispatch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Cmp {
    /// `=`
    Eq = EQ,
    /// `<>` (true when unordered, as `!=` on NaN)
    Ne = LT | GT | UNORD,
    /// `<`
    Lt = LT,
    /// `<=`
    Le = LT | EQ,
    /// `>`
    Gt = GT,
    /// `>=`
    Ge = GT | EQ,
}

const LT: u8 = 1;
const EQ: u8 = 2;
const GT: u8 = 4;
const UNORD: u8 = 8;

impl Cmp {
    #[inline(always)]
    pub(super) fn test<T: PartialOrd>(self, a: T, b: T) -> bool {
        // 0 less, 1 equal, 2 greater, 3 unordered (NaN; folded away for integers, which
        // are always ordered).
        let (ge, lt) = (a >= b, a < b);
        let outcome = ge as u8 + (a > b) as u8 + 3 * (!ge && !lt) as u8;
        (self as u8 >> outcome) & 1 != 0
    }
}

/// One-argument floating point functions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MathFn {
    /// ABS
    Abs,
    /// SQRT
    Sqrt,
    /// LN
    Ln,
    /// LOG (base 10)
    Log,
    /// EXP
    Exp,
    /// SIN
    Sin,
    /// COS
    Cos,
    /// TAN
    Tan,
    /// ASIN
    Asin,
    /// ACOS
    Acos,
    /// ATAN
    Atan,
}

/// Bit shifts and rotations on a bit string of a given width.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shift {
    /// SHL
    Shl,
    /// SHR
    Shr,
    /// ROL
    Rol,
    /// ROR
    Ror,
}

/// Binary operations that fuse with their right operand (see `peephole`). The logic
/// operations come first so that [`Bin::apply`] tells them apart with one range test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bin {
    /// Bitwise AND.
    And,
    /// Bitwise OR.
    Or,
    /// Bitwise XOR.
    Xor,
    /// BOOL `a AND NOT b` (fused `NotB` + `And`).
    AndN,
    /// BOOL `a OR NOT b`.
    OrN,
    /// Signed comparison.
    CmpI(Cmp),
    /// Integer add.
    Add(IntKind),
    /// Integer subtract.
    Sub(IntKind),
    /// Integer multiply.
    Mul(IntKind),
    /// Unsigned comparison.
    CmpU(Cmp),
    /// Float comparison.
    CmpF(Cmp),
    /// Float add.
    FAdd(bool),
    /// Float subtract.
    FSub(bool),
    /// Float multiply.
    FMul(bool),
    /// Signed min/max.
    MinMaxI(bool),
    /// Float min/max.
    MinMaxF(bool),
    /// Integer divide by a constant that is not zero (fused only then: it cannot fault).
    Div(IntKind),
    /// Integer remainder by a constant that is not zero.
    Mod(IntKind),
}

/// Integer `a / b` (`div`) or `a MOD b` of kind `k`, `b` not zero: truncating, the
/// remainder with the sign of the dividend, 64-bit unsigned kinds unsigned, wrapped.
#[inline(always)]
pub(super) fn div_rem(k: IntKind, a: u64, b: u64, div: bool) -> u64 {
    let (sa, sb) = (a as i64, b as i64);
    let r = if k.bits() == 64 && !k.signed() {
        if div {
            a / b
        } else {
            a % b
        }
    } else if k.bits() <= 32 && sa as i32 as i64 == sa && sb as i32 as i64 == sb {
        // The 32-bit division is the faster instruction. It differs from the 64-bit one
        // only for i32::MIN / -1 (-2^31 instead of 2^31), the same after wrapping to a
        // kind of 32 bits or fewer.
        let (a, b) = (sa as i32, sb as i32);
        (if div {
            a.wrapping_div(b)
        } else {
            a.wrapping_rem(b)
        }) as i64 as u64
    } else if div {
        (a as i64).wrapping_div(b as i64) as u64
    } else {
        (a as i64).wrapping_rem(b as i64) as u64
    };
    k.wrap(r as i64) as u64
}

/// The multiplier of [`mod16`] for divisor `d` (`2..=65535`): `ceil(2^32 / d)`.
pub fn mod_magic(d: u16) -> u32 {
    u32::MAX / d as u32 + 1
}

/// `a MOD d` (the sign of the dividend) for `2 <= d < 2^16`, with `m` =
/// [`mod_magic`]`(d)`: for `|a| < 2^16` (every cell of a 16-bit kind) Lemire's remainder by
/// multiplication, exact for 16-bit operands and a 32-bit multiplier, a few cycles where the
/// divide takes tens and stalls what depends on it. A wider value (a raw cell written from
/// outside) takes the divide, so the result is the division's for every cell.
#[inline(always)]
pub fn mod16(a: i64, d: u16, m: u32) -> i64 {
    let ua = a.unsigned_abs();
    if ua >> 16 != 0 {
        return a % d as i64;
    }
    let low = m.wrapping_mul(ua as u32);
    let r = ((low as u64 * d as u64) >> 32) as i64;
    if a < 0 {
        -r
    } else {
        r
    }
}

impl Bin {
    /// Whether its operands are floats (REAL/LREAL cells).
    pub fn float(self) -> bool {
        matches!(
            self,
            Bin::CmpF(_) | Bin::FAdd(_) | Bin::FSub(_) | Bin::FMul(_) | Bin::MinMaxF(_)
        )
    }

    /// The logic operations as masks: `b` is XORed with the first, then the result is
    /// `(a & b & second) | ((a ^ b) & third)` (AND, OR, XOR and the negated-operand forms).
    #[inline(always)]
    fn logic(self) -> Option<(u64, u64, u64)> {
        Some(match self {
            Bin::And => (0, !0, 0),
            Bin::Or => (0, !0, !0),
            Bin::Xor => (0, 0, !0),
            Bin::AndN => (1, !0, 0),
            Bin::OrN => (1, !0, !0),
            _ => return None,
        })
    }

    /// `a op b`, exactly as the unfused instruction computes it. Inlined into every fused
    /// instruction: the common operations (logic, signed comparison, integer add and
    /// subtract) are picked out by tests and computed without a branch on the operator,
    /// because a jump table here is a second indirect jump beside the instruction's own
    /// dispatch; the others go through one match.
    #[inline(always)]
    pub fn apply(self, a: u64, b: u64) -> u64 {
        if let Some((n, both, either)) = self.logic() {
            let b = b ^ n;
            return (a & b & both) | ((a ^ b) & either);
        }
        match self {
            Bin::CmpI(c) => return c.test(a as i64, b as i64) as u64,
            Bin::Add(k) => return k.wrap((a as i64).wrapping_add(b as i64)) as u64,
            Bin::Sub(k) => return k.wrap((a as i64).wrapping_sub(b as i64)) as u64,
            _ => {}
        }
        self.apply_other(a, b)
    }

    /// The less common operations of [`Bin::apply`].
    #[inline(always)]
    fn apply_other(self, a: u64, b: u64) -> u64 {
        match self {
            Bin::Add(k) => k.wrap((a as i64).wrapping_add(b as i64)) as u64,
            Bin::Sub(k) => k.wrap((a as i64).wrapping_sub(b as i64)) as u64,
            Bin::Mul(k) => k.wrap((a as i64).wrapping_mul(b as i64)) as u64,
            Bin::CmpI(c) => c.test(a as i64, b as i64) as u64,
            Bin::CmpU(c) => c.test(a, b) as u64,
            Bin::CmpF(c) => c.test(f(a), f(b)) as u64,
            Bin::And => a & b,
            Bin::Or => a | b,
            Bin::Xor => a ^ b,
            Bin::FAdd(s) => fb(f(a) + f(b), s),
            Bin::FSub(s) => fb(f(a) - f(b), s),
            Bin::FMul(s) => fb(f(a) * f(b), s),
            Bin::MinMaxI(max) => {
                if ((a as i64) < (b as i64)) != max {
                    a
                } else {
                    b
                }
            }
            Bin::MinMaxF(max) => {
                if (f(a) < f(b)) != max {
                    a
                } else {
                    b
                }
            }
            Bin::Div(k) => div_rem(k, a, b, true),
            Bin::Mod(k) => div_rem(k, a, b, false),
            Bin::AndN => a & (b ^ 1),
            Bin::OrN => a | (b ^ 1),
        }
    }
}

/// Why a scan stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// Integer division or MOD by zero.
    DivisionByZero,
    /// An array index outside the declared bounds.
    IndexOutOfRange,
    /// MUX selector outside its inputs.
    SelectorOutOfRange,
    /// The per-scan instruction budget ran out (an endless or too long loop).
    BudgetExhausted,
    /// Calls nested deeper than the call stack (cannot happen without recursion, which the
    /// compiler refuses; kept so a compiler bug faults instead of crashing).
    CallDepth,
}

impl std::fmt::Display for FaultKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FaultKind::DivisionByZero => "division by zero",
            FaultKind::IndexOutOfRange => "array index out of range",
            FaultKind::SelectorOutOfRange => "MUX selector out of range",
            FaultKind::BudgetExhausted => "instruction budget exhausted",
            FaultKind::CallDepth => "call stack exhausted",
        })
    }
}

/// An instruction. Cells hold BOOL as 0/1, integers sign- or zero-extended, TIME in ns and
/// REAL/LREAL as `f64` bits (REAL values rounded to single precision).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Op {
    /// Push a constant cell.
    Push(u64),
    /// Push `mem[base + o]`.
    LoadL(u32),
    /// Push `mem[a]`.
    LoadG(u32),
    /// Pop into `mem[base + o]`.
    StoreL(u32),
    /// Pop into `mem[a]`.
    StoreG(u32),
    /// Push the address `base + o`.
    AddrL(u32),
    /// Push the address `a`.
    AddrG(u32),
    /// Pop an address, push `mem[addr + k]`.
    LoadInd(u32),
    /// Pop a value and an address, store at `addr + k`.
    StoreInd(u32),
    /// Pop a source and a destination address, copy `n` cells.
    Copy(u32),
    /// Pop an index and an address; push `addr + (index - lo) * stride`, fault outside
    /// `lo .. lo + len`.
    Index {
        /// Lower bound.
        lo: i32,
        /// Number of elements.
        len: u32,
        /// Cells per element.
        stride: u32,
    },
    /// Discard the top.
    Pop,
    /// Duplicate the top.
    Dup,
    /// Replace the top with its bit `n`.
    GetBit(u8),
    /// Pop a BOOL into bit `n` of `mem[base + o]`.
    SetBitL(u32, u8),
    /// Pop a BOOL into bit `n` of `mem[a]`.
    SetBitG(u32, u8),
    /// Pop a BOOL and an address; set bit `n` of `mem[addr + k]`.
    SetBitInd(u32, u8),
    /// Integer add, wrapped to the kind.
    Add(IntKind),
    /// Integer subtract.
    Sub(IntKind),
    /// Integer multiply.
    Mul(IntKind),
    /// Integer divide (truncating; faults on zero).
    Div(IntKind),
    /// Integer remainder (sign of the dividend; faults on zero).
    Mod(IntKind),
    /// Integer negate.
    Neg(IntKind),
    /// Signed (or BOOL/TIME/enum) comparison.
    CmpI(Cmp),
    /// Unsigned 64-bit comparison (ULINT, LWORD).
    CmpU(Cmp),
    /// Floating comparison.
    CmpF(Cmp),
    /// Bitwise AND (BOOL and bit strings).
    And,
    /// Bitwise OR.
    Or,
    /// Bitwise XOR.
    Xor,
    /// Bitwise NOT within the kind's width (BOOL uses `Byte`-like width 1 via `NotB`).
    NotW(IntKind),
    /// Boolean NOT.
    NotB,
    /// Float add; `true` rounds to single precision.
    FAdd(bool),
    /// Float subtract.
    FSub(bool),
    /// Float multiply.
    FMul(bool),
    /// Float divide (IEEE: x/0 is ±inf).
    FDiv(bool),
    /// Float power.
    FPow(bool),
    /// Float negate.
    FNeg,
    /// Float function.
    Math(MathFn, bool),
    /// Wrap an integer to a kind (narrowing or sign change).
    Wrap(IntKind),
    /// Signed integer to float.
    IToF(bool),
    /// Unsigned 64-bit integer to float.
    UToF(bool),
    /// Float to integer, rounded half away from zero, saturated at 64 bits, wrapped.
    FToI(IntKind),
    /// Float to integer, truncated toward zero.
    FTrunc(IntKind),
    /// Round an LREAL to REAL.
    FSingle,
    /// Integer absolute value, wrapped.
    AbsI(IntKind),
    /// Pop b, a; push min (or max when `true`), signed.
    MinMaxI(bool),
    /// Unsigned min/max.
    MinMaxU(bool),
    /// Float min/max.
    MinMaxF(bool),
    /// Pop in1, in0, g; push `g ? in1 : in0`.
    Sel,
    /// Pop `n` inputs and a selector k; push input k, fault if out of range.
    Mux(u32),
    /// Pop n, x; shift or rotate x by n within the kind's width.
    Shift(Shift, IntKind),
    /// Jump.
    Jmp(u32),
    /// Pop; jump if zero.
    Jz(u32),
    /// Pop; jump if not zero.
    Jnz(u32),
    /// Call user code at `entry` with base `base + o` (`rel`) or `o`.
    Call {
        /// First instruction.
        entry: u32,
        /// Offset or address of the callee's base.
        at: u32,
        /// `at` is relative to the caller's base.
        rel: bool,
    },
    /// Pop a base address and call user code at the entry.
    CallInd(u32),
    /// Run a standard block on the instance at `base + o` (`rel`) or `o`.
    Std {
        /// Which block.
        fb: StdFb,
        /// Offset or address of the instance.
        at: u32,
        /// `at` is relative to the caller's base.
        rel: bool,
    },
    /// Pop an instance address and run a standard block on it.
    StdInd(StdFb),
    /// Return from user code.
    Ret,
    /// Fused `LoadL(o)` + binary operation: the right operand is `mem[base + o]`.
    BinL(Bin, u32),
    /// Fused `Push(c)` + binary operation.
    BinC(Bin, u64),
    /// Fused `LoadL(src)` + `StoreL(dst)`.
    MovL(u32, u32),
    /// Fused `Push(c)` + `StoreL(dst)`.
    SetL(u32, u64),
    /// Fused `LoadL(x)` + `BinL(b, y)` + `StoreL(d)`: `mem[d] = mem[x] b mem[y]`, all
    /// relative to the base.
    BinLL(Bin, u32, u32, u32),
    /// Fused `LoadL(x)` + `BinC(b, k)` + `StoreL(d)` with an integer constant that fits 32
    /// bits (sign-extended to the cell).
    BinLI(Bin, u32, i32, u32),
    /// The same with a float constant that is exact in single precision.
    BinLF(Bin, u32, f32, u32),
    /// Fused `BinL(b, y)` + `StoreL(d)`: pop `a`, `mem[d] = a b mem[y]`.
    BinLS(Bin, u32, u32),
    /// A binary operation whose result is stored: pop `b`, `a`, `mem[base + d] = a op b`.
    BinS(Bin, u32),
    /// Fused `LoadL(x)` + `BinL(b, y)`: push `mem[x] b mem[y]`.
    PushLL(Bin, u32, u32),
    /// Fused `LoadL(x)` + `BinC(b, k)` with a 32-bit integer constant: push `mem[x] b k`.
    PushLI(Bin, u32, i32),
    /// The same with a single-precision float constant.
    PushLF(Bin, u32, f32),
    /// Fused `BinC(b, k)` + `StoreL(d)` with a 32-bit integer constant: pop `a`,
    /// `mem[d] = a b k`.
    BinCSI(Bin, i32, u32),
    /// The same with a single-precision float constant.
    BinCSF(Bin, f32, u32),
    /// Fused `LoadL(x)` + `LoadL(y)`.
    LoadLL(u32, u32),
    /// Fused `LoadL(x)` + `IToF(s)`: push `mem[x]` converted to float.
    LoadIToF(u32, bool),
    /// Fused `LoadL(x)` + `Jz(t)`: jump if `mem[x]` is zero.
    JzL(u32, u32),
    /// Fused `LoadL(x)` + `BinL(b, y)` + `Jz(t)`: jump if `mem[x] b mem[y]` is zero
    /// (false).
    JfLL(Bin, u32, u32, u32),
    /// Fused `LoadL(x)` + `BinC(b, k)` + `Jz(t)` with a 32-bit integer constant.
    JfLI(Bin, u32, i32, u32),
    /// The same with a single-precision float constant.
    JfLF(Bin, u32, f32, u32),
    // Fourth generation (`superop`): two operations in one dispatch. Offsets that are
    // 16 bits wide keep the instruction at 16 bytes; a program whose cells lie further
    // from the base keeps the two-instruction form.
    /// Push `(mem[base + x] b1 k1) b2 k2` (fused `PushLI` + `BinC`: `a MOD 7 = 0`).
    PushLIC(Bin, Bin, u16, i32, i32),
    /// Pop `a`; `mem[base + d] = a b2 (mem[base + x] b1 mem[base + y])` (fused `PushLL` +
    /// `BinS`: `... OR (p AND NOT q)`).
    BinSLL(Bin, Bin, u16, u16, u16),
    /// `mem[base + d] = (mem[base + y] b1 k) b2 mem[base + x]` (fused `PushLI` + `BinLS`:
    /// `a := a + b * 3`).
    BinLIL(Bin, Bin, u16, u16, u16, i32),
    /// Pop `a`; `mem[base + d] = a b2 (float(mem[base + x]) b1 k)`, the conversion to
    /// single precision if the flag says so (fused `LoadIToF` + `BinC` + `BinS`:
    /// `r := r * 0.99 + INT_TO_REAL(a) * 0.01`).
    BinSIToF(Bin, Bin, bool, u16, u16, f32),
    /// `mem[base + d] = mem[base + x] * k1 + float(mem[base + y]) * k2`, every step in
    /// single precision when the flag says so, else in double (fused `PushLF(FMul)` +
    /// `BinSIToF(FMul, FAdd)`: the first-order filter `r := r * 0.99 + INT_TO_REAL(a) * 0.01`).
    FilterF(bool, u16, u16, u16, f32, f32),
    /// Push `(mem[base + x] MOD d) b k` for a cell of 16 bits or fewer and a divisor
    /// `2 <= d <= 32767`, the remainder by multiplication with `m` = [`mod_magic`]`(d)`
    /// instead of a division (fused `PushLIC(Mod(kind), b, x, d, k)`: `a MOD 7 = 0`).
    PushModC(Bin, u16, u16, u32, i32),
    /// `mem[base + d] = LIMIT(lo, mem[base + x], hi)` on signed cells (fused
    /// `PushLI(MinMaxI(max))` + `BinCSI(MinMaxI(min))`).
    ClampI(u16, u16, i32, i32),
    /// `mem[base + d] = mem[base + src]`, then the standard block call (fused `MovL` +
    /// `Std`: a block call carries its last input store, `t(IN := x)`).
    StdMov {
        /// The block.
        fb: StdFb,
        /// Instance address.
        at: u32,
        /// Whether `at` is relative to the base.
        rel: bool,
        /// Source cell (base-relative).
        src: u32,
        /// Input cell (base-relative).
        d: u32,
    },
    /// `mem[base + d] = mem[base + src]`, `mem[base + d2] = k << sh`, then the standard
    /// block call (fused `MovL` + `SetL` + `Std`: `t(IN := x, PT := T#5s)`).
    StdSetMov {
        /// The block.
        fb: StdFb,
        /// Whether `at` is relative to the base.
        rel: bool,
        /// Left shift of the constant.
        sh: u8,
        /// Instance address.
        at: u16,
        /// Source cell of the copied input (base-relative).
        src: u16,
        /// The copied input's cell (base-relative).
        d: u16,
        /// The constant input's cell (base-relative).
        d2: u16,
        /// The constant, shifted right by `sh`.
        k: i32,
    },
}

/// Code checked once when it is built: not empty, its last instruction a `Ret` or `Jmp`
/// (control never falls off the end) and every jump target and call entry inside it, so a
/// compiler bug surfaces as a compile error instead of a panic in the scan. (A fetch without
/// the per-instruction bounds check, which this would allow, measured no faster.)
#[derive(Debug, Clone, Default)]
pub struct Code(Vec<Op>);

/// Why instructions are not valid [`Code`] (a compiler bug, never a user's program).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BadCode {
    /// No instructions, or the last one could fall through past the end.
    #[error("code does not end with RET or JMP")]
    OpenEnd,
    /// A jump or call leads outside the code.
    #[error("instruction {at} jumps to {target}, outside the {len} instructions")]
    Target {
        /// The instruction.
        at: usize,
        /// Where it leads.
        target: u32,
        /// Code length.
        len: usize,
    },
}

impl Code {
    /// Checks that control cannot leave the code.
    pub fn new(ops: Vec<Op>) -> Result<Code, BadCode> {
        if !matches!(ops.last(), Some(Op::Ret | Op::Jmp(_))) {
            return Err(BadCode::OpenEnd);
        }
        for (at, op) in ops.iter().enumerate() {
            if let Some(target) = super::peephole::target(*op) {
                if target as usize >= ops.len() {
                    return Err(BadCode::Target {
                        at,
                        target,
                        len: ops.len(),
                    });
                }
            }
        }
        Ok(Code(ops))
    }
}

impl std::ops::Deref for Code {
    type Target = [Op];
    fn deref(&self) -> &[Op] {
        &self.0
    }
}

/// A cell read as a float (REAL cells hold the f32 value widened, see [`fb`]).
#[inline(always)]
pub(super) fn f(v: u64) -> f64 {
    f64::from_bits(v)
}

/// A float stored in a cell, rounded to f32 first for a REAL (`single`).
#[inline(always)]
pub(super) fn fb(v: f64, single: bool) -> u64 {
    if single {
        (v as f32 as f64).to_bits()
    } else {
        v.to_bits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CMPS: [Cmp; 6] = [Cmp::Eq, Cmp::Ne, Cmp::Lt, Cmp::Le, Cmp::Gt, Cmp::Ge];

    /// The comparison as written in the language, for checking the mask form.
    fn reference<T: PartialOrd>(c: Cmp, a: T, b: T) -> bool {
        match c {
            Cmp::Eq => a == b,
            Cmp::Ne => a != b,
            Cmp::Lt => a < b,
            Cmp::Le => a <= b,
            Cmp::Gt => a > b,
            Cmp::Ge => a >= b,
        }
    }

    /// The outcome-mask comparison agrees with the operators, unordered (NaN) floats and
    /// the extremes of the integers included.
    #[test]
    fn comparison_masks_agree_with_the_operators() {
        let ints = [i64::MIN, -7, -1, 0, 1, 3, i64::MAX];
        let floats = [
            f64::NEG_INFINITY,
            -2.5,
            -0.0,
            0.0,
            1.0,
            f64::INFINITY,
            f64::NAN,
        ];
        for c in CMPS {
            for a in ints {
                for b in ints {
                    assert_eq!(c.test(a, b), reference(c, a, b), "{c:?} {a} {b}");
                    let (ua, ub) = (a as u64, b as u64);
                    assert_eq!(c.test(ua, ub), reference(c, ua, ub), "{c:?} {ua} {ub}");
                }
            }
            for a in floats {
                for b in floats {
                    assert_eq!(c.test(a, b), reference(c, a, b), "{c:?} {a} {b}");
                }
            }
        }
    }

    /// The remainder by multiplication equals the division's for every 16-bit dividend
    /// (signed and unsigned) and divisors across the range.
    #[test]
    fn remainder_by_multiplication_is_exact() {
        let mut ds: Vec<u16> = vec![2, 3, 5, 7, 10, 12, 60, 100, 256, 1000, 4096, 9999, 32767];
        ds.extend((0..40u32).map(|i| (i * 7919 % 32766 + 2) as u16));
        for d in ds {
            let m = mod_magic(d);
            let wide = [65536, -65536, 1 << 40, i64::MIN, i64::MAX];
            for a in (-65535i64..=65535).chain(wide) {
                assert_eq!(mod16(a, d, m), a % d as i64, "{a} MOD {d}");
            }
        }
    }

    /// Every fusable operation computes through the fast tests what the plain match
    /// computes, on integers (every kind), BOOLs and floats.
    #[test]
    fn fast_operations_agree_with_the_plain_match() {
        let mut ops = vec![Bin::And, Bin::Or, Bin::Xor, Bin::AndN, Bin::OrN];
        for k in IntKind::ALL {
            ops.extend([
                Bin::Add(k),
                Bin::Sub(k),
                Bin::Mul(k),
                Bin::Div(k),
                Bin::Mod(k),
            ]);
        }
        for c in CMPS {
            ops.extend([Bin::CmpI(c), Bin::CmpU(c), Bin::CmpF(c)]);
        }
        for s in [false, true] {
            ops.extend([
                Bin::FAdd(s),
                Bin::FSub(s),
                Bin::FMul(s),
                Bin::MinMaxI(s),
                Bin::MinMaxF(s),
            ]);
        }
        let mut vals: Vec<u64> = [0i64, 1, -1, 2, 7, -300, 40_000, i32::MIN as i64, i64::MAX]
            .iter()
            .map(|&v| v as u64)
            .collect();
        vals.extend([1.5f64, -0.25, f64::NAN].map(f64::to_bits));
        for b in ops {
            for &x in &vals {
                for &y in &vals {
                    if matches!(b, Bin::Div(_) | Bin::Mod(_)) && y == 0 {
                        continue;
                    }
                    assert_eq!(b.apply(x, y), b.apply_other(x, y), "{b:?} {x:#x} {y:#x}");
                }
            }
        }
    }
}
