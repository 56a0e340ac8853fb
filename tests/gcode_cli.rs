//! `hytask gcode canon|check` as a user runs them: trace on stdout in rs274 layout, errors
//! on stderr with file:line:col and a failing exit status.
#![allow(clippy::unwrap_used)]

use std::process::Command;

fn hytask() -> Command {
    Command::new(env!("CARGO_BIN_EXE_hytask"))
}

#[test]
fn canon_prints_the_rs274_layout() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("p.ngc");
    std::fs::write(&f, "G21 G0 X1\n(PRINT, hello)\nM2\n").unwrap();
    let out = hytask().args(["gcode", "canon"]).arg(&f).output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "    1 N..... USE_LENGTH_UNITS(CANON_UNITS_MM)");
    assert!(lines.contains(
        &"    8 N..... STRAIGHT_TRAVERSE(1.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000)"
    ));
    assert!(lines.contains(&" hello"), "PRINT is a bare line");
    assert_eq!(lines.last().copied(), Some("   17 N..... ON_RESET()"));
}

#[test]
fn canon_uses_tool_table_and_subroutine_path() {
    let dir = tempfile::tempdir().unwrap();
    let subs = dir.path().join("subs");
    std::fs::create_dir(&subs).unwrap();
    std::fs::write(
        subs.join("drill.ngc"),
        "o<drill> sub\nG1 Z-1\no<drill> endsub\nM2\n",
    )
    .unwrap();
    std::fs::write(dir.path().join("t.tbl"), "T4 P1 Z1\n").unwrap();
    let f = dir.path().join("p.ngc");
    std::fs::write(&f, "G21 F10 T4 M6 G43\no<drill> call\nM2\n").unwrap();
    let out = hytask()
        .args(["gcode", "canon", "--tool-table"])
        .arg(dir.path().join("t.tbl"))
        .arg("--subroutine-path")
        .arg(&subs)
        .arg(&f)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    // Default machine units are inches, as rs274 without an INI file.
    assert!(
        text.contains("USE_TOOL_LENGTH_OFFSET(0.0000 0.0000 25.4000,"),
        "{text}"
    );
    assert!(text.contains("STRAIGHT_FEED(0.0000, 0.0000, -1.0000,"));
}

#[test]
fn errors_fail_with_file_line_column() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("bad.ngc");
    std::fs::write(&f, "G21\nG1 X1\nM2\n").unwrap();
    for sub in ["canon", "check"] {
        let out = hytask().args(["gcode", sub]).arg(&f).output().unwrap();
        assert!(!out.status.success());
        assert!(out.stdout.is_empty(), "no partial trace");
        let err = String::from_utf8(out.stderr).unwrap();
        assert!(
            err.contains("bad.ngc:2:1: Cannot do g1 with zero feed rate"),
            "{err}"
        );
    }
    std::fs::write(&f, "G21\nG1 X1 F1\nM2\n").unwrap();
    let out = hytask().args(["gcode", "check"]).arg(&f).output().unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8(out.stdout).unwrap().contains("ok"));
}

/// `hytask plan` plans a program that changes tools with `--tool-table`; without a table
/// it refuses it with the line of the unknown tool, as `gcode canon` does.
#[test]
fn plan_takes_a_tool_table() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("t.tbl"), "T4 P1 Z10\n").unwrap();
    let f = dir.path().join("p.ngc");
    std::fs::write(&f, "G21 F600 T4 M6 G43\nG1 X10 Z-1\nM2\n").unwrap();
    let without = hytask().arg("plan").arg(&f).output().unwrap();
    assert!(!without.status.success());
    let err = String::from_utf8_lossy(&without.stderr);
    assert!(err.contains("p.ngc:1:"), "{err}");
    let with = hytask()
        .arg("plan")
        .arg(&f)
        .arg("--tool-table")
        .arg(dir.path().join("t.tbl"))
        .output()
        .unwrap();
    assert!(
        with.status.success(),
        "{}",
        String::from_utf8_lossy(&with.stderr)
    );
    assert!(String::from_utf8_lossy(&with.stdout).contains("job time:"));
}

/// A long trace sent to a file is written while interpreting (in chunks) and is the same
/// text as through a pipe; a long program with an error at its end leaves the file as it
/// was, so "no partial trace" holds for files too.
#[test]
fn canon_into_a_file_is_whole_or_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut prog = String::from("G21 F100\n");
    for i in 0..20_000 {
        prog.push_str(&format!("G1 X{}.5 Y{}\n", i % 97, i % 13));
    }
    let good = dir.path().join("good.ngc");
    std::fs::write(&good, format!("{prog}M2\n")).unwrap();
    let piped = hytask()
        .args(["gcode", "canon"])
        .arg(&good)
        .output()
        .unwrap();
    assert!(piped.status.success());
    assert!(piped.stdout.len() > 1 << 20, "several chunks long");

    let to_file = |prog: &std::path::Path, name: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, b"kept\n").unwrap();
        let file = std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .unwrap();
        let status = hytask()
            .args(["gcode", "canon"])
            .arg(prog)
            .stdout(file)
            .status()
            .unwrap();
        (status, std::fs::read(&path).unwrap())
    };
    let (status, text) = to_file(&good, "good.txt");
    assert!(status.success());
    assert_eq!(&text[..5], b"kept\n");
    assert!(text[5..] == piped.stdout[..], "file and pipe traces differ");

    let bad = dir.path().join("bad.ngc");
    std::fs::write(&bad, format!("{prog}G1 X1 Y1 Z1 Q\nM2\n")).unwrap();
    let (status, text) = to_file(&bad, "bad.txt");
    assert!(!status.success());
    assert_eq!(text, b"kept\n", "the partial trace was taken back");
}
