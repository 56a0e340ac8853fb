//! The fourth peephole pass: two operations that the earlier passes left in two
//! instructions become one, because the cost of a scan is mostly the number of instructions
//! dispatched. Each rule takes a pair (or triple) that a typical statement compiles to:
//! `x := (a MOD 7 = 0) OR (p AND NOT q)`, `a := a + b * 3`,
//! `r := r * k1 + INT_TO_REAL(a) * k2`, `y := LIMIT(lo, x, hi)` and a standard block call
//! with its inputs (`t(IN := x, PT := T#5s)`, three in one). The fused instruction computes exactly what
//! the pair did: the same [`Bin::apply`] in the same order; none of them can fault.
//! Base-relative offsets are carried in 16 bits when the rule needs room, so an instruction
//! stays 16 bytes; a cell further from its base keeps the unfused pair.

use super::op::mod_magic;
use super::peephole::{with_const, Rewrite};
use super::vm::{Bin, Op};

fn short(o: u32) -> Option<u16> {
    u16::try_from(o).ok()
}

/// An integer or BOOL operation's constant carried in 32 bits (sign-extended), when it fits.
fn int_const(b: Bin, k: u64) -> Option<i32> {
    with_const(b, k, Some, |_| None).flatten()
}

/// One instruction for what two (or three) were.
fn fused(w: &[Op]) -> Option<(Op, usize)> {
    Some(match *w {
        // The last input store of a block call rides on the call; a constant input store
        // between them moves in front when it touches neither of the moved store's cells.
        [Op::MovL(src, d), Op::SetL(d2, _), Op::Std { fb, at, rel }, ..]
            if d2 != src && d2 != d =>
        {
            (
                Op::StdMov {
                    fb,
                    at,
                    rel,
                    src,
                    d,
                },
                3,
            )
        }
        [Op::MovL(src, d), Op::Std { fb, at, rel }, ..] => (
            Op::StdMov {
                fb,
                at,
                rel,
                src,
                d,
            },
            2,
        ),
        [Op::LoadIToF(x, s), Op::BinC(b1, k), Op::BinS(b2, d), ..] if b1.float() => {
            let k = with_const(b1, k, |_| None, Some)??;
            (Op::BinSIToF(b1, b2, s, short(x)?, short(d)?, k), 3)
        }
        [Op::PushLI(Bin::MinMaxI(true), x, lo), Op::BinCSI(Bin::MinMaxI(false), hi, d), ..] => {
            (Op::ClampI(short(x)?, short(d)?, lo, hi), 2)
        }
        [Op::PushLI(b1, x, k1), Op::BinC(b2, k2), ..] if !b2.float() => {
            (Op::PushLIC(b1, b2, short(x)?, k1, int_const(b2, k2)?), 2)
        }
        [Op::PushLI(b1, y, k), Op::BinLS(b2, x, d), ..] => {
            (Op::BinLIL(b1, b2, short(y)?, short(x)?, short(d)?, k), 2)
        }
        [Op::PushLL(b1, x, y), Op::BinS(b2, d), ..] => {
            (Op::BinSLL(b1, b2, short(x)?, short(y)?, short(d)?), 2)
        }
        _ => return None,
    })
}

/// A cell constant as `k << sh` with `k` in 32 bits, when it is one (every TIME constant
/// of whole milliseconds up to 137 s, of whole seconds up to 18 min).
fn shifted(c: u64) -> Option<(i32, u8)> {
    let sh = c.trailing_zeros().min(63);
    let k = i32::try_from((c as i64) >> sh).ok()?;
    (((k as i64) << sh) as u64 == c).then_some((k, sh as u8))
}

/// A standard block call with one variable and one constant input store, in either order
/// (`t(IN := x, PT := T#5s)`): one instruction when every offset fits 16 bits.
fn block_call(w: &[Op]) -> Option<Op> {
    let (src, d, d2, c, fb, at, rel) = match *w {
        [Op::MovL(src, d), Op::SetL(d2, c), Op::Std { fb, at, rel }, ..] => {
            (src, d, d2, c, fb, at, rel)
        }
        // The constant store first: it moves after the copy when it touches neither cell.
        [Op::SetL(d2, c), Op::MovL(src, d), Op::Std { fb, at, rel }, ..]
            if d2 != src && d2 != d =>
        {
            (src, d, d2, c, fb, at, rel)
        }
        _ => return None,
    };
    let (k, sh) = shifted(c)?;
    Some(Op::StdSetMov {
        fb,
        rel,
        sh,
        at: short(at)?,
        src: short(src)?,
        d: short(d)?,
        d2: short(d2)?,
        k,
    })
}

/// The rule of the sixth pass: a remainder by a constant of a cell of 16 bits or fewer,
/// then an operation with a constant (`a MOD 7 = 0`), computes the remainder by
/// multiplication ([`Op::PushModC`]): the divide is the slowest instruction of the scan.
pub(super) fn fuse_mod(w: &[Op], _at: usize) -> Option<Rewrite> {
    match *w {
        [Op::PushLIC(Bin::Mod(kind), b, x, d, k), ..] if kind.bits() <= 16 && d >= 2 => {
            let d = u16::try_from(d).ok().filter(|&d| d <= 32767)?;
            Some(([Some(Op::PushModC(b, x, d, mod_magic(d), k)), None], 1))
        }
        _ => None,
    }
}

/// The rule of the fifth pass, over the fourth's output: the first-order filter
/// `r := r * k1 + INT_TO_REAL(a) * k2` in one instruction when both products and the sum
/// round alike (all REAL or all LREAL).
pub(super) fn fuse_filter(w: &[Op], _at: usize) -> Option<Rewrite> {
    match *w {
        [Op::PushLF(Bin::FMul(s1), x, k1), Op::BinSIToF(Bin::FMul(s2), Bin::FAdd(s3), s, y, d, k2), ..]
            if s1 == s && s2 == s && s3 == s =>
        {
            Some(([Some(Op::FilterF(s, short(x)?, y, d, k1, k2)), None], 2))
        }
        _ => None,
    }
}

/// The rule of the fourth pass (see `peephole::pass`).
pub(super) fn fuse(w: &[Op], _at: usize) -> Option<Rewrite> {
    if let Some(op) = block_call(w) {
        return Some(([Some(op), None], 3));
    }
    let (op, used) = fused(w)?;
    // The moved constant input store goes first.
    if let (3, [_, Op::SetL(d2, c), Op::Std { .. }, ..]) = (used, w) {
        return Some(([Some(Op::SetL(*d2, *c)), Some(op)], 3));
    }
    Some(([Some(op), None], used))
}
