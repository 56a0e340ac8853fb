//! Values of elementary types outside the VM: conversion to and from cells, IEC literal
//! formatting (`TRUE`, `42`, `1.5`, `T#1s500ms`) and parsing of values typed by a user.

use super::types::Ty;

/// A value of an elementary type.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    /// BOOL
    Bool(bool),
    /// Any integer or bit string (ULINT/LWORD above `i64::MAX` reinterpret the bits).
    Int(i64),
    /// REAL or LREAL.
    Real(f64),
    /// TIME, in nanoseconds.
    Time(i64),
}

/// A value could not be stored in a variable of the given type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{value} does not fit a variable of type {ty}")]
pub struct TypeMismatch {
    /// The value as text.
    pub value: String,
    /// The variable's type.
    pub ty: String,
}

impl Value {
    /// Reads a cell of type `ty`.
    pub fn from_cell(ty: Ty, c: u64) -> Value {
        match ty {
            Ty::Bool => Value::Bool(c != 0),
            Ty::Real | Ty::LReal => Value::Real(f64::from_bits(c)),
            Ty::Time => Value::Time(c as i64),
            _ => Value::Int(c as i64),
        }
    }

    /// The cell of this value stored in a variable of type `ty`, if it fits.
    pub fn to_cell(self, ty: Ty) -> Option<u64> {
        match (ty, self) {
            (Ty::Bool, Value::Bool(b)) => Some(b as u64),
            (Ty::Bool, Value::Int(v @ (0 | 1))) => Some(v as u64),
            (Ty::Int(k), Value::Int(v)) => {
                let fits =
                    (k.min()..=k.max()).contains(&(v as i128)) || (k.bits() == 64 && !k.signed());
                fits.then_some(v as u64)
            }
            (Ty::Int(_), Value::Bool(b)) => Some(b as u64),
            (Ty::Enum(_), Value::Int(v)) => Some(v as u64),
            (Ty::Real, Value::Real(v)) => Some((v as f32 as f64).to_bits()),
            (Ty::Real, Value::Int(v)) => Some((v as f32 as f64).to_bits()),
            (Ty::LReal, Value::Real(v)) => Some(v.to_bits()),
            (Ty::LReal, Value::Int(v)) => Some((v as f64).to_bits()),
            (Ty::Time, Value::Time(v)) => Some(v as u64),
            _ => None,
        }
    }
}

/// Formats a cell of type `ty` as an IEC literal. `enum_name` names enumeration values.
pub fn format_cell(ty: Ty, c: u64, enum_name: impl Fn(u32, i64) -> Option<String>) -> String {
    match ty {
        Ty::Bool => if c != 0 { "TRUE" } else { "FALSE" }.into(),
        Ty::Int(k) if k.bitstring() => format!("16#{c:X}"),
        Ty::Int(k) if k.bits() == 64 && !k.signed() => c.to_string(),
        Ty::Int(_) => (c as i64).to_string(),
        Ty::Real => format!("{:?}", f64::from_bits(c) as f32),
        Ty::LReal => format!("{:?}", f64::from_bits(c)),
        Ty::Time => format_time(c as i64),
        Ty::Enum(e) => enum_name(e, c as i64).unwrap_or_else(|| (c as i64).to_string()),
        _ => "?".into(),
    }
}

/// `T#1h2m3s4ms`, `T#0ms`, `T#-5s`.
pub fn format_time(ns: i64) -> String {
    if ns == 0 {
        return "T#0ms".into();
    }
    let mut s = String::from("T#");
    if ns < 0 {
        s.push('-');
    }
    let mut rest = ns.unsigned_abs();
    for (unit, len) in [
        ("d", 86_400_000_000_000u64),
        ("h", 3_600_000_000_000),
        ("m", 60_000_000_000),
        ("s", 1_000_000_000),
        ("ms", 1_000_000),
        ("us", 1_000),
        ("ns", 1),
    ] {
        if rest >= len {
            s.push_str(&format!("{}{unit}", rest / len));
            rest %= len;
        }
    }
    s
}

/// Parses a value typed by a user for a variable of type `ty`: `TRUE`/`FALSE`/`1`/`0`,
/// integers (also `16#FF`), reals, `T#...` durations (or plain milliseconds), enumeration
/// value names (resolved by `enum_value`).
pub fn parse_value(
    ty: Ty,
    text: &str,
    enum_value: impl Fn(u32, &str) -> Option<i64>,
) -> Option<Value> {
    let t = text.trim();
    let up = t.to_ascii_uppercase();
    let int = || -> Option<i64> {
        if let Some((base, digits)) = up.split_once('#') {
            let base: u32 = base.parse().ok()?;
            return u64::from_str_radix(&digits.replace('_', ""), base)
                .ok()
                .map(|v| v as i64);
        }
        up.replace('_', "")
            .parse::<i64>()
            .ok()
            .or_else(|| up.parse::<u64>().ok().map(|v| v as i64))
    };
    let v = match ty {
        Ty::Bool => match up.as_str() {
            "TRUE" | "1" => Value::Bool(true),
            "FALSE" | "0" => Value::Bool(false),
            _ => return None,
        },
        Ty::Int(_) => Value::Int(int()?),
        Ty::Real | Ty::LReal => Value::Real(up.parse().ok()?),
        Ty::Time => {
            let body = up.strip_prefix("T#").or_else(|| up.strip_prefix("TIME#"));
            match body {
                Some(b) => {
                    let (neg, b) = match b.strip_prefix('-') {
                        Some(b) => (true, b),
                        None => (false, b),
                    };
                    let ns =
                        super::lexer::parse_duration(&b.to_ascii_lowercase().replace('_', ""))?;
                    Value::Time(if neg { -ns } else { ns })
                }
                None => Value::Time(int()?.checked_mul(1_000_000)?),
            }
        }
        Ty::Enum(e) => Value::Int(enum_value(e, &up).or_else(int)?),
        _ => return None,
    };
    v.to_cell(ty).map(|_| v)
}
