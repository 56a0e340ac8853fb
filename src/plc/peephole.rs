//! Peephole fusion of common instruction sequences, after code generation. Two passes:
//! first an operand load or constant followed by a binary operation becomes one
//! instruction, as does a load or constant followed by a store (block inputs,
//! assignments); then the three-address forms `x op y -> d`, `x op k -> d`, the
//! compare-and-branch forms `IF x op y` / `IF x op k`, `x op y` / `x op k` pushed, a
//! store of a binary result, a pair of loads, and a jump to the next instruction (an IF without ELSE) disappear into one
//! instruction each. Fewer dispatches per scan, same effect. A sequence is never fused
//! across a jump target.

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

/// A rewrite: the replacement (`None` deletes) and how many instructions it consumes.
type Rewrite = (Option<Op>, usize);

/// First pass: operand fusion.
fn pairs(w: &[Op], _at: usize) -> Option<Rewrite> {
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
    Some((Some(fused), 2))
}

/// A constant of operation `b` in 32 bits, when it fits exactly: a signed 32-bit integer
/// for integer and bit operations, a single-precision float for float operations (every
/// REAL constant is one).
enum Compact {
    Int(i32),
    Float(f32),
}

fn compact(b: Bin, c: u64) -> Option<Compact> {
    if b.float() {
        let v = f64::from_bits(c) as f32;
        ((v as f64).to_bits() == c).then_some(Compact::Float(v))
    } else {
        let v = c as i64 as i32;
        (v as i64 as u64 == c).then_some(Compact::Int(v))
    }
}

/// Second pass: three-address and compare-and-branch forms.
fn triples(w: &[Op], at: usize) -> Option<Rewrite> {
    let a = *w.first()?;
    if let (Some(&b), Some(&c)) = (w.get(1), w.get(2)) {
        let fused = match (a, b, c) {
            (Op::LoadL(x), Op::BinL(b, y), Op::StoreL(d)) => Some(Op::BinLL(b, x, y, d)),
            (Op::LoadL(x), Op::BinL(b, y), Op::Jz(t)) => Some(Op::JfLL(b, x, y, t)),
            (Op::LoadL(x), Op::BinC(b, k), Op::StoreL(d)) => match compact(b, k) {
                Some(Compact::Int(k)) => Some(Op::BinLI(b, x, k, d)),
                Some(Compact::Float(k)) => Some(Op::BinLF(b, x, k, d)),
                None => None,
            },
            (Op::LoadL(x), Op::BinC(b, k), Op::Jz(t)) => match compact(b, k) {
                Some(Compact::Int(k)) => Some(Op::JfLI(b, x, k, t)),
                Some(Compact::Float(k)) => Some(Op::JfLF(b, x, k, t)),
                None => None,
            },
            _ => None,
        };
        if fused.is_some() {
            return Some((fused, 3));
        }
    }
    if let Op::Jmp(t) = a {
        if t as usize == at + 1 {
            return Some((None, 1));
        }
    }
    let fused = match (a, *w.get(1)?) {
        (Op::LoadL(x), Op::BinL(b, y)) => Op::PushLL(b, x, y),
        (Op::LoadL(x), Op::BinC(b, k)) => match compact(b, k)? {
            Compact::Int(k) => Op::PushLI(b, x, k),
            Compact::Float(k) => Op::PushLF(b, x, k),
        },
        (Op::BinC(b, k), Op::StoreL(d)) => match compact(b, k)? {
            Compact::Int(k) => Op::BinCSI(b, k, d),
            Compact::Float(k) => Op::BinCSF(b, k, d),
        },
        (Op::LoadL(x), Op::LoadL(y)) => Op::LoadLL(x, y),
        (Op::LoadL(x), Op::Jz(t)) => Op::JzL(x, t),
        (Op::BinL(b, y), Op::StoreL(d)) => Op::BinLS(b, y, d),
        (op, Op::StoreL(d)) => Op::BinS(bin(op)?, d),
        _ => return None,
    };
    Some((Some(fused), 2))
}

fn targets(op: Op) -> Option<u32> {
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

fn retarget(op: &mut Op, map: &[u32]) {
    match op {
        Op::Jmp(t)
        | Op::Jz(t)
        | Op::Jnz(t)
        | Op::CallInd(t)
        | Op::JzL(_, t)
        | Op::JfLL(_, _, _, t)
        | Op::JfLI(_, _, _, t)
        | Op::JfLF(_, _, _, t) => *t = map[*t as usize],
        Op::Call { entry, .. } => *entry = map[*entry as usize],
        _ => {}
    }
}

/// Fuses sequences in place; `entries` (entry points called from outside) are remapped.
pub fn optimize(ops: &mut Vec<Op>, spans: &mut Vec<Span>, entries: &mut [&mut u32]) {
    pass(ops, spans, entries, pairs);
    pass(ops, spans, entries, triples);
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
        if let Some(t) = targets(op) {
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
            Some((op, used)) => {
                let to = map[i];
                map[i + 1..i + used].fill(to);
                if let Some(op) = op {
                    new_ops.push(op);
                    // The last instruction is the one that can fault or be reported.
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
