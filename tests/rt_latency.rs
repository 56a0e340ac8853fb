//! `hytask latency` runs the real periodic activity and prints cyclictest-like figures.
#![allow(clippy::unwrap_used)]

use std::process::Command;

#[test]
fn latency_tool_reports_percentiles_counts_and_histogram() {
    let out = Command::new(env!("CARGO_BIN_EXE_hytask"))
        .args([
            "latency",
            "--period-us",
            "1000",
            "--priority",
            "70",
            "--duration",
            "500ms",
            "--histogram",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let field = |k: &str| -> String {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{k}: ")))
            .unwrap_or_else(|| panic!("missing {k} in {text}"))
            .to_owned()
    };
    let samples: u64 = field("samples").parse().unwrap();
    // At most one sample per period (missed periods are skipped, never run back to back);
    // how many periods a loaded or stalled host lets through is not this test's business.
    assert!(
        (1..=520).contains(&samples),
        "{samples} cycles in 500 ms at 1 kHz"
    );
    for k in [
        "min_us",
        "avg_us",
        "p50_us",
        "p90_us",
        "p99_us",
        "max_us",
        "over_50us",
        "over_100us",
        "over_half_period",
    ] {
        field(k);
    }
    let hist: u64 = text
        .lines()
        .filter(|l| l.len() == 13 && l.as_bytes()[6] == b' ')
        .map(|l| l[7..].parse::<u64>().unwrap())
        .sum();
    let overflow: u64 = text
        .lines()
        .find_map(|l| l.strip_prefix("# Histogram Overflows: "))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    assert_eq!(
        hist + overflow,
        samples,
        "histogram accounts for every sample"
    );
}
