//! Parameter values in `(DEBUG,…)`, `(PRINT,…)`, `(ABORT,…)` and `(LOG,…)` comments, as
//! rs274's `convert_param_comment` writes them.
//!
//! `#n` and `#<name>` are replaced by their value (`######` when unset or out of range);
//! the format is `%f` until a directive changes it for the rest of the comment: `%d`
//! (no decimals), `%f` (four), `%.Nf` (N, one digit). A value within 0.0001 of 0 prints as
//! 0 (rs274 compares with its fuzzy `equal`), so a rounding residue never shows as
//! `-0.000000`. What is not a directive is copied as rs274 copies it (a `%.` not followed
//! by a digit and `f` loses its `%`). An unterminated `#<name` (or a `#` ending the
//! comment) is an error rs274 ignores: the text stops there.

use super::Interp;
use crate::gcode::expr::ParamSource;

/// rs274's `VAL_LEN`: a value whose text does not fit in 29 characters is `######`.
const VAL_LEN: usize = 30;

/// rs274's `TOLERANCE_EQUAL`.
const TOLERANCE_EQUAL: f64 = 0.0001;

/// The text of `v` under the comment's current format (`decimals`).
fn value_text(v: f64, decimals: usize) -> String {
    let v = if v.abs() < TOLERANCE_EQUAL { 0.0 } else { v };
    let s = format!("{v:.decimals$}");
    if s.len() >= VAL_LEN {
        "######".into()
    } else {
        s
    }
}

impl Interp<'_> {
    /// The comment body with its parameters substituted.
    pub(super) fn substitute(&self, text: &str) -> String {
        let b = text.as_bytes();
        let mut out = String::with_capacity(text.len());
        let mut decimals = 6;
        let mut i = 0;
        while i < b.len() {
            match b[i] {
                b'%' => {
                    i += 1;
                    match b.get(i) {
                        Some(b'd') => {
                            decimals = 0;
                            i += 1;
                        }
                        Some(b'f') => {
                            decimals = 4;
                            i += 1;
                        }
                        Some(b'.') => {
                            i += 1;
                            match (b.get(i), b.get(i + 1)) {
                                (Some(d), Some(b'f')) if d.is_ascii_digit() => {
                                    decimals = usize::from(d - b'0');
                                    i += 2;
                                }
                                _ => out.push('.'),
                            }
                        }
                        _ => out.push('%'),
                    }
                }
                b'#' => {
                    i += 1;
                    let Some(&c) = b.get(i) else {
                        return out;
                    };
                    let value = if c.is_ascii_digit() {
                        let n = b[i..].iter().take_while(|c| c.is_ascii_digit()).count();
                        let v = text[i..i + n]
                            .parse::<f64>()
                            .ok()
                            .and_then(|n| ParamSource::numbered(self, n).ok());
                        i += n;
                        v
                    } else if c == b'<' {
                        let rest = &text[i + 1..];
                        let Some(end) = rest
                            .find(['>', ')'])
                            .filter(|&e| rest[e..].starts_with('>'))
                        else {
                            return out;
                        };
                        let name: String = rest[..end]
                            .chars()
                            .filter(|c| !c.is_whitespace())
                            .map(|c| c.to_ascii_lowercase())
                            .collect();
                        i += 1 + end + 1;
                        ParamSource::named(self, &name)
                    } else {
                        out.push('#');
                        continue;
                    };
                    match value {
                        Some(v) => out.push_str(&value_text(v, decimals)),
                        None => out.push_str("######"),
                    }
                }
                _ => {
                    let ch = text[i..].chars().next().unwrap_or(' ');
                    out.push(ch);
                    i += ch.len_utf8();
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::value_text;

    #[test]
    fn values_as_rs274_prints_them() {
        assert_eq!(value_text(1.123456789, 6), "1.123457");
        assert_eq!(value_text(1.123456789, 0), "1");
        assert_eq!(value_text(2.5, 0), "2");
        assert_eq!(value_text(-0.00009, 6), "0.000000");
        assert_eq!(value_text(-0.0, 4), "0.0000");
        assert_eq!(value_text(1e30, 6), "######");
    }
}
