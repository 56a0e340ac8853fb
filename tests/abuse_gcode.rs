//! Abuse of the G-code path from outside, through interpreter, planner and interpolator as a
//! daemon job runs them: P/L/Q extremes and mutated real programs. Whatever the program:
//! an error naming its line (and for the interpreter file:line:col), or a plan that runs;
//! never a panic, a hang, an allocation the size of the request's numbers, and an abort
//! always stops what runs.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::{load_str, InterpOptions};
use hytask::motion::trace;
use hytask::motion::{plan, InterpState, MotionConfig};

fn canon(text: &str) -> Vec<hytask::gcode::Canon> {
    load_str("abuse.ngc", text, &InterpOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .canon
}

/// Found by `G2 X299 Y299 I-1 J0 F100 P2000000000` over MDI: the planner sized the chords of
/// an arc of two billion turns in one allocation (4.5 TB) and the daemon aborted. A turn
/// count is legal G-code; the plan must refuse it by line instead.
#[test]
fn an_arc_of_two_billion_turns_is_refused_by_line_not_allocated() {
    let c = canon("G21 G90 G17\nG0 X10 Y10\nG2 X10 Y10 I5 J0 F100 P2000000000\nM2\n");
    let e = plan(&c, &MotionConfig::default()).unwrap_err().to_string();
    assert!(e.contains("line 3"), "{e}");
    assert!(e.contains("turns") || e.contains("chords"), "{e}");
}

/// The chord bound is per arc and generous: real helices (thread milling, a deep spiral)
/// still plan.
#[test]
fn a_helix_of_a_thousand_turns_still_plans() {
    let c = canon("G21 G90 G17\nG0 X10 Y10 Z0\nG2 X10 Y10 Z-50 I5 J0 F600 P1000\nM2\n");
    let p = plan(&c, &MotionConfig::default()).unwrap();
    assert!(p.distance_mm > 1000.0 * 2.0 * std::f64::consts::PI * 5.0);
}

/// Found by `G4 P100` then `job.abort` over the socket: the abort was accepted, but the dwell
/// ran to its end (a `G4 P1e20` never ended; only an e-stop stopped the job). The tool is at
/// rest during a dwell, so an abort must end it at once.
#[test]
fn an_abort_ends_a_dwell_at_once() {
    let cfg = MotionConfig::default();
    let c = canon("G21 G90\nG1 X5 F600\nG4 P100000\nG1 X10\nM2\n");
    let p = plan(&c, &cfg).unwrap();
    let periods_per_s = (1.0 / cfg.servo_period_s) as usize;
    let mut abort_at = None;
    let tr = trace::run(&p, &cfg, 30 * periods_per_s, |n, it| {
        // Abort 1 s into the dwell (the move to X5 takes about half a second).
        if n == 2 * periods_per_s {
            abort_at = Some(n);
            it.abort();
        }
    });
    assert!(abort_at.is_some(), "the trace ended before the abort");
    let end = tr.states.len();
    assert_eq!(
        *tr.states.last().unwrap(),
        InterpState::Idle,
        "still dwelling"
    );
    assert!(
        end < 3 * periods_per_s,
        "the abort took {} periods",
        end - 2 * periods_per_s
    );
    assert_eq!(
        motion_util::last(&tr)[0],
        5.0,
        "stopped where the dwell was"
    );
}

/// Found by mutating `tests/gcode/corpus/lathe_g72_pocket.ngc`: a G72.1 started at
/// Z2147483647 roughs two billion passes, which the interpreter collected in memory (21 GB
/// before the OOM killer) before checking `max_canon`. Now the cycle is refused by position.
#[test]
fn a_lathe_cycle_of_two_billion_passes_is_refused_by_position() {
    let text = "o3 sub\nG1 X2 Z-8\nG1 X4\nG1 X5 Z-5\nG1 X6 Z-7\nG1 X9 Z-7\nG1 Z0\no3 endsub\n\
                G18 G21 G90 G8\nS500 M3\nG0 X11 Z2\nG72.1 Q3 X11 Z2147483647 I1 R0.3\nM2\n";
    let e = load_str("pocket.ngc", text, &InterpOptions::default()).unwrap_err();
    assert_eq!(e.line, 12, "{e}");
    assert!(e.to_string().contains("more than"), "{e}");
    let text = text.replace(
        "G72.1 Q3 X11 Z2147483647 I1 R0.3",
        "G72 Q3 X11 Z2 I0.0000001",
    );
    let e = load_str("pocket.ngc", &text, &InterpOptions::default()).unwrap_err();
    assert!(e.to_string().contains("more than"), "{e}");
    let g70 = "o1 sub\nG1 X4 Z0\nG1 X6 Z-5\nG1 X9 Z-8\no1 endsub\nG18 G21 G90 G8\n\
               G0 X10 Z2\nG70 Q1 P2147483647 D1\nM2\n";
    let e = load_str("g70.ngc", g70, &InterpOptions::default()).unwrap_err();
    assert!(e.to_string().contains("more than"), "{e}");
}

/// Found with `hytask plan`: a peck drilling cycle with a tiny Q (a billion pecks) or a drill
/// cycle with L2147483647 filled memory in one block (5 GB before the allocation failed),
/// and a daemon job is streamed only between blocks. Refused by position now, with the
/// daemon's default limits.
#[test]
fn a_canned_cycle_of_a_billion_pecks_is_refused_by_position() {
    for (block, line) in [
        ("G90 G83 X10 Y10 Z-100 R0 Q0.0000001 F100", 3),
        ("G91 G81 X0.001 Y0 Z-1 R1 L2147483647 F100", 3),
    ] {
        let text = format!("G21 G90\nG0 X10 Y10 Z0\n{block}\nM2\n");
        let e = load_str("cycle.ngc", &text, &InterpOptions::default()).unwrap_err();
        assert_eq!(e.line, line, "{e}");
        assert!(
            e.to_string().contains("One block produces more than"),
            "{e}"
        );
    }
}

/// Tight interpreter limits, so that a mutated loop count ends fast (the bounds themselves are
/// tested in `tests/gcode_fuzz.rs`).
fn tight() -> InterpOptions {
    InterpOptions {
        limits: hytask::gcode::Limits {
            max_call_depth: 16,
            max_expr_depth: 32,
            max_loop_iterations: 5_000,
            max_blocks: 50_000,
            max_file_bytes: 1 << 20,
            max_line_len: 4096,
            max_lines: 50_000,
            max_canon: 50_000,
        },
        ..InterpOptions::default()
    }
}

/// Numbers an abuser writes into a real program.
const EXTREMES: &[&str] = &[
    "0",
    "-1",
    "0.0000001",
    "99999999",
    "-99999999",
    "2147483647",
    "1000000000000",
    "[1/3]",
];

/// Every corpus program, with seeded numbers of it replaced by extremes (P/L/Q words, loop
/// counts, radii, feeds alike): the interpreter gives file:line:col or a program, the planner
/// an error by line or a plan; never a panic, a hang or a request-sized allocation.
#[test]
fn mutated_corpus_programs_error_by_position_or_plan() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/gcode/corpus");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "ngc"))
        .collect();
    files.sort();
    assert!(files.len() > 100, "corpus not found");
    let cfg = MotionConfig::default();
    let mut seed: u64 = 0xab05_e5eed;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let mut panics = Vec::new();
    for path in &files {
        let text = std::fs::read_to_string(path).unwrap();
        // Byte ranges of the numbers following a word letter.
        let bytes = text.as_bytes();
        let mut numbers = Vec::new();
        let mut i = 1;
        while i < bytes.len() {
            if bytes[i].is_ascii_digit() && bytes[i - 1].is_ascii_alphabetic() {
                let start = i;
                while i < bytes.len() && (bytes[i].is_ascii_digit() || bytes[i] == b'.') {
                    i += 1;
                }
                numbers.push((start, i));
            }
            i += 1;
        }
        if numbers.is_empty() {
            continue;
        }
        for _ in 0..4 {
            let (a, b) = numbers[(next() as usize) % numbers.len()];
            let x = EXTREMES[(next() as usize) % EXTREMES.len()];
            let mutated = format!("{}{x}{}", &text[..a], &text[b..]);
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if std::env::var_os("ABUSE_TRACE").is_some() {
                eprintln!("{name}: byte {a}: {x}");
            }
            let run = std::panic::catch_unwind(|| match load_str(&name, &mutated, &tight()) {
                Ok(p) => {
                    let _ = plan(&p.canon, &cfg);
                }
                Err(e) => assert!(e.line >= 1 && e.col >= 1, "{e:?}"),
            });
            if run.is_err() {
                panics.push(format!("{name}: byte {a}: {x}"));
            }
        }
    }
    assert!(panics.is_empty(), "panics:\n{}", panics.join("\n"));
}
