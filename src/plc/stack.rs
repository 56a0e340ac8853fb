//! Operand stack depth of compiled code, computed once at load so the scan's stack is
//! preallocated: a walk over every path from each entry point.

use super::vm::Op;

/// (values popped, values pushed) by one instruction; calls count only their own operands.
fn effect(op: Op) -> (usize, usize) {
    use Op::*;
    match op {
        Push(_) | LoadL(_) | LoadG(_) | AddrL(_) | AddrG(_) => (0, 1),
        Dup => (1, 2),
        StoreL(_) | StoreG(_) | Pop | SetBitL(..) | SetBitG(..) | Jz(_) | Jnz(_) => (1, 0),
        CallInd(_) | StdInd(_) => (1, 0),
        LoadInd(_) | GetBit(_) | Neg(_) | NotW(_) | NotB | FNeg | Math(..) | Wrap(_) | IToF(_)
        | UToF(_) | FToI(_) | FTrunc(_) | FSingle | AbsI(_) => (1, 1),
        StoreInd(_) | SetBitInd(..) | Copy(_) => (2, 0),
        Index { .. } => (2, 1),
        Add(_) | Sub(_) | Mul(_) | Div(_) | Mod(_) | CmpI(_) | CmpU(_) | CmpF(_) | And | Or
        | Xor | FAdd(_) | FSub(_) | FMul(_) | FDiv(_) | FPow(_) | MinMaxI(_) | MinMaxU(_)
        | MinMaxF(_) | Shift(..) => (2, 1),
        Sel => (3, 1),
        Mux(n) => (n as usize + 1, 1),
        Call { .. } | Std { .. } | Jmp(_) | Ret | MovL(..) | SetL(..) => (0, 0),
        BinL(..) | BinC(..) => (1, 1),
        BinLL(..) | BinLI(..) | BinLF(..) | JzL(..) | JfLL(..) | JfLI(..) | JfLF(..) => (0, 0),
        BinLS(..) | BinCSI(..) | BinCSF(..) => (1, 0),
        PushLL(..) | PushLI(..) | PushLF(..) | LoadIToF(..) => (0, 1),
        BinS(..) => (2, 0),
        LoadLL(..) => (0, 2),
        PushLIC(..) | PushModC(..) => (0, 1),
        BinSLL(..) | BinSIToF(..) => (1, 0),
        BinLIL(..) | ClampI(..) | FilterF(..) | StdMov { .. } | StdSetMov { .. } => (0, 0),
    }
}

/// The deepest operand stack any single body reaches, from the given entry points.
pub fn max_depth(ops: &[Op], entries: impl Iterator<Item = u32>) -> usize {
    let mut depth: Vec<Option<usize>> = vec![None; ops.len()];
    let mut max = 1;
    let mut work: Vec<(usize, usize)> = entries.map(|e| (e as usize, 0)).collect();
    while let Some((pc, d)) = work.pop() {
        if pc >= ops.len() || depth[pc].is_some() {
            continue;
        }
        depth[pc] = Some(d);
        let (pop, push) = effect(ops[pc]);
        let after = d.saturating_sub(pop) + push;
        max = max.max(after).max(d);
        match ops[pc] {
            Op::Ret => {}
            Op::Jmp(t) => work.push((t as usize, after)),
            Op::Jz(t)
            | Op::Jnz(t)
            | Op::JzL(_, t)
            | Op::JfLL(_, _, _, t)
            | Op::JfLI(_, _, _, t)
            | Op::JfLF(_, _, _, t) => {
                work.push((t as usize, after));
                work.push((pc + 1, after));
            }
            _ => work.push((pc + 1, after)),
        }
    }
    max
}
