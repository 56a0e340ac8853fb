//! Syntax conformance against an independent grammar: blark (a lark grammar of TwinCAT's
//! IEC 61131-3 dialect, PyPI) and our parser must agree on every file of the corpus
//! (tests/plc/corpus/*.st, written in OpenPLC and TwinCAT style, plus the shipped programs in
//! config/plc/): both accept it, or both reject it at the same line. Files where they
//! disagree for a known reason are listed in `DIFFERENCES` with the reason; a listed file
//! that stops differing fails the test, so the list stays true.
//!
//! blark lives in target/blark-venv (installed by tests/install-deps). Without it the test
//! fails under CI=true and is reported as skipped otherwise.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Files the two parsers disagree on, and why.
const DIFFERENCES: &[(&str, &str)] = &[(
    "comments_pragmas.st",
    "C-style /* */ comments: CODESYS and TwinCAT 3 accept them (and we do); blark 0.8.3's \
     grammar only knows (* *) and //",
)];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn corpus() -> Vec<PathBuf> {
    let mut files = Vec::new();
    for dir in ["tests/plc/corpus", "config/plc"] {
        for e in std::fs::read_dir(root().join(dir)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "st") {
                files.push(p);
            }
        }
    }
    files.sort();
    files
}

fn name(p: &Path) -> String {
    p.file_name().unwrap().to_string_lossy().into_owned()
}

/// blark's verdict per file: `None` if accepted, else the line of its first error.
fn blark(files: &[PathBuf]) -> Option<BTreeMap<String, Option<u32>>> {
    let python = root().join("target/blark-venv/bin/python");
    if !python.exists() {
        assert!(
            std::env::var_os("CI").is_none(),
            "blark is not installed in target/blark-venv: run tests/install-deps"
        );
        eprintln!("SKIPPED: blark not installed (run tests/install-deps)");
        return None;
    }
    let out = Command::new(python)
        .arg(root().join("tests/plc/blark_check.py"))
        .args(files)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let mut verdicts = BTreeMap::new();
    for line in text.lines() {
        let mut f = line.split('\t');
        let path = f.next().unwrap();
        let verdict = match f.next() {
            Some("OK") => None,
            _ => {
                let msg = f.next().unwrap_or("");
                let line = msg
                    .split("at line ")
                    .nth(1)
                    .and_then(|r| r.split_whitespace().next())
                    .and_then(|n| n.parse().ok())
                    .unwrap_or(0);
                Some(line)
            }
        };
        verdicts.insert(name(Path::new(path)), verdict);
    }
    assert_eq!(verdicts.len(), files.len(), "{text}");
    Some(verdicts)
}

/// Our parser's verdict: `None` if accepted, else the line of the first syntax error.
fn ours(p: &Path) -> Option<u32> {
    let src = std::fs::read_to_string(p).unwrap();
    let (_, diags) = hytask::plc::parser::parse(&src);
    diags.iter().map(|d| d.span.line).min()
}

#[test]
fn blark_and_hytask_agree_on_the_corpus() {
    let files = corpus();
    assert!(files.len() >= 15, "corpus too small: {}", files.len());
    let Some(theirs) = blark(&files) else {
        return;
    };
    let mut disagreements = Vec::new();
    for f in &files {
        let n = name(f);
        let (a, b) = (ours(f), theirs[&n]);
        let agree = match (a, b) {
            (None, None) => true,
            (Some(x), Some(y)) => x == y,
            _ => false,
        };
        let listed = DIFFERENCES.iter().any(|d| d.0 == n);
        if agree == listed {
            disagreements.push(format!(
                "{n}: hytask {a:?}, blark {b:?} (listed as a difference: {listed})"
            ));
        }
    }
    assert!(disagreements.is_empty(), "{}", disagreements.join("\n"));
}

/// Every corpus file our parser accepts also compiles (types, layout), except the ones
/// that are meant to be wrong.
#[test]
fn accepted_corpus_files_compile() {
    for f in corpus() {
        let n = name(&f);
        if n.starts_with("bad_") {
            assert!(ours(&f).is_some(), "{n} should not parse");
            continue;
        }
        hytask::plc::load_file(&f, hytask::plc::Options::default())
            .unwrap_or_else(|e| panic!("{e}"));
    }
}
