//! The command line's whole-program paths abused (session 10): `hytask plan` and `hytask
//! plot` hold every canonical command and the plan in memory, where a job streams. A 90-byte
//! program could make them hold the interpreter's 50 M commands (GBs). Now a documented
//! limit (`--max-commands`, default `PLAN_MAX_COMMANDS`) refuses it with an error naming it.
#![allow(clippy::unwrap_used)]

mod support;

use support::*;

/// A loop of `n` iterations of two moves: `2 n` commands from a few lines.
fn moves(dir: &std::path::Path, n: u64) -> std::path::PathBuf {
    let p = dir.join("many.ngc");
    let text = format!("G21 G90\no1 repeat [{n}]\nG1 X1 F600\nG1 X0\no1 endrepeat\nM2\n");
    std::fs::write(&p, text).unwrap();
    p
}

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn plan_and_plot_refuse_a_program_beyond_max_commands_naming_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let prog = moves(dir.path(), 1_000);
    let file = prog.to_str().unwrap();
    let svg = dir.path().join("p.svg");
    let svg = svg.to_str().unwrap();
    for args in [
        vec!["plan", file, "--max-commands", "500"],
        vec!["plot", file, "-o", svg, "--max-commands", "500"],
    ] {
        let out = hytask(&args);
        assert!(!out.status.success(), "{args:?}");
        let e = stderr(&out);
        assert!(
            e.contains("at most 500 (--max-commands)") && e.contains("limit 500"),
            "{args:?}: {e}"
        );
    }
    // Within the limit it plans.
    hytask_ok(&["plan", file, "--max-commands", "5000"]);
}

#[test]
fn plan_has_a_default_limit_far_below_the_interpreters() {
    let dir = tempfile::tempdir().unwrap();
    // 2.2 M commands: over the default 2 M (before, planned whole after GBs of commands).
    let prog = moves(dir.path(), 1_100_000);
    let out = hytask(&["plan", prog.to_str().unwrap()]);
    assert!(!out.status.success());
    let e = stderr(&out);
    assert!(e.contains("at most 2000000 (--max-commands)"), "{e}");
}

/// Found in session 10: `hytask plan` of `G1 X10 F0.000…1` (a subnormal feed) overflowed
/// (a panic in a debug build) sizing its trace; now refused by position as a job is.
#[test]
fn plan_refuses_a_subnormal_feed_by_position() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("sub.ngc");
    let tiny = format!("0.{}1", "0".repeat(318));
    std::fs::write(&p, format!("G21 G90\nG1 X10 F{tiny}\nM2\n")).unwrap();
    let out = hytask(&["plan", p.to_str().unwrap()]);
    assert!(!out.status.success());
    let e = stderr(&out);
    assert!(
        e.contains("sub.ngc:2:")
            && e.contains("below the slowest accepted")
            && !e.contains("panicked"),
        "{e}"
    );
}

/// A program the planner refuses (a move past the soft limits) is named with its file and
/// line, as a refused job is (`hytask plan` said only "line 2").
#[test]
fn plan_names_the_file_and_line_of_a_move_it_refuses() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("far.ngc");
    std::fs::write(&p, "G21 G90\nG1 X5000 F600\nM2\n").unwrap();
    let out = hytask(&["plan", p.to_str().unwrap()]);
    assert!(!out.status.success());
    let e = stderr(&out);
    assert!(
        e.contains("far.ngc: line 2:") && e.contains("soft limits"),
        "{e}"
    );
}

/// Found in session 10: `hytask plan` of a slow but accepted feed (`F0.001`, 10 mm: a job
/// of 600,000 s) ran the servo-period trace for hours and held GBs. Now the plan and its
/// time are reported and the trace is not run beyond `--max-trace-s` (default 4 h), which
/// `--trace` and `plot --velocity` name when they refuse.
#[test]
fn plan_reports_a_very_long_job_without_running_its_trace() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("slow.ngc");
    std::fs::write(&p, "G21 G90\nG1 X10 F0.001\nM2\n").unwrap();
    let file = p.to_str().unwrap();
    let out = hytask_ok(&["plan", file]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("job time:        600000.")
            && text.contains("trace:           not run")
            && text.contains("--max-trace-s 14400"),
        "{text}"
    );
    let csv = dir.path().join("t.csv");
    let svg = dir.path().join("v.svg");
    for args in [
        vec!["plan", file, "--trace", csv.to_str().unwrap()],
        vec!["plot", file, "--velocity", "-o", svg.to_str().unwrap()],
    ] {
        let out = hytask(&args);
        assert!(!out.status.success(), "{args:?}");
        assert!(stderr(&out).contains("--max-trace-s"), "{args:?}");
    }
    // A short job is traced as before; the limit is the option's.
    std::fs::write(&p, "G21 G90\nG1 X10 F600\nM2\n").unwrap();
    let out = hytask_ok(&["plan", file, "--max-trace-s", "0.5"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("not run"));
    let out = hytask_ok(&["plan", file, "--max-trace-s", "5"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("periods of 1.000 ms"));
}
