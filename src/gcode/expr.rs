//! Expressions: `[ ]` arithmetic, parameter references and the unary functions of
//! LinuxCNC, with its precedence, its fuzzy `EQ`/`NE` and its error messages.

use super::ldouble::{rad2deg, trig_deg, Trig};

/// Binary operators, LinuxCNC spelling in the doc of each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    /// `**`
    Pow,
    /// `*`
    Mul,
    /// `/`
    Div,
    /// `MOD`
    Mod,
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `EQ`
    Eq,
    /// `NE`
    Ne,
    /// `GT`
    Gt,
    /// `GE`
    Ge,
    /// `LT`
    Lt,
    /// `LE`
    Le,
    /// `AND`
    And,
    /// `OR`
    Or,
    /// `XOR`
    Xor,
}

impl BinOp {
    /// Binding strength, higher binds tighter (LinuxCNC `precedence()`); all operators are
    /// left-associative.
    pub fn precedence(self) -> u8 {
        match self {
            BinOp::Pow => 6,
            BinOp::Mul | BinOp::Div | BinOp::Mod => 5,
            BinOp::Add | BinOp::Sub => 4,
            BinOp::Eq | BinOp::Ne | BinOp::Gt | BinOp::Ge | BinOp::Lt | BinOp::Le => 3,
            BinOp::And | BinOp::Or | BinOp::Xor => 2,
        }
    }
}

/// Unary functions (`name[arg]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Func {
    /// `ABS`
    Abs,
    /// `ACOS` (degrees)
    Acos,
    /// `ASIN` (degrees)
    Asin,
    /// `COS` (degrees)
    Cos,
    /// `EXP`
    Exp,
    /// `FIX` (round down)
    Fix,
    /// `FUP` (round up)
    Fup,
    /// `LN`
    Ln,
    /// `ROUND` (half away from zero)
    Round,
    /// `SIN` (degrees)
    Sin,
    /// `SQRT`
    Sqrt,
    /// `TAN` (degrees)
    Tan,
}

impl Func {
    /// Looks a function up by its lower-case name.
    pub fn from_name(name: &str) -> Option<Func> {
        Some(match name {
            "abs" => Func::Abs,
            "acos" => Func::Acos,
            "asin" => Func::Asin,
            "cos" => Func::Cos,
            "exp" => Func::Exp,
            "fix" => Func::Fix,
            "fup" => Func::Fup,
            "ln" => Func::Ln,
            "round" => Func::Round,
            "sin" => Func::Sin,
            "sqrt" => Func::Sqrt,
            "tan" => Func::Tan,
            _ => return None,
        })
    }
}

/// An expression tree. Constants stay unboxed so the common `X1.5` costs no allocation.
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    /// A literal.
    Num(f64),
    /// `#n` (the index is itself an expression: `#[#1+1]`, `##2`).
    Param(Box<Expr>),
    /// `#<name>` (lower-case, blanks removed).
    Named(Box<str>),
    /// `-value`.
    Neg(Box<Expr>),
    /// `func[arg]`.
    Call(Func, Box<Expr>),
    /// `ATAN[y]/[x]`, degrees.
    Atan(Box<Expr>, Box<Expr>),
    /// `EXISTS[#<name>]`.
    Exists(Box<str>),
    /// `EXISTS[#index]`: 1 when the (integer) index is a parameter number, as in rs274.
    ExistsNumbered(Box<Expr>),
    /// `a op b`.
    Bin(BinOp, Box<Expr>, Box<Expr>),
}

/// Where expression evaluation reads parameters from.
pub trait ParamSource {
    /// Value of numbered parameter `index` (already range-checked by the caller? no: the
    /// source checks and names the error).
    fn numbered(&self, index: f64) -> Result<f64, String>;
    /// Value of a named parameter, None when it does not exist.
    fn named(&self, name: &str) -> Option<f64>;
}

/// LinuxCNC's tolerance for `EQ`/`NE`.
const TOLERANCE_EQUAL: f64 = 0.0001;

/// How far from an integer a value read as an integer may be (rs274's `TOLERANCE_INCH`-like
/// test in its integer reader: `#1.00001` is 1, `#1.001` an error).
const TOLERANCE_INTEGER: f64 = 0.0001;

/// rs274's parameter table size: numbered parameters are 1 to 5601.
const MAX_PARAMETERS: f64 = crate::gcode::params::NUM_PARAMS as f64;

/// Evaluates `e` against `src`. Errors carry LinuxCNC's wording.
pub fn eval(e: &Expr, src: &dyn ParamSource) -> Result<f64, String> {
    match e {
        Expr::Num(v) => Ok(*v),
        Expr::Param(i) => {
            let idx = eval(i, src)?;
            src.numbered(idx)
        }
        Expr::Named(n) => src
            .named(n)
            .ok_or_else(|| format!("Named parameter #<{n}> not defined")),
        Expr::Neg(v) => Ok(-eval(v, src)?),
        Expr::Exists(n) => Ok(if src.named(n).is_some() { 1.0 } else { 0.0 }),
        Expr::ExistsNumbered(i) => {
            let idx = eval(i, src)?;
            let n = idx.round();
            if (idx - n).abs() > TOLERANCE_INTEGER {
                return Err("Non integer value for integer".into());
            }
            Ok(if (1.0..MAX_PARAMETERS).contains(&n) {
                1.0
            } else {
                0.0
            })
        }
        Expr::Atan(y, x) => {
            let y = eval(y, src)?;
            let x = eval(x, src)?;
            Ok(rad2deg(y.atan2(x)))
        }
        Expr::Call(f, a) => finite(call(*f, eval(a, src)?)?),
        Expr::Bin(op, a, b) => {
            let a = eval(a, src)?;
            let b = eval(b, src)?;
            finite(binary(*op, a, b)?)
        }
    }
}

/// LinuxCNC refuses a calculation whose result is not a finite number.
fn finite(v: f64) -> Result<f64, String> {
    if v.is_nan() {
        Err("Calculation resulted in 'not a number'".into())
    } else if v.is_infinite() {
        Err("Calculation resulted in 'infinity'".into())
    } else {
        Ok(v)
    }
}

fn call(f: Func, v: f64) -> Result<f64, String> {
    Ok(match f {
        Func::Abs => v.abs(),
        Func::Acos => {
            if !(-1.0..=1.0).contains(&v) {
                return Err("Argument to acos out of range".into());
            }
            rad2deg(v.acos())
        }
        Func::Asin => {
            if !(-1.0..=1.0).contains(&v) {
                return Err("Argument to asin out of range".into());
            }
            rad2deg(v.asin())
        }
        Func::Cos => trig_deg(Trig::Cos, v),
        Func::Exp => v.exp(),
        Func::Fix => v.floor(),
        Func::Fup => v.ceil(),
        Func::Ln => {
            if v <= 0.0 {
                return Err("Zero or negative argument to ln".into());
            }
            v.ln()
        }
        Func::Round => {
            // LinuxCNC rounds through a C `int` cast: out of range gives INT_MIN on x86.
            let r = (v + if v < 0.0 { -0.5 } else { 0.5 }).trunc();
            if (-2_147_483_648.0..=2_147_483_647.0).contains(&r) {
                r
            } else {
                -2_147_483_648.0
            }
        }
        Func::Sin => trig_deg(Trig::Sin, v),
        Func::Sqrt => {
            if v < 0.0 {
                return Err("Negative argument to sqrt".into());
            }
            v.sqrt()
        }
        Func::Tan => trig_deg(Trig::Tan, v),
    })
}

/// Applies one binary operator with LinuxCNC's semantics.
pub fn binary(op: BinOp, a: f64, b: f64) -> Result<f64, String> {
    let t = |c: bool| if c { 1.0 } else { 0.0 };
    Ok(match op {
        BinOp::Pow => {
            if a < 0.0 && b.floor() != b {
                return Err("Attempt to raise negative to non-integer power".into());
            }
            a.powf(b)
        }
        BinOp::Mul => a * b,
        BinOp::Div => {
            if b == 0.0 {
                return Err("Attempt to divide by zero".into());
            }
            a / b
        }
        BinOp::Mod => {
            if b == 0.0 {
                return Err("Attempt to divide by zero".into());
            }
            let mut r = a % b;
            if r < 0.0 {
                r += b.abs();
            }
            r
        }
        BinOp::Add => a + b,
        BinOp::Sub => a - b,
        BinOp::Eq => t((a - b).abs() < TOLERANCE_EQUAL),
        BinOp::Ne => t((a - b).abs() >= TOLERANCE_EQUAL),
        BinOp::Gt => t(a > b),
        BinOp::Ge => t(a >= b),
        BinOp::Lt => t(a < b),
        BinOp::Le => t(a <= b),
        BinOp::And => t(a != 0.0 && b != 0.0),
        BinOp::Or => t(a != 0.0 || b != 0.0),
        BinOp::Xor => t((a != 0.0) != (b != 0.0)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mod_is_non_negative_and_eq_is_fuzzy() {
        assert_eq!(binary(BinOp::Mod, -7.0, 3.0), Ok(2.0));
        assert_eq!(binary(BinOp::Eq, 1.0, 1.00001), Ok(1.0));
        assert_eq!(binary(BinOp::Ne, 1.0, 1.001), Ok(1.0));
        assert!(binary(BinOp::Div, 1.0, 0.0).is_err());
        assert!(binary(BinOp::Pow, -2.0, 0.5).is_err());
    }

    #[test]
    fn non_finite_results_are_errors() {
        struct NoParams;
        impl ParamSource for NoParams {
            fn numbered(&self, _: f64) -> Result<f64, String> {
                Ok(0.0)
            }
            fn named(&self, _: &str) -> Option<f64> {
                None
            }
        }
        let e = Expr::Bin(
            BinOp::Pow,
            Box::new(Expr::Num(0.0)),
            Box::new(Expr::Num(-1.0)),
        );
        assert_eq!(
            eval(&e, &NoParams),
            Err("Calculation resulted in 'infinity'".into())
        );
        let e = Expr::Call(Func::Exp, Box::new(Expr::Num(1e6)));
        assert!(eval(&e, &NoParams).is_err());
    }

    #[test]
    fn round_is_half_away_from_zero() {
        assert_eq!(call(Func::Round, 2.5), Ok(3.0));
        assert_eq!(call(Func::Round, -2.5), Ok(-3.0));
        assert_eq!(call(Func::Fix, -1.5), Ok(-2.0));
    }
}
