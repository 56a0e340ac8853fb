//! Robustness: random bytes and random token soup through the whole interpreter. Whatever
//! the input, `load_str` returns (no panic, no hang), within bounded memory, and every
//! error names a line and column.
#![allow(clippy::unwrap_used)]

use hytask::gcode::{load_str, InterpOptions, Limits};
use proptest::prelude::*;

fn tight() -> InterpOptions {
    InterpOptions {
        limits: Limits {
            max_call_depth: 16,
            max_expr_depth: 32,
            max_loop_iterations: 2_000,
            max_blocks: 20_000,
            max_file_bytes: 1 << 16,
            max_line_len: 1024,
            max_lines: 10_000,
            max_canon: 20_000,
        },
        ..InterpOptions::default()
    }
}

fn check(text: &str) {
    match load_str("fuzz.ngc", text, &tight()) {
        Ok(p) => assert!(p.canon.len() <= 20_000),
        Err(e) => {
            assert!(e.line >= 1 && e.col >= 1, "{e:?}");
            assert!(!e.message.is_empty());
        }
    }
}

const TOKENS: &[&str] = &[
    "G0",
    "G1",
    "G2",
    "G3",
    "G4",
    "G17",
    "G18",
    "G19",
    "G20",
    "G21",
    "G28",
    "G30",
    "G38.2",
    "G40",
    "G43",
    "G49",
    "G53",
    "G54",
    "G55",
    "G61",
    "G64",
    "G73",
    "G80",
    "G81",
    "G82",
    "G83",
    "G85",
    "G89",
    "G90",
    "G91",
    "G90.1",
    "G91.1",
    "G92",
    "G92.1",
    "G93",
    "G94",
    "G95",
    "G98",
    "G99",
    "G10 L2 P1",
    "G10 L20 P0",
    "M0",
    "M1",
    "M3",
    "M4",
    "M5",
    "M6",
    "M7",
    "M8",
    "M9",
    "M48",
    "M50",
    "M62 P1",
    "M66 P0 L0",
    "M67 E0 Q1",
    "M70",
    "M72",
    "M101",
    "T1",
    "X1",
    "Y-2.5",
    "Z.5",
    "A30",
    "I1",
    "J-1",
    "K1",
    "R2",
    "R-3",
    "P2",
    "Q0.5",
    "L3",
    "F100",
    "S500",
    "H1",
    "X#1",
    "Y#<a>",
    "#1=",
    "#<a>=",
    "#<_g>=",
    "[",
    "]",
    "1",
    "-",
    "+",
    "*",
    "/",
    "**",
    "MOD",
    "EQ",
    "LT",
    "AND",
    "SIN[",
    "ATAN[1]/[",
    "EXISTS[#<a>]",
    "(",
    ")",
    "(MSG,hi)",
    "(DEBUG,#1)",
    ";",
    "/",
    "%",
    "\n",
    "\n",
    "\n",
    "o1 while [1]",
    "o1 endwhile",
    "o2 if [#1]",
    "o2 else",
    "o2 endif",
    "o3 do",
    "o3 while [#1 LT 5]",
    "o4 repeat [3]",
    "o4 endrepeat",
    "o1 break",
    "o1 continue",
    "o<s> sub",
    "o<s> endsub",
    "o<s> call [1]",
    "o<s> return",
    "M2",
    "M30",
];

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, .. ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        check(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn random_ascii_lines_never_panic(text in "[ -~\n]{0,400}") {
        check(&text);
    }

    #[test]
    fn token_soup_never_panics(toks in proptest::collection::vec(0..TOKENS.len(), 0..120), end in any::<bool>()) {
        let mut s: String = toks.iter().map(|&i| TOKENS[i]).collect::<Vec<_>>().join(" ");
        if end {
            s.push_str("\nM2\n");
        }
        check(&s);
    }
}

#[test]
fn pathological_inputs_hit_limits_not_the_stack() {
    check(&format!("#1=[{}1]\nM2\n", "1+".repeat(400)));
    check(&format!("#1={}1\nM2\n", "-".repeat(5000)));
    check(&format!("#1={}1\nM2\n", "#".repeat(5000)));
    check(&format!(
        "#1={}1{}\nM2\n",
        "[".repeat(5000),
        "]".repeat(5000)
    ));
    check("o<r> sub\no<r> call\no<r> endsub\no<r> call\nM2\n");
    check("o1 while [1]\no1 endwhile\nM2\n");
    check("o1 do\no1 while [1]\nM2\n");
    check("G21 F1\nG2 X1 Y0 I0.5 J0 P99999999999\nM2\n");
    check("G21 F1 G81 X1 Z-1 R1 L999999999999\nM2\n");
    check(&format!("G0 X{}\nM2\n", "9".repeat(400)));
}
