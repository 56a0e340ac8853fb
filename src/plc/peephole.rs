//! Peephole fusion of common instruction sequences, after code generation. Three passes:
//! first an operand load or constant followed by a binary operation becomes one
//! instruction, as does a load or constant followed by a store (block inputs,
//! assignments), a negated BOOL operand of AND/OR (`a AND NOT x`), a load converted to
//! float (`INT_TO_REAL(x)`), and a constant left operand of a commutative operation is
//! moved to the right; then the three-address forms `x op y -> d`, `x op k -> d`, the
//! compare-and-branch forms `IF x op y` / `IF x op k`, `x op y` / `x op k` pushed, a
//! store of a binary result, a pair of loads, and a jump to the next instruction (an IF
//! without ELSE) disappear into one instruction each; then `x op (y op2 k)` with a
//! commutative `op` is reordered so both operations fuse; last two operations that are
//! still apart become one (`superop`), and a remainder of a 16-bit cell by
//! a constant is computed by multiplication instead of a divide. Fewer dispatches per scan,
//! same effect. A sequence is never fused across a jump target.

use super::diag::Span;
use super::vm::{Bin, Op};

/// The fusable binary operation of an instruction.
fn bin(op: Op) -> Option<Bin> {
    Some(match op {
        Op::Add(k) => Bin::Add(k),
        Op::Sub(k) => Bin::Sub(k),
        Op::Mul(k) => Bin::Mul(k),
        Op::CmpI(c) => Bin::CmpI(c),
        Op::CmpU(c) => Bin::CmpU(c),
        Op::CmpF(c) => Bin::CmpF(c),
        Op::And => Bin::And,
        Op::Or => Bin::Or,
        Op::Xor => Bin::Xor,
        Op::FAdd(s) => Bin::FAdd(s),
        Op::FSub(s) => Bin::FSub(s),
        Op::FMul(s) => Bin::FMul(s),
        Op::MinMaxI(m) => Bin::MinMaxI(m),
        Op::MinMaxF(m) => Bin::MinMaxF(m),
        _ => return None,
    })
}

/// A rewrite: the replacement (none, one or two instructions) and how many instructions it
/// consumes.
pub(super) type Rewrite = ([Option<Op>; 2], usize);

/// `b` with its operands swapped, when `a b c = c b' a` for every pair of integer or BOOL
/// cells (floats are left alone: which NaN a float operation returns depends on the order).
fn swapped(b: Bin) -> Option<Bin> {
    use super::vm::Cmp;
    let flip = |c: Cmp| match c {
        Cmp::Lt => Cmp::Gt,
        Cmp::Gt => Cmp::Lt,
        Cmp::Le => Cmp::Ge,
        Cmp::Ge => Cmp::Le,
        c => c,
    };
    Some(match b {
        Bin::Add(_) | Bin::Mul(_) | Bin::And | Bin::Or | Bin::Xor | Bin::MinMaxI(_) => b,
        Bin::CmpI(c) => Bin::CmpI(flip(c)),
        Bin::CmpU(c) => Bin::CmpU(flip(c)),
        _ => return None,
    })
}

/// First pass: operand fusion.
fn pairs(w: &[Op], _at: usize) -> Option<Rewrite> {
    if let [Op::LoadL(x), Op::NotB, op, ..] = *w {
        // `a AND NOT x`, `a OR NOT x` (BOOL): the negation rides on the operand.
        let b = match op {
            Op::And => Some(Bin::AndN),
            Op::Or => Some(Bin::OrN),
            _ => None,
        };
        if let Some(b) = b {
            return Some(([Some(Op::BinL(b, x)), None], 3));
        }
    }
    if let [Op::Push(c), Op::LoadL(y), op, ..] = *w {
        // `k op y` becomes `y op' k`, which fuses further (`LIMIT(0, x, 9)`, `IF 5 < x`).
        if let Some(b) = bin(op).and_then(swapped) {
            return Some(([Some(Op::LoadL(y)), Some(Op::BinC(b, c))], 3));
        }
    }
    if let [Op::LoadL(x), Op::IToF(s), ..] = *w {
        return Some(([Some(Op::LoadIToF(x, s)), None], 2));
    }
    let fused = match (*w.first()?, *w.get(1)?) {
        (Op::LoadL(s), Op::StoreL(d)) => Op::MovL(s, d),
        (Op::Push(c), Op::StoreL(d)) => Op::SetL(d, c),
        (Op::LoadL(o), b) => Op::BinL(bin(b)?, o),
        // A constant divisor that is not zero cannot fault: the division fuses too.
        (Op::Push(c), Op::Div(k)) if c != 0 => Op::BinC(Bin::Div(k), c),
        (Op::Push(c), Op::Mod(k)) if c != 0 => Op::BinC(Bin::Mod(k), c),
        (Op::Push(c), b) => Op::BinC(bin(b)?, c),
        _ => return None,
    };
    Some(([Some(fused), None], 2))
}

/// The fused form of operation `b` with constant `c` carried in 32 bits, when it fits
/// exactly: `int` with a signed 32-bit integer for integer and bit operations, `float` with
/// a single-precision float for float operations (every REAL constant is one).
pub(super) fn with_const<T>(
    b: Bin,
    c: u64,
    int: impl FnOnce(i32) -> T,
    float: impl FnOnce(f32) -> T,
) -> Option<T> {
    if b.float() {
        let v = f64::from_bits(c) as f32;
        ((v as f64).to_bits() == c).then(|| float(v))
    } else {
        let v = c as i64 as i32;
        (v as i64 as u64 == c).then(|| int(v))
    }
}

/// Second pass: three-address and compare-and-branch forms.
fn triples(w: &[Op], at: usize) -> Option<Rewrite> {
    let a = *w.first()?;
    if let (Some(&b), Some(&c)) = (w.get(1), w.get(2)) {
        let fused = match (a, b, c) {
            (Op::LoadL(x), Op::BinL(b, y), Op::StoreL(d)) => Some(Op::BinLL(b, x, y, d)),
            (Op::LoadL(x), Op::BinL(b, y), Op::Jz(t)) => Some(Op::JfLL(b, x, y, t)),
            (Op::LoadL(x), Op::BinC(b, k), Op::StoreL(d)) => {
                with_const(b, k, |k| Op::BinLI(b, x, k, d), |k| Op::BinLF(b, x, k, d))
            }
            (Op::LoadL(x), Op::BinC(b, k), Op::Jz(t)) => {
                with_const(b, k, |k| Op::JfLI(b, x, k, t), |k| Op::JfLF(b, x, k, t))
            }
            _ => None,
        };
        if fused.is_some() {
            return Some(([fused, None], 3));
        }
    }
    if let Op::Jmp(t) = a {
        if t as usize == at + 1 {
            return Some(([None, None], 1));
        }
    }
    let fused = match (a, *w.get(1)?) {
        (Op::LoadL(x), Op::BinL(b, y)) => Op::PushLL(b, x, y),
        (Op::LoadL(x), Op::BinC(b, k)) => {
            with_const(b, k, |k| Op::PushLI(b, x, k), |k| Op::PushLF(b, x, k))?
        }
        (Op::BinC(b, k), Op::StoreL(d)) => {
            with_const(b, k, |k| Op::BinCSI(b, k, d), |k| Op::BinCSF(b, k, d))?
        }
        (Op::LoadL(x), Op::LoadL(y)) => Op::LoadLL(x, y),
        (Op::LoadL(x), Op::Jz(t)) => Op::JzL(x, t),
        (Op::BinL(b, y), Op::StoreL(d)) => Op::BinLS(b, y, d),
        (op, Op::StoreL(d)) => Op::BinS(bin(op)?, d),
        _ => return None,
    };
    Some(([Some(fused), None], 2))
}

/// Third pass: `x op (y op2 k)` with a commutative `op` (`a := a + b * 3`) computes
/// `y op2 k` first and takes `x` as the right operand, so both halves fuse.
fn commuted(w: &[Op], _at: usize) -> Option<Rewrite> {
    let [Op::LoadLL(x, y), Op::BinC(b2, k), last, ..] = *w else {
        return None;
    };
    let push = with_const(b2, k, |k| Op::PushLI(b2, y, k), |k| Op::PushLF(b2, y, k))?;
    let outer = match last {
        Op::BinS(b, d) if swapped(b) == Some(b) => Op::BinLS(b, x, d),
        op => match bin(op) {
            Some(b) if swapped(b) == Some(b) => Op::BinL(b, x),
            _ => return None,
        },
    };
    Some(([Some(push), Some(outer)], 3))
}

/// The jump target or call entry an instruction carries, for reading or rewriting: the
/// one list of branching instructions the pass keeps.
fn target_mut(op: &mut Op) -> Option<&mut u32> {
    match op {
        Op::Jmp(t)
        | Op::Jz(t)
        | Op::Jnz(t)
        | Op::CallInd(t)
        | Op::JzL(_, t)
        | Op::JfLL(_, _, _, t)
        | Op::JfLI(_, _, _, t)
        | Op::JfLF(_, _, _, t) => Some(t),
        Op::Call { entry, .. } => Some(entry),
        _ => None,
    }
}

/// The jump target or call entry of an instruction, if it has one.
pub(crate) fn target(mut op: Op) -> Option<u32> {
    target_mut(&mut op).copied()
}

fn retarget(op: &mut Op, map: &[u32]) {
    if let Some(t) = target_mut(op) {
        *t = map[*t as usize];
    }
}

/// Fuses sequences in place; `entries` (entry points called from outside) are remapped.
pub fn optimize(ops: &mut Vec<Op>, spans: &mut Vec<Span>, entries: &mut [&mut u32]) {
    pass(ops, spans, entries, pairs);
    pass(ops, spans, entries, triples);
    pass(ops, spans, entries, commuted);
    pass(ops, spans, entries, super::superop::fuse);
    pass(ops, spans, entries, super::superop::fuse_filter);
    pass(ops, spans, entries, super::superop::fuse_mod);
}

/// One rewriting pass with `rule`, which sees the code from an instruction on (never
/// past the next jump target) and that instruction's index.
fn pass(
    ops: &mut Vec<Op>,
    spans: &mut Vec<Span>,
    entries: &mut [&mut u32],
    rule: fn(&[Op], usize) -> Option<Rewrite>,
) {
    let n = ops.len();
    let mut is_target = vec![false; n + 1];
    for &op in ops.iter() {
        if let Some(t) = target(op) {
            is_target[t as usize] = true;
        }
    }
    for e in entries.iter() {
        is_target[**e as usize] = true;
    }
    let mut new_ops = Vec::with_capacity(n);
    let mut new_spans = Vec::with_capacity(n);
    let mut map = vec![0u32; n + 1];
    let mut i = 0;
    while i < n {
        map[i] = new_ops.len() as u32;
        // The window ends before the next jump target: nothing jumps into a fused body.
        let end = (i + 1..n.min(i + 3))
            .find(|&j| is_target[j])
            .unwrap_or(n.min(i + 3));
        match rule(&ops[i..end], i) {
            Some((out, used)) => {
                let to = map[i];
                map[i + 1..i + used].fill(to);
                for op in out.into_iter().flatten() {
                    new_ops.push(op);
                    // The last instruction is the one that can fault or be reported (no
                    // rule emits two instructions of which the first can fault).
                    new_spans.push(spans[i + used - 1]);
                }
                i += used;
            }
            None => {
                new_ops.push(ops[i]);
                new_spans.push(spans[i]);
                i += 1;
            }
        }
    }
    map[n] = new_ops.len() as u32;
    for op in new_ops.iter_mut() {
        retarget(op, &map);
    }
    for e in entries.iter_mut() {
        **e = map[**e as usize];
    }
    *ops = new_ops;
    *spans = new_spans;
}
