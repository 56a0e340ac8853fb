//! LinuxCNC's long-double angle arithmetic, reproduced in double-double.
//!
//! rs274 writes `cos((x * M_PIl) / 180.0)`: with `M_PIl` a long double, the product and
//! the quotient are x87 extended (64-bit significand) and C++ picks `cosl`, so the result
//! is the cosine of an extended number slightly above the true angle (`M_PIl` exceeds pi
//! by 1.5e-20 relatively), only then stored to double. That is what decides the sign of
//! the results that should be zero: rs274's `cos[90]` is -2.5e-20 (printed `-0.0000`
//! when multiplied into a coordinate), `sin[180]` is -5e-20, `tan[45]` exactly 1. Rust
//! has no extended type, so the extended values are carried as exact double-double sums
//! and rounded to 64 significant bits where the x87 rounds; the trigonometric functions
//! are evaluated on that exact argument to about 100 bits and rounded once to double.

/// An unevaluated sum `hi + lo` with `|lo| <= ulp(hi) / 2`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Dd {
    hi: f64,
    lo: f64,
}

/// `M_PIl` (pi rounded to 64 significant bits, 0xC90FDAA22168C235 * 2^-62), exactly.
const PI_L: Dd = Dd {
    hi: std::f64::consts::PI,
    lo: 1.225_148_454_908_62e-16,
};

/// pi/2 in three parts (about 160 bits), for the argument reduction.
const PIO2: [f64; 3] = [
    std::f64::consts::FRAC_PI_2,
    6.123_233_995_736_766e-17,
    -1.497_384_904_859_169_8e-33,
];

fn two_sum(a: f64, b: f64) -> Dd {
    let s = a + b;
    let bb = s - a;
    Dd {
        hi: s,
        lo: (a - (s - bb)) + (b - bb),
    }
}

fn two_prod(a: f64, b: f64) -> Dd {
    let p = a * b;
    Dd {
        hi: p,
        lo: a.mul_add(b, -p),
    }
}

fn add(x: Dd, y: Dd) -> Dd {
    let s = two_sum(x.hi, y.hi);
    let t = two_sum(x.lo, y.lo);
    let s = two_sum(s.hi, s.lo + t.hi);
    two_sum(s.hi, s.lo + t.lo)
}

fn mul(x: Dd, y: Dd) -> Dd {
    let p = two_prod(x.hi, y.hi);
    two_sum(p.hi, p.lo + (x.hi * y.lo + x.lo * y.hi))
}

fn neg(x: Dd) -> Dd {
    Dd {
        hi: -x.hi,
        lo: -x.lo,
    }
}

fn div(x: Dd, y: Dd) -> Dd {
    let q1 = x.hi / y.hi;
    let r = add(x, neg(mul(Dd { hi: q1, lo: 0.0 }, y)));
    let q2 = r.hi / y.hi;
    let r = add(r, neg(mul(Dd { hi: q2, lo: 0.0 }, y)));
    let q3 = r.hi / y.hi;
    add(two_sum(q1, q2), Dd { hi: q3, lo: 0.0 })
}

fn dd(x: f64) -> Dd {
    Dd { hi: x, lo: 0.0 }
}

/// `x` rounded to 64 significant bits, to nearest, ties to even: an x87 extended result.
fn round_ext(x: Dd) -> Dd {
    let x = two_sum(x.hi, x.lo);
    if x.hi == 0.0 || !x.hi.is_finite() || x.lo == 0.0 {
        return x;
    }
    let bits = x.hi.abs().to_bits();
    let mut e = ((bits >> 52) & 0x7ff) as i32 - 1023;
    if bits & ((1 << 52) - 1) == 0 && (x.lo < 0.0) != (x.hi < 0.0) {
        // hi is a power of two and the sum lies below it
        e -= 1;
    }
    let ulp_exp = e - 63;
    if !(-1022..=1023).contains(&ulp_exp) {
        return x;
    }
    let ulp = f64::from_bits(((ulp_exp + 1023) as u64) << 52);
    // hi is a multiple of 2 ulp (its own ulp is at least 2^11 extended ones), so the tie
    // goes to the even multiple of lo's share alone.
    let n = (x.lo / ulp).round_ties_even();
    two_sum(x.hi, n * ulp)
}

/// `(x * M_PIl) / 180` as rs274 computes it: two extended roundings.
fn ext_radians(x: f64) -> Dd {
    let p = two_prod(x, PI_L.hi);
    let q = two_prod(x, PI_L.lo);
    let prod = round_ext(add(p, q));
    round_ext(div(prod, dd(180.0)))
}

/// sin and cos of `r`, |r| <= pi/4, by their Taylor series in double-double.
fn sin_cos_small(r: Dd) -> (Dd, Dd) {
    let r2 = mul(r, r);
    // Horner from the highest term: sum (-1)^k r^2k / (2k+1)! and / (2k)!
    const TERMS: u32 = 14;
    let (mut s, mut c) = (dd(1.0), dd(1.0));
    for k in (1..=TERMS).rev() {
        let k = f64::from(k);
        // s = 1 - r2 / ((2k)(2k+1)) * s
        let ds = div(mul(r2, s), dd(2.0 * k * (2.0 * k + 1.0)));
        s = add(dd(1.0), neg(ds));
        let dc = div(mul(r2, c), dd((2.0 * k - 1.0) * (2.0 * k)));
        c = add(dd(1.0), neg(dc));
    }
    (mul(r, s), c)
}

/// sin and cos of the exact value `x` (|x| below about 1e9).
fn sin_cos(x: Dd) -> (Dd, Dd) {
    let k = (x.hi / PIO2[0]).round();
    // x - k pi/2: the first difference is exact (Sterbenz), the rest are exact products
    let m = two_prod(k, PIO2[0]);
    let mut r = two_sum(x.hi - m.hi, x.lo);
    r = add(r, neg(dd(m.lo)));
    r = add(r, neg(two_prod(k, PIO2[1])));
    r = add(r, dd(-k * PIO2[2]));
    let (s, c) = sin_cos_small(r);
    match (k as i64).rem_euclid(4) {
        0 => (s, c),
        1 => (c, neg(s)),
        2 => (neg(s), neg(c)),
        _ => (neg(c), s),
    }
}

/// Which function of an angle in degrees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trig {
    /// `sin[x]`
    Sin,
    /// `cos[x]`
    Cos,
    /// `tan[x]`
    Tan,
}

/// rs274's `sin[x]`, `cos[x]`, `tan[x]` of `x` degrees (see the module doc).
///
/// Checked against g++ on 20000 arguments (integers, thousandths, multiples of 4.5,
/// random): sin and cos agree bit for bit; tan differs in the last bit on about 1 in
/// 2000 (glibc's `tanl` is not correctly rounded), far below the printed digits.
pub fn trig_deg(f: Trig, x: f64) -> f64 {
    if !x.is_finite() || x.abs() > 1e15 {
        // outside the reduction's range: the double formula (no program goes there)
        let r = x * std::f64::consts::PI / 180.0;
        return match f {
            Trig::Sin => r.sin(),
            Trig::Cos => r.cos(),
            Trig::Tan => r.tan(),
        };
    }
    let (s, c) = sin_cos(ext_radians(x));
    let v = match f {
        Trig::Sin => s,
        Trig::Cos => c,
        Trig::Tan => div(s, c),
    };
    // cosl's extended result, then the store to double (two roundings)
    let v = round_ext(v);
    v.hi + v.lo
}

/// `a + k * M_PIl` in extended (the product rounded first, as C does), not yet stored.
fn ext_add_pi(a: f64, k: f64) -> Dd {
    let kp = round_ext(mul(dd(k), PI_L));
    round_ext(add(dd(a), kp))
}

/// The extended `x` stored to double (the second rounding of an x87 result).
fn store(x: Dd) -> f64 {
    let x = two_sum(x.hi, x.lo);
    x.hi
}

/// rs274's `a + k * M_PIl` stored to a double (angle arithmetic in cutter compensation
/// and arcs: `theta + 2 * M_PIl`, `beta - M_PI_2l` with k = -0.5).
pub fn add_pi(a: f64, k: f64) -> f64 {
    store(ext_add_pi(a, k))
}

/// rs274's `a + k * M_PIl + b` (left to right, both sums extended) stored to a double.
pub fn add_pi_then(a: f64, k: f64, b: f64) -> f64 {
    store(round_ext(add(ext_add_pi(a, k), dd(b))))
}

/// rs274's `(a + M_PIl) / 2.0` stored to a double (half an inside corner).
pub fn half_add_pi(a: f64) -> f64 {
    let s = ext_add_pi(a, 1.0);
    store(Dd {
        hi: s.hi / 2.0,
        lo: s.lo / 2.0,
    })
}

/// rs274's `r * sin(beta - M_PI_2l)` stored to a double: the argument is extended, so C++
/// takes `sinl`, and the product is extended too (a cutter compensation corner).
pub fn mul_sin_minus_half_pi(r: f64, beta: f64) -> f64 {
    let (s, _) = sin_cos(ext_add_pi(beta, -0.5));
    store(round_ext(mul(dd(r), round_ext(s))))
}

/// rs274's `(r * 180.0) / M_PIl`: radians to degrees, the product in double, the quotient
/// in extended, then stored to double.
pub fn rad2deg(r: f64) -> f64 {
    let q = round_ext(div(dd(r * 180.0), PI_L));
    q.hi + q.lo
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values printed by a C++ program compiled with g++ on x86-64 (`cos((x * M_PIl) /
    /// 180.0)` with `<math.h>`, printf `%.17g`), the arithmetic rs274 runs.
    #[test]
    fn matches_x87_long_double() {
        let cases = [
            (Trig::Cos, 90.0, -2.508278806334166e-20),
            (Trig::Cos, 270.0, 1.836_685_814_385_754_3e-19),
            (Trig::Sin, 180.0, -5.016557612668332e-20),
            (Trig::Sin, 360.0, 1.003_311_522_533_666_5e-19),
            (Trig::Cos, 450.0, -4.506745920623597e-19),
            (Trig::Tan, 90.0, -3.98679762981171e+19),
            (Trig::Tan, 45.0, 1.0),
            (Trig::Tan, 30.0, 0.5773502691896257),
            (Trig::Sin, 45.0, std::f64::consts::FRAC_1_SQRT_2),
            (Trig::Cos, 30.0, 0.866_025_403_784_438_6),
            (Trig::Sin, 30.0, 0.5),
            // cosl's extended result is rounded again when stored: these two need both
            (Trig::Cos, -3.366, 0.9982748452732826),
            (Trig::Cos, 98.455, -0.147_032_594_378_678_16),
        ];
        for (f, x, want) in cases {
            let want: f64 = want;
            let got = trig_deg(f, x);
            assert_eq!(
                got.to_bits(),
                want.to_bits(),
                "{f:?}({x}) = {got:e}, want {want:e}"
            );
        }
    }

    /// g++ on x86-64: `double t = a + 2 * M_PIl;` and friends, printf `%.17g`.
    #[test]
    fn pi_sums_match_x87() {
        // the double sums give 3.7831853071795862, -1.4707963267948965, 3.4415926535897929
        assert_eq!(add_pi(-2.5, 2.0), 3.7831853071795867);
        assert_eq!(add_pi(0.1, -0.5), -1.4707963267948967);
        assert_eq!(half_add_pi(-0.3), 1.4207963267948966);
        assert_eq!(add_pi_then(1.0, 1.0, -0.7), 3.4415926535897934);
    }

    #[test]
    fn rad2deg_rounds_like_rs274() {
        assert_eq!(rad2deg(std::f64::consts::FRAC_PI_2), 90.0);
        assert_eq!(rad2deg(1.0f64.atan2(1.0)), 45.0);
        assert_eq!(rad2deg(0.0), 0.0);
    }

    #[test]
    fn round_ext_rounds_to_64_bits() {
        // 1 + 2^-64 is a tie between 1 and 1 + 2^-63: even is 1
        let x = Dd {
            hi: 1.0,
            lo: 2f64.powi(-64),
        };
        assert_eq!(round_ext(x), dd(1.0));
        let y = Dd {
            hi: 1.0,
            lo: 3.0 * 2f64.powi(-64),
        };
        assert_eq!(round_ext(y).lo, 2f64.powi(-62));
    }
}
