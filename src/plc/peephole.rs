//! Peephole fusion of common instruction pairs, after code generation: an operand load or
//! constant followed by a binary operation becomes one instruction, as do a load or constant
//! followed by a store (block inputs, assignments). Fewer dispatches per scan, same effect.
//! A pair is never fused across a jump target.

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

fn fuse(a: Op, b: Op) -> Option<Op> {
    Some(match (a, b) {
        (Op::LoadL(s), Op::StoreL(d)) => Op::MovL(s, d),
        (Op::Push(c), Op::StoreL(d)) => Op::SetL(d, c),
        (Op::LoadL(o), b) => Op::BinL(bin(b)?, o),
        (Op::Push(c), b) => Op::BinC(bin(b)?, c),
        _ => return None,
    })
}

fn targets(op: Op) -> Option<u32> {
    match op {
        Op::Jmp(t) | Op::Jz(t) | Op::Jnz(t) | Op::CallInd(t) => Some(t),
        Op::Call { entry, .. } => Some(entry),
        _ => None,
    }
}

/// Fuses pairs in place; `entries` (entry points called from outside) are remapped.
pub fn optimize(ops: &mut Vec<Op>, spans: &mut Vec<Span>, entries: &mut [&mut u32]) {
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
        let fused = (i + 1 < n && !is_target[i + 1])
            .then(|| fuse(ops[i], ops[i + 1]))
            .flatten();
        match fused {
            Some(op) => {
                map[i + 1] = map[i];
                new_ops.push(op);
                // The second instruction is the one that can fault or be reported.
                new_spans.push(spans[i + 1]);
                i += 2;
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
        match op {
            Op::Jmp(t) | Op::Jz(t) | Op::Jnz(t) | Op::CallInd(t) => *t = map[*t as usize],
            Op::Call { entry, .. } => *entry = map[*entry as usize],
            _ => {}
        }
    }
    for e in entries.iter_mut() {
        **e = map[**e as usize];
    }
    *ops = new_ops;
    *spans = new_spans;
}
