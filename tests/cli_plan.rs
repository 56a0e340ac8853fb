//! `hytask plan FILE --trace out.csv` on the planner benchmark's programs (issue 14): the
//! CSV names its columns with units, steps at the servo period, ends where the program
//! ends, stays within every limit; and the time-optimal bound printed beside the plan is
//! a lower bound (never above the planned time) on every program.
#![allow(clippy::unwrap_used)]

#[path = "../benches/programs/gen.rs"]
mod gen;

use std::path::Path;
use std::process::Command;

/// Default limits of `hytask plan` (the benchmark's): mm/s, mm/s², mm/s³; servo period, s.
const VEL: f64 = 50.0;
const ACC: f64 = 500.0;
const JERK: f64 = 50_000.0;
const DT: f64 = 0.001;

/// Runs `hytask plan` on `program` with `--trace csv`; returns stdout.
pub fn plan_with_trace(program: &Path, csv: &Path) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args(["plan", program.to_str().unwrap(), "--trace"])
        .arg(csv)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// The number of seconds on the report line starting with `key`.
fn seconds(report: &str, key: &str) -> f64 {
    let line = report
        .lines()
        .find(|l| l.starts_with(key))
        .unwrap_or_else(|| panic!("no {key:?} in {report}"));
    line[key.len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

/// Where a G90 program of straight moves ends: the last X, Y and Z words.
fn program_end(text: &str) -> [f64; 3] {
    let mut end = [0.0; 3];
    for line in text.lines().filter(|l| !l.starts_with('(')) {
        for word in line.split_whitespace() {
            let (letter, value) = word.split_at(1);
            if let Some(a) = "XYZ".find(letter) {
                end[a] = value.parse().unwrap();
            }
        }
    }
    end
}

#[test]
fn trace_csv_and_lower_bound_on_every_benchmark_program() {
    let dir = tempfile::tempdir().unwrap();
    for p in gen::all() {
        let program = dir.path().join(p.name);
        std::fs::write(&program, &p.text).unwrap();
        let csv = dir.path().join(format!("{}.csv", p.name));
        let report = plan_with_trace(&program, &csv);
        let planned = seconds(&report, "job time:");
        let bound = seconds(&report, "optimal bound:");
        let feed = seconds(&report, "feed bound:");
        assert!(
            bound <= planned && bound >= feed,
            "{}: feed bound {feed} <= optimal bound {bound} <= plan {planned}",
            p.name
        );

        let text = std::fs::read_to_string(&csv).unwrap();
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let mut want = vec!["t_s".to_string()];
        for a in ["X", "Y", "Z"] {
            for c in ["mm", "vel_mm_s", "acc_mm_s2", "jerk_mm_s3"] {
                want.push(format!("{a}_{c}"));
            }
        }
        assert_eq!(header, want, "{}", p.name);
        let rows: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
            .collect();
        assert!(rows.iter().all(|r| r.len() == header.len()));
        for (i, r) in rows.iter().enumerate() {
            assert!((r[0] - i as f64 * DT).abs() < 1e-9, "{}: row {i}", p.name);
            for a in 0..3 {
                let c = 1 + 4 * a;
                assert!(
                    r[c + 1].abs() <= VEL * 1.000_001,
                    "{}: row {i} {r:?}",
                    p.name
                );
                assert!(
                    r[c + 2].abs() <= ACC * 1.000_001,
                    "{}: row {i} {r:?}",
                    p.name
                );
                assert!(
                    r[c + 3].abs() <= JERK * 1.000_001,
                    "{}: row {i} {r:?}",
                    p.name
                );
            }
        }
        // The velocity column is the difference of the positions (and so on down).
        let mid = rows.len() / 2;
        let dv = (rows[mid][1] - rows[mid - 1][1]) / DT;
        assert!((rows[mid][2] - dv).abs() < 1e-6 * (1.0 + dv.abs()));
        let last = rows.last().unwrap();
        let end = program_end(&p.text);
        for a in 0..3 {
            assert!(
                (last[1 + 4 * a] - end[a]).abs() < 1e-9,
                "{}: ends at {last:?}, program at {end:?}",
                p.name
            );
        }
        // The trace lasts the planned time, to a few servo periods (the report rounds to
        // 1 ms; the trace ends on the period the interpolator reports the end).
        let t_end = last[0];
        assert!((t_end - planned).abs() <= 5.0 * DT, "{t_end} vs {planned}");
    }
}
