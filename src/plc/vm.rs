//! The bytecode and its interpreter: a stack machine over 64-bit cells. Memory is one flat
//! array of cells laid out by the compiler; a POU's own variables are addressed relative to
//! its base (the instance or frame), globals absolutely. Every loop iteration is charged
//! against the scan's instruction budget, so a runaway loop ends in a fault at its line
//! instead of an overrun.

use super::stdfb::StdFb;
use super::types::IntKind;

/// Comparison operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cmp {
    /// `=`
    Eq,
    /// `<>`
    Ne,
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
}

impl Cmp {
    #[inline(always)]
    fn test<T: PartialOrd>(self, a: T, b: T) -> bool {
        match self {
            Cmp::Eq => a == b,
            Cmp::Ne => a != b,
            Cmp::Lt => a < b,
            Cmp::Le => a <= b,
            Cmp::Gt => a > b,
            Cmp::Ge => a >= b,
        }
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

/// Binary operations that fuse with their right operand (see `peephole`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bin {
    /// Integer add.
    Add(IntKind),
    /// Integer subtract.
    Sub(IntKind),
    /// Integer multiply.
    Mul(IntKind),
    /// Signed comparison.
    CmpI(Cmp),
    /// Unsigned comparison.
    CmpU(Cmp),
    /// Float comparison.
    CmpF(Cmp),
    /// Bitwise AND.
    And,
    /// Bitwise OR.
    Or,
    /// Bitwise XOR.
    Xor,
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
    /// BOOL `a AND NOT b` (fused `NotB` + `And`).
    AndN,
    /// BOOL `a OR NOT b`.
    OrN,
}

/// Integer `a / b` (`div`) or `a MOD b` of kind `k`, `b` not zero: truncating, the
/// remainder with the sign of the dividend, 64-bit unsigned kinds unsigned, wrapped.
#[inline(always)]
fn div_rem(k: IntKind, a: u64, b: u64, div: bool) -> u64 {
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

impl Bin {
    /// Whether its operands are floats (REAL/LREAL cells).
    pub fn float(self) -> bool {
        matches!(
            self,
            Bin::CmpF(_) | Bin::FAdd(_) | Bin::FSub(_) | Bin::FMul(_) | Bin::MinMaxF(_)
        )
    }

    /// `a op b`, exactly as the unfused instruction computes it.
    #[inline(always)]
    pub fn apply(self, a: u64, b: u64) -> u64 {
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

/// The machine state of one scan, borrowed from the program's preallocated storage.
pub struct Vm<'a> {
    /// Code.
    pub ops: &'a Code,
    /// Memory cells.
    pub mem: &'a mut [u64],
    /// Operand stack.
    pub stack: &'a mut [u64],
    /// Return stack: (return pc, caller base).
    pub frames: &'a mut [(u32, u32)],
    /// Scan time stamp (ns).
    pub now: i64,
    /// Budget left this scan: each loop iteration costs its length in instructions (a
    /// cheap, deterministic bound; straight-line code and calls are bounded by the code).
    pub fuel: u64,
}

#[inline(always)]
fn f(v: u64) -> f64 {
    f64::from_bits(v)
}
#[inline(always)]
fn fb(v: f64, single: bool) -> u64 {
    if single {
        (v as f32 as f64).to_bits()
    } else {
        v.to_bits()
    }
}

/// A float function of `x` (cell bits). Out of line: rare, and each is a library call that
/// would otherwise add its register shuffling to the interpreter loop.
#[inline(never)]
fn math(m: MathFn, s: bool, x: u64) -> u64 {
    let x = f(x);
    let y = match m {
        MathFn::Abs => x.abs(),
        MathFn::Sqrt => x.sqrt(),
        MathFn::Ln => x.ln(),
        MathFn::Log => x.log10(),
        MathFn::Exp => x.exp(),
        MathFn::Sin => x.sin(),
        MathFn::Cos => x.cos(),
        MathFn::Tan => x.tan(),
        MathFn::Asin => x.asin(),
        MathFn::Acos => x.acos(),
        MathFn::Atan => x.atan(),
    };
    fb(y, s)
}

/// `x` shifted or rotated by `n` within the width of `k`. Out of line: rare and long.
#[inline(never)]
fn shift(s: Shift, k: IntKind, x: u64, n: u32) -> u64 {
    let w = k.bits();
    let x = x & (u64::MAX >> (64 - w));
    let r = match s {
        Shift::Shl if n >= w => 0,
        Shift::Shr if n >= w => 0,
        Shift::Shl => x << n,
        Shift::Shr => x >> n,
        Shift::Rol | Shift::Ror => {
            let n = if s == Shift::Rol {
                n % w
            } else {
                (w - n % w) % w
            };
            if n == 0 {
                x
            } else {
                (x << n) | (x >> (w - n))
            }
        }
    };
    k.wrap(r as i64) as u64
}

impl Vm<'_> {
    /// Runs the code at `entry` with base `base` until its `Ret`. On a fault returns the
    /// kind and the pc of the faulting instruction.
    pub fn run(&mut self, entry: u32, base: u32) -> Result<(), (FaultKind, u32)> {
        let ops: &[Op] = self.ops;
        let mut pc = entry as usize;
        let mut base = base as usize;
        let mut sp = 0usize;
        let mut depth = 0usize;
        let mut fuel = self.fuel;
        let st = &mut *self.stack;
        let mem = &mut *self.mem;
        macro_rules! pop {
            () => {{
                sp -= 1;
                st[sp]
            }};
        }
        macro_rules! push {
            ($v:expr) => {{
                let v = $v;
                st[sp] = v;
                sp += 1;
            }};
        }
        macro_rules! bin {
            (|$a:ident, $b:ident| $e:expr) => {{
                let $b = st[sp - 1];
                let $a = st[sp - 2];
                sp -= 1;
                st[sp - 1] = $e;
            }};
        }
        macro_rules! fault {
            ($k:expr) => {{
                self.fuel = fuel;
                return Err(($k, pc as u32));
            }};
        }
        // Loops are charged at their backward jump with the instructions of one iteration,
        // so straight-line code costs nothing extra and a fault names the loop's line.
        macro_rules! charge {
            ($t:expr) => {{
                let t = $t as usize;
                if t < pc {
                    let cost = (pc - t) as u64;
                    if fuel < cost {
                        pc -= 1;
                        fault!(FaultKind::BudgetExhausted);
                    }
                    fuel -= cost;
                }
            }};
        }
        macro_rules! call {
            ($entry:expr, $nb:expr) => {{
                if depth == self.frames.len() {
                    pc -= 1;
                    fault!(FaultKind::CallDepth);
                }
                self.frames[depth] = (pc as u32, base as u32);
                depth += 1;
                base = $nb;
                pc = $entry as usize;
            }};
        }
        macro_rules! std_call {
            ($fb:expr, $at:expr, $rel:expr) => {{
                let a = if $rel {
                    base + $at as usize
                } else {
                    $at as usize
                };
                let n = $fb.members().len();
                $fb.exec(&mut mem[a..a + n], self.now);
            }};
        }
        loop {
            // Matched in place: each arm loads only its own operands (a copy of the whole
            // instruction made every dispatch decode every field layout first).
            let op = &ops[pc];
            pc += 1;
            match *op {
                Op::Push(v) => push!(v),
                Op::BinL(b, o) => st[sp - 1] = b.apply(st[sp - 1], mem[base + o as usize]),
                Op::BinC(b, c) => st[sp - 1] = b.apply(st[sp - 1], c),
                Op::MovL(s, d) => mem[base + d as usize] = mem[base + s as usize],
                Op::SetL(d, c) => mem[base + d as usize] = c,
                Op::BinLL(b, x, y, d) => {
                    mem[base + d as usize] = b.apply(mem[base + x as usize], mem[base + y as usize])
                }
                Op::BinLI(b, x, k, d) => {
                    mem[base + d as usize] = b.apply(mem[base + x as usize], k as i64 as u64)
                }
                Op::BinLF(b, x, k, d) => {
                    mem[base + d as usize] = b.apply(mem[base + x as usize], (k as f64).to_bits())
                }
                Op::BinLS(b, y, d) => {
                    let a = pop!();
                    mem[base + d as usize] = b.apply(a, mem[base + y as usize]);
                }
                Op::BinS(b, d) => {
                    let v = b.apply(st[sp - 2], st[sp - 1]);
                    sp -= 2;
                    mem[base + d as usize] = v;
                }
                Op::PushLL(b, x, y) => {
                    push!(b.apply(mem[base + x as usize], mem[base + y as usize]))
                }
                Op::PushLI(b, x, k) => push!(b.apply(mem[base + x as usize], k as i64 as u64)),
                Op::PushLF(b, x, k) => {
                    push!(b.apply(mem[base + x as usize], (k as f64).to_bits()))
                }
                Op::BinCSI(b, k, d) => {
                    let a = pop!();
                    mem[base + d as usize] = b.apply(a, k as i64 as u64);
                }
                Op::BinCSF(b, k, d) => {
                    let a = pop!();
                    mem[base + d as usize] = b.apply(a, (k as f64).to_bits());
                }
                Op::LoadIToF(x, s) => push!(fb(mem[base + x as usize] as i64 as f64, s)),
                Op::LoadLL(x, y) => {
                    push!(mem[base + x as usize]);
                    push!(mem[base + y as usize]);
                }
                Op::JzL(x, t) => {
                    if mem[base + x as usize] == 0 {
                        charge!(t);
                        pc = t as usize;
                    }
                }
                Op::JfLL(b, x, y, t) => {
                    if b.apply(mem[base + x as usize], mem[base + y as usize]) == 0 {
                        charge!(t);
                        pc = t as usize;
                    }
                }
                Op::JfLI(b, x, k, t) => {
                    if b.apply(mem[base + x as usize], k as i64 as u64) == 0 {
                        charge!(t);
                        pc = t as usize;
                    }
                }
                Op::JfLF(b, x, k, t) => {
                    if b.apply(mem[base + x as usize], (k as f64).to_bits()) == 0 {
                        charge!(t);
                        pc = t as usize;
                    }
                }
                Op::LoadL(o) => push!(mem[base + o as usize]),
                Op::LoadG(a) => push!(mem[a as usize]),
                Op::StoreL(o) => mem[base + o as usize] = pop!(),
                Op::StoreG(a) => mem[a as usize] = pop!(),
                Op::AddrL(o) => push!((base + o as usize) as u64),
                Op::AddrG(a) => push!(a as u64),
                Op::LoadInd(k) => {
                    let a = st[sp - 1] as usize + k as usize;
                    st[sp - 1] = mem[a];
                }
                Op::StoreInd(k) => {
                    let v = pop!();
                    let a = pop!() as usize + k as usize;
                    mem[a] = v;
                }
                Op::Copy(n) => {
                    let src = pop!() as usize;
                    let dst = pop!() as usize;
                    mem.copy_within(src..src + n as usize, dst);
                }
                Op::Index { lo, len, stride } => {
                    let i = (pop!() as i64).wrapping_sub(lo as i64);
                    if i < 0 || i >= len as i64 {
                        pc -= 1;
                        fault!(FaultKind::IndexOutOfRange);
                    }
                    st[sp - 1] += i as u64 * stride as u64;
                }
                Op::Pop => sp -= 1,
                Op::Dup => push!(st[sp - 1]),
                Op::GetBit(n) => st[sp - 1] = (st[sp - 1] >> n) & 1,
                Op::SetBitL(o, n) => {
                    let v = pop!();
                    let c = &mut mem[base + o as usize];
                    *c = (*c & !(1 << n)) | ((v & 1) << n);
                }
                Op::SetBitG(a, n) => {
                    let v = pop!();
                    let c = &mut mem[a as usize];
                    *c = (*c & !(1 << n)) | ((v & 1) << n);
                }
                Op::SetBitInd(k, n) => {
                    let v = pop!();
                    let a = pop!() as usize + k as usize;
                    let c = &mut mem[a];
                    *c = (*c & !(1 << n)) | ((v & 1) << n);
                }
                Op::Add(k) => bin!(|a, b| k.wrap((a as i64).wrapping_add(b as i64)) as u64),
                Op::Sub(k) => bin!(|a, b| k.wrap((a as i64).wrapping_sub(b as i64)) as u64),
                Op::Mul(k) => bin!(|a, b| k.wrap((a as i64).wrapping_mul(b as i64)) as u64),
                Op::Div(k) | Op::Mod(k) => {
                    let (a, b) = (st[sp - 2], st[sp - 1]);
                    if b == 0 {
                        pc -= 1;
                        fault!(FaultKind::DivisionByZero);
                    }
                    sp -= 1;
                    st[sp - 1] = div_rem(k, a, b, matches!(op, Op::Div(_)));
                }
                Op::Neg(k) => st[sp - 1] = k.wrap((st[sp - 1] as i64).wrapping_neg()) as u64,
                Op::CmpI(c) => bin!(|a, b| c.test(a as i64, b as i64) as u64),
                Op::CmpU(c) => bin!(|a, b| c.test(a, b) as u64),
                Op::CmpF(c) => bin!(|a, b| c.test(f(a), f(b)) as u64),
                Op::And => bin!(|a, b| a & b),
                Op::Or => bin!(|a, b| a | b),
                Op::Xor => bin!(|a, b| a ^ b),
                Op::NotW(k) => st[sp - 1] = k.wrap(!(st[sp - 1] as i64)) as u64,
                Op::NotB => st[sp - 1] ^= 1,
                Op::FAdd(s) => bin!(|a, b| fb(f(a) + f(b), s)),
                Op::FSub(s) => bin!(|a, b| fb(f(a) - f(b), s)),
                Op::FMul(s) => bin!(|a, b| fb(f(a) * f(b), s)),
                Op::FDiv(s) => bin!(|a, b| fb(f(a) / f(b), s)),
                Op::FPow(s) => bin!(|a, b| fb(f(a).powf(f(b)), s)),
                Op::FNeg => st[sp - 1] = (-f(st[sp - 1])).to_bits(),
                Op::Math(m, s) => st[sp - 1] = math(m, s, st[sp - 1]),
                Op::Wrap(k) => st[sp - 1] = k.wrap(st[sp - 1] as i64) as u64,
                Op::IToF(s) => st[sp - 1] = fb(st[sp - 1] as i64 as f64, s),
                Op::UToF(s) => st[sp - 1] = fb(st[sp - 1] as f64, s),
                Op::FToI(k) => st[sp - 1] = k.wrap(f(st[sp - 1]).round() as i64) as u64,
                Op::FTrunc(k) => st[sp - 1] = k.wrap(f(st[sp - 1]).trunc() as i64) as u64,
                Op::FSingle => st[sp - 1] = fb(f(st[sp - 1]), true),
                Op::AbsI(k) => st[sp - 1] = k.wrap((st[sp - 1] as i64).wrapping_abs()) as u64,
                Op::MinMaxI(max) => {
                    bin!(|a, b| if ((a as i64) < (b as i64)) != max {
                        a
                    } else {
                        b
                    })
                }
                Op::MinMaxU(max) => bin!(|a, b| if (a < b) != max { a } else { b }),
                Op::MinMaxF(max) => bin!(|a, b| if (f(a) < f(b)) != max { a } else { b }),
                Op::Sel => {
                    let in1 = pop!();
                    let in0 = pop!();
                    st[sp - 1] = if st[sp - 1] != 0 { in1 } else { in0 };
                }
                Op::Mux(n) => {
                    let k = st[sp - 1 - n as usize] as i64;
                    if k < 0 || k >= n as i64 {
                        pc -= 1;
                        fault!(FaultKind::SelectorOutOfRange);
                    }
                    let v = st[sp - n as usize + k as usize];
                    sp -= n as usize;
                    st[sp - 1] = v;
                }
                Op::Shift(s, k) => {
                    let n = pop!() as u32;
                    st[sp - 1] = shift(s, k, st[sp - 1], n);
                }
                Op::Jmp(t) => {
                    charge!(t);
                    pc = t as usize;
                }
                Op::Jz(t) => {
                    if pop!() == 0 {
                        charge!(t);
                        pc = t as usize;
                    }
                }
                Op::Jnz(t) => {
                    if pop!() != 0 {
                        pc = t as usize;
                    }
                }
                Op::Call { entry, at, rel } => {
                    let nb = if rel { base + at as usize } else { at as usize };
                    call!(entry, nb);
                }
                Op::CallInd(entry) => {
                    let nb = pop!() as usize;
                    call!(entry, nb);
                }
                Op::Std { fb, at, rel } => std_call!(fb, at, rel),
                Op::StdMov {
                    fb,
                    at,
                    rel,
                    src,
                    d,
                } => {
                    mem[base + d as usize] = mem[base + src as usize];
                    std_call!(fb, at, rel);
                }
                Op::StdSetMov {
                    fb,
                    rel,
                    sh,
                    at,
                    src,
                    d,
                    d2,
                    k,
                } => {
                    mem[base + d as usize] = mem[base + src as usize];
                    mem[base + d2 as usize] = ((k as i64) << sh) as u64;
                    std_call!(fb, at, rel);
                }
                Op::StdInd(fb) => {
                    let a = pop!() as usize;
                    let n = fb.members().len();
                    fb.exec(&mut mem[a..a + n], self.now);
                }
                Op::PushLIC(b1, b2, x, k1, k2) => {
                    let v = b1.apply(mem[base + x as usize], k1 as i64 as u64);
                    push!(b2.apply(v, k2 as i64 as u64))
                }
                Op::BinSLL(b1, b2, x, y, d) => {
                    let a = pop!();
                    let v = b1.apply(mem[base + x as usize], mem[base + y as usize]);
                    mem[base + d as usize] = b2.apply(a, v);
                }
                Op::BinLIL(b1, b2, y, x, d, k) => {
                    let v = b1.apply(mem[base + y as usize], k as i64 as u64);
                    mem[base + d as usize] = b2.apply(v, mem[base + x as usize]);
                }
                Op::BinSIToF(b1, b2, s, x, d, k) => {
                    let a = pop!();
                    let i = fb(mem[base + x as usize] as i64 as f64, s);
                    let v = b1.apply(i, (k as f64).to_bits());
                    mem[base + d as usize] = b2.apply(a, v);
                }
                Op::FilterF(s, x, y, d, k1, k2) => {
                    let v = Bin::FMul(s).apply(mem[base + x as usize], (k1 as f64).to_bits());
                    let i = fb(mem[base + y as usize] as i64 as f64, s);
                    let w = Bin::FMul(s).apply(i, (k2 as f64).to_bits());
                    mem[base + d as usize] = Bin::FAdd(s).apply(v, w);
                }
                Op::ClampI(x, d, lo, hi) => {
                    let v = Bin::MinMaxI(true).apply(mem[base + x as usize], lo as i64 as u64);
                    mem[base + d as usize] = Bin::MinMaxI(false).apply(v, hi as i64 as u64);
                }
                Op::Ret => {
                    if depth == 0 {
                        self.fuel = fuel;
                        return Ok(());
                    }
                    depth -= 1;
                    let (rpc, rb) = self.frames[depth];
                    pc = rpc as usize;
                    base = rb as usize;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Code::new` refuses code that could leave itself:
    /// each way out is refused.
    #[test]
    fn code_that_could_run_off_its_end_is_refused() {
        assert_eq!(Code::new(vec![]).unwrap_err(), BadCode::OpenEnd);
        assert_eq!(
            Code::new(vec![Op::Ret, Op::Push(1)]).unwrap_err(),
            BadCode::OpenEnd
        );
        assert_eq!(
            Code::new(vec![Op::Ret, Op::Jz(0)]).unwrap_err(),
            BadCode::OpenEnd,
            "a conditional jump falls through"
        );
        assert_eq!(
            Code::new(vec![
                Op::Ret,
                Op::Call {
                    entry: 0,
                    at: 0,
                    rel: true
                }
            ])
            .unwrap_err(),
            BadCode::OpenEnd,
            "a call as the last instruction returns past the end"
        );
        for bad in [
            Op::Jmp(3),
            Op::Jz(3),
            Op::Jnz(7),
            Op::JzL(0, 3),
            Op::Call {
                entry: 3,
                at: 0,
                rel: false,
            },
            Op::CallInd(9),
        ] {
            assert!(
                matches!(
                    Code::new(vec![Op::Push(0), bad, Op::Ret]),
                    Err(BadCode::Target { at: 1, len: 3, .. })
                ),
                "{bad:?}"
            );
        }
        let ok = Code::new(vec![Op::Push(1), Op::Jz(2), Op::Jmp(0)]).unwrap();
        assert_eq!(ok.len(), 3);
    }

    /// Code that passes runs as before: a loop charged against the budget faults at its
    /// backward jump, a call returns after itself.
    #[test]
    fn accepted_code_runs() {
        let ops = vec![
            Op::Call {
                entry: 2,
                at: 0,
                rel: false,
            },
            Op::Ret,
            Op::SetL(0, 5),
            Op::Ret,
        ];
        let (mut mem, mut st, mut fr) = ([0u64; 1], [0u64; 4], [(0u32, 0u32); 2]);
        let mut run = |ops: Vec<Op>, mem: &mut [u64]| {
            let code = Code::new(ops).unwrap();
            Vm {
                ops: &code,
                mem,
                stack: &mut st,
                frames: &mut fr,
                now: 0,
                fuel: 10,
            }
            .run(0, 0)
        };
        assert_eq!(run(ops, &mut mem), Ok(()));
        assert_eq!(mem[0], 5);
        assert_eq!(
            run(vec![Op::Jmp(0)], &mut mem),
            Err((FaultKind::BudgetExhausted, 0))
        );
    }
}
