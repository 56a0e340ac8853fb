//! The standard functions (IEC 61131-3 ed.3 §6.6.2.5): type conversions `X_TO_Y` (and
//! CODESYS's `TO_Y`), TRUNC, numerical (ABS, SQRT, LN, LOG, EXP, trigonometry, EXPT),
//! selection (MIN, MAX, LIMIT, SEL, MUX) and bit shifts (SHL, SHR, ROL, ROR), compiled inline.
//!
//! Conversion semantics where the standard leaves them open follow CODESYS/TwinCAT:
//! REAL to integer rounds half away from zero, narrowing integers wrap (keep the low bits),
//! TIME converts to and from integers as milliseconds.

use super::compile::{lit_class, Compiler, LitClass};
use super::diag::Span;
use super::expr::{Arg, BinOp, Expr};
use super::types::{common, elementary, implicit, IntKind, Ty};
use super::vm::{Cmp, MathFn, Op, Shift};

const NAMES: &[&str] = &[
    "ABS", "SQRT", "LN", "LOG", "EXP", "SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN", "EXPT", "MIN",
    "MAX", "LIMIT", "SEL", "MUX", "SHL", "SHR", "ROL", "ROR", "TRUNC",
];

/// A conversion function's source (if named), target, and whether it truncates.
fn conversion(key: &str) -> Option<(Option<Ty>, Ty, bool)> {
    if key == "TRUNC" {
        return Some((None, Ty::Int(IntKind::DInt), true));
    }
    if let Some(t) = key.strip_prefix("TRUNC_") {
        return Some((None, elementary(t).filter(|t| t.int().is_some())?, true));
    }
    if let Some(t) = key.strip_prefix("TO_") {
        return Some((None, elementary(t)?, false));
    }
    let (a, b) = key.split_once("_TO_")?;
    let from = elementary(a)?;
    Some((Some(from), elementary(b)?, false))
}

/// Whether `key` names a standard function.
pub fn is_builtin(key: &str) -> bool {
    NAMES.contains(&key) || conversion(key).is_some()
}

/// The common type of several operands, untyped literals following the others.
fn common_of(c: &mut Compiler, es: &[&Expr], hint: Option<Ty>) -> Option<Ty> {
    let mut t: Option<Ty> = None;
    let mut lits = Vec::new();
    for e in es {
        match lit_class(e) {
            Some(l) => lits.push(l),
            None => {
                let pt = c.peek(e);
                if pt == Ty::Void {
                    return Some(Ty::Void);
                }
                t = Some(match t {
                    None => pt,
                    Some(x) => common(x, pt)?,
                });
            }
        }
    }
    let real_lit = lits.iter().any(|l| matches!(l, LitClass::Real));
    match t {
        Some(t) if real_lit && !t.float() => common(t, Ty::LReal),
        Some(t) => Some(t),
        None => match hint {
            Some(h) if h.float() || (h.int().is_some() && !real_lit) => Some(h),
            _ if real_lit => Some(Ty::LReal),
            _ => Some(Ty::Int(IntKind::DInt)),
        },
    }
}

/// Compiles a call of standard function `key`; `None` if it is not one.
pub fn call(c: &mut Compiler, key: &str, args: &[Arg], hint: Option<Ty>, span: Span) -> Option<Ty> {
    if !is_builtin(key) {
        return None;
    }
    if let Some(a) = args.iter().find(|a| a.output) {
        c.err(a.value.span, format!("{key} has no outputs"));
    }
    let es: Vec<&Expr> = args.iter().map(|a| &a.value).collect();
    let arity = |c: &mut Compiler, ok: bool, what: &str| {
        if !ok {
            c.err(span, format!("{key} takes {what}"));
        }
        ok
    };
    let dummy = |c: &mut Compiler| {
        c.emit(Op::Push(0), span);
        Ty::Void
    };
    if let Some((from, to, trunc)) = conversion(key) {
        if !arity(c, es.len() == 1, "one argument") {
            return Some(dummy(c));
        }
        let t = c.expr(es[0], from.or(Some(to)));
        let from = match from {
            Some(f) => {
                c.coerce(t, f, es[0].span);
                f
            }
            None => t,
        };
        if trunc && !from.float() && from != Ty::Void {
            c.err(es[0].span, format!("{key} needs a REAL or LREAL"));
        }
        convert(c, from, to, trunc, span);
        return Some(to);
    }
    let ty = match key {
        "ABS" => {
            if !arity(c, es.len() == 1, "one argument") {
                return Some(dummy(c));
            }
            let t = c.expr(es[0], hint);
            match t {
                Ty::Int(k) if !k.bitstring() => c.emit(Op::AbsI(k), span),
                t if t.float() => c.emit(Op::Math(MathFn::Abs, t == Ty::Real), span),
                Ty::Void => 0,
                _ => {
                    let n = c.ty_name(t);
                    c.err(span, format!("ABS needs a number, found {n}"));
                    0
                }
            };
            t
        }
        "SQRT" | "LN" | "LOG" | "EXP" | "SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "ATAN" => {
            if !arity(c, es.len() == 1, "one argument") {
                return Some(dummy(c));
            }
            let t = match lit_class(es[0]) {
                Some(_) => hint.filter(|h| h.float()).unwrap_or(Ty::LReal),
                None => {
                    let t = c.peek(es[0]);
                    if t.float() || t == Ty::Void {
                        t
                    } else if implicit(t, Ty::Real) {
                        Ty::Real
                    } else {
                        Ty::LReal
                    }
                }
            };
            let at = c.expr(es[0], Some(t));
            c.coerce(at, t, es[0].span);
            let f = match key {
                "SQRT" => MathFn::Sqrt,
                "LN" => MathFn::Ln,
                "LOG" => MathFn::Log,
                "EXP" => MathFn::Exp,
                "SIN" => MathFn::Sin,
                "COS" => MathFn::Cos,
                "TAN" => MathFn::Tan,
                "ASIN" => MathFn::Asin,
                "ACOS" => MathFn::Acos,
                _ => MathFn::Atan,
            };
            c.emit(Op::Math(f, t == Ty::Real), span);
            t
        }
        "EXPT" => {
            if !arity(c, es.len() == 2, "two arguments") {
                return Some(dummy(c));
            }
            c.binary(BinOp::Pow, es[0], es[1], hint, span)
        }
        "MIN" | "MAX" | "LIMIT" => {
            let n = es.len();
            let ok = if key == "LIMIT" { n == 3 } else { n >= 2 };
            if !arity(
                c,
                ok,
                if key == "LIMIT" {
                    "three arguments (MN, IN, MX)"
                } else {
                    "two or more arguments"
                },
            ) {
                return Some(dummy(c));
            }
            let Some(t) = common_of(c, &es, hint) else {
                c.err(span, format!("arguments of {key} have no common type"));
                return Some(dummy(c));
            };
            let mm = |max| match t {
                t if t.float() => Op::MinMaxF(max),
                Ty::Int(k) if k.bits() == 64 && !k.signed() => Op::MinMaxU(max),
                _ => Op::MinMaxI(max),
            };
            for (i, e) in es.iter().enumerate() {
                let at = c.expr(e, Some(t));
                c.coerce(at, t, e.span);
                if i > 0 {
                    // LIMIT(MN, IN, MX) = MIN(MAX(IN, MN), MX).
                    let max = key == "MAX" || (key == "LIMIT" && i == 1);
                    c.emit(mm(max), span);
                }
            }
            if !t.scalar() || t == Ty::Bool {
                let n = c.ty_name(t);
                c.err(span, format!("{key} does not apply to {n}"));
            }
            t
        }
        "SEL" => {
            if !arity(c, es.len() == 3, "three arguments (G, IN0, IN1)") {
                return Some(dummy(c));
            }
            let g = c.expr(es[0], Some(Ty::Bool));
            c.coerce(g, Ty::Bool, es[0].span);
            let t = common_of(c, &es[1..], hint).unwrap_or(Ty::Void);
            for e in &es[1..] {
                let at = c.expr(e, Some(t));
                c.coerce(at, t, e.span);
            }
            c.emit(Op::Sel, span);
            t
        }
        "MUX" => {
            if !arity(c, es.len() >= 2, "a selector and one or more inputs") {
                return Some(dummy(c));
            }
            let k = c.expr(es[0], Some(Ty::Int(IntKind::DInt)));
            if k.int().is_none() && k != Ty::Void {
                c.err(es[0].span, "MUX selector must be an integer");
            }
            let t = common_of(c, &es[1..], hint).unwrap_or(Ty::Void);
            for e in &es[1..] {
                let at = c.expr(e, Some(t));
                c.coerce(at, t, e.span);
            }
            c.emit(Op::Mux(es.len() as u32 - 1), span);
            t
        }
        _ => {
            // SHL, SHR, ROL, ROR
            if !arity(c, es.len() == 2, "two arguments (IN, N)") {
                return Some(dummy(c));
            }
            let t = c.expr(es[0], hint);
            let n = c.expr(es[1], Some(Ty::Int(IntKind::DInt)));
            if n.int().is_none() && n != Ty::Void {
                c.err(es[1].span, format!("{key} count must be an integer"));
            }
            let s = match key {
                "SHL" => Shift::Shl,
                "SHR" => Shift::Shr,
                "ROL" => Shift::Rol,
                _ => Shift::Ror,
            };
            match t {
                Ty::Int(k) => {
                    c.emit(Op::Shift(s, k), span);
                }
                Ty::Void => {}
                _ => {
                    let tn = c.ty_name(t);
                    c.err(span, format!("{key} needs a bit string, found {tn}"));
                }
            }
            t
        }
    };
    Some(ty)
}

/// Emits an explicit conversion.
pub(crate) fn convert(c: &mut Compiler, from: Ty, to: Ty, trunc: bool, span: Span) {
    let ms = 1_000_000u64;
    let unsigned64 = |t: Ty| t.int().is_some_and(|k| k.bits() == 64 && !k.signed());
    match (from, to) {
        (a, b) if a == b => {}
        (Ty::Void, _) | (_, Ty::Void) => {}
        // 0 and 1 fit every integer type.
        (Ty::Bool, Ty::Int(_)) => {}
        (Ty::Int(_) | Ty::Enum(_), Ty::Int(k)) => {
            c.emit(Op::Wrap(k), span);
        }
        (Ty::Int(_), Ty::Bool) => {
            c.emit(Op::Push(0), span);
            c.emit(Op::CmpI(Cmp::Ne), span);
        }
        (f, t) if (f.int().is_some() || f == Ty::Bool) && t.float() => {
            let single = t == Ty::Real;
            c.emit(
                if unsigned64(f) {
                    Op::UToF(single)
                } else {
                    Op::IToF(single)
                },
                span,
            );
        }
        (f, Ty::Int(k)) if f.float() => {
            c.emit(if trunc { Op::FTrunc(k) } else { Op::FToI(k) }, span);
        }
        (f, Ty::Bool) if f.float() => {
            c.emit(Op::Push(0f64.to_bits()), span);
            c.emit(Op::CmpF(Cmp::Ne), span);
        }
        (Ty::Real, Ty::LReal) => {}
        (Ty::LReal, Ty::Real) => {
            c.emit(Op::FSingle, span);
        }
        (Ty::Time, Ty::Int(k)) => {
            c.emit(Op::Push(ms), span);
            c.emit(Op::Div(IntKind::LInt), span);
            c.emit(Op::Wrap(k), span);
        }
        (Ty::Int(_), Ty::Time) => {
            c.emit(Op::Push(ms), span);
            c.emit(Op::Mul(IntKind::LInt), span);
        }
        (Ty::Time, t) if t.float() => {
            c.emit(Op::IToF(false), span);
            c.emit(Op::Push(1e6f64.to_bits()), span);
            c.emit(Op::FDiv(t == Ty::Real), span);
        }
        (f, Ty::Time) if f.float() => {
            c.emit(Op::Push(1e6f64.to_bits()), span);
            c.emit(Op::FMul(false), span);
            c.emit(Op::FToI(IntKind::LInt), span);
        }
        _ => {
            let (a, b) = (c.ty_name(from), c.ty_name(to));
            c.err(span, format!("no conversion from {a} to {b}"));
        }
    }
}
