//! The bytecode and its interpreter: a stack machine over 64-bit cells. Memory is one flat
//! array of cells laid out by the compiler; a POU's own variables are addressed relative to
//! its base (the instance or frame), globals absolutely. Every loop iteration is charged
//! against the scan's instruction budget, so a runaway loop ends in a fault at its line
//! instead of an overrun.

use super::op::*;
pub use super::op::{BadCode, Bin, Cmp, Code, FaultKind, MathFn, Op, Shift};
use super::stdfb::{ton, StdFb, TIMER_CELLS};
use super::types::IntKind;

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
                if let StdFb::Ton = $fb {
                    // The common timer without the jump on the block type (the conversion
                    // cannot fail: the range is the array's length).
                    if let Ok(c) = <&mut [u64; TIMER_CELLS]>::try_from(&mut mem[a..a + TIMER_CELLS])
                    {
                        ton(c, self.now);
                    }
                } else {
                    let n = $fb.members().len();
                    $fb.exec(&mut mem[a..a + n], self.now);
                }
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
                Op::PushModC(b, x, d, m, k) => {
                    let r = mod16(mem[base + x as usize] as i64, d, m);
                    push!(b.apply(r as u64, k as i64 as u64))
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
