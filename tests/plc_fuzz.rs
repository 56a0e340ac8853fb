//! The compiler never panics or hangs on broken input, and what it accepts scans without
//! panicking: every corpus file is mutated (spans deleted, tokens inserted) deterministically
//! and compiled; programs that compile are scanned with extreme inputs. With
//! PLC_FUZZ_TRACE set, each input is written to /tmp/plc_fuzz_last.st first (to find a hang).
#![allow(clippy::unwrap_used)]

use hytask::plc::{compile, Options, Value};

const TOKENS: &[&str] = &[
    ";",
    ":=",
    "(",
    ")",
    "[",
    "]",
    "END_IF",
    "IF",
    "THEN",
    "END_VAR",
    "VAR",
    "CASE",
    "OF",
    ":",
    "..",
    "x",
    "1",
    "16#FF",
    "T#5s",
    "(*",
    "*)",
    "'",
    ".",
    ".3",
    "FOR",
    "TO",
    "DO",
    "END_FOR",
    "=>",
    "NOT",
    "-",
    "**",
    "%IX0.0",
    "{",
    "}",
    "ARRAY",
    "STRUCT",
    "END_STRUCT",
    "REPEAT",
    "UNTIL",
    "#",
    "E",
    "/",
    "1.5E",
    "FUNCTION_BLOCK",
    "END_PROGRAM",
];

/// A small deterministic generator (xorshift), so failures reproduce.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> usize {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0 as usize
    }
}

fn mutate(src: &str, rng: &mut Rng) -> String {
    let chars: Vec<char> = src.chars().collect();
    let mut out: Vec<char> = chars.clone();
    for _ in 0..1 + rng.next() % 3 {
        let at = rng.next() % (out.len() + 1);
        if rng.next().is_multiple_of(2) && at < out.len() {
            let len = 1 + rng.next() % 12;
            out.drain(at..(at + len).min(out.len()));
        } else {
            let t = TOKENS[rng.next() % TOKENS.len()];
            for (i, c) in format!(" {t} ").chars().enumerate() {
                out.insert(at + i, c);
            }
        }
    }
    out.into_iter().collect()
}

#[test]
fn mutated_corpus_never_panics() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/plc/corpus");
    let mut compiled = 0;
    let mut rejected = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let src = std::fs::read_to_string(e.unwrap().path()).unwrap();
        for _ in 0..150 {
            let m = mutate(&src, &mut rng);
            if std::env::var_os("PLC_FUZZ_TRACE").is_some() {
                std::fs::write("/tmp/plc_fuzz_last.st", &m).unwrap();
            }
            match compile("m.st", &m, Options { budget: 10_000 }) {
                Ok(mut p) => {
                    compiled += 1;
                    let ids: Vec<_> = (0..p.vars().len() as u32).map(hytask::plc::VarId).collect();
                    for (i, &id) in ids.iter().enumerate() {
                        let v = match p.info(id).ty {
                            hytask::plc::Ty::Bool => Value::Bool(i % 2 == 0),
                            hytask::plc::Ty::Real | hytask::plc::Ty::LReal => Value::Real(-1e30),
                            hytask::plc::Ty::Time => Value::Time(i64::MIN / 2),
                            _ => Value::Int(-1),
                        };
                        let _ = p.set(id, v);
                    }
                    for s in 0..3 {
                        let _ = p.scan(&[], &mut [], i64::MAX / 4 * s);
                        p.reset_fault();
                    }
                }
                Err(d) => {
                    rejected += 1;
                    assert!(!d.list.is_empty());
                    for x in &d.list {
                        assert!(x.span.line >= 1 && x.span.col >= 1, "{d}");
                    }
                }
            }
        }
    }
    assert!(
        compiled > 50 && rejected > 50,
        "compiled {compiled}, rejected {rejected}"
    );
}
