//! `hytask latency`: measures the wake-up latency of hytask's own periodic thread, the way
//! cyclictest measures its own.
//!
//! It runs the real [`PeriodicActivity`](crate::rt::activity::PeriodicActivity) (the same
//! thread setup, absolute-deadline sleep and statistics code the daemon's servo thread uses)
//! with an empty task group, and reports min/avg/p50/p90/p99/max of (actual wake-up −
//! deadline) plus the counts above 50 µs, 100 µs and half a period. `--histogram` prints the
//! 1 µs histogram in cyclictest's format (`%06d %06d` per bucket), so both tools' outputs can
//! be summarised by the same script (`benches/latency_vs_cyclictest.sh`).

use crate::rt::activity::{OverrunPolicy, PeriodicActivity, TaskGroup, ThreadSpec};
use crate::rt::stats::TimingStats;
use crate::rt::system;
use anyhow::Context;
use std::process::ExitCode;
use std::time::Duration;

/// Histogram range: 1 µs buckets up to this many µs (cyclictest's `--histogram` default
/// range is similar); later samples count as overflow.
const HISTOGRAM_US: usize = 20_000;

/// Arguments of `hytask latency`.
#[derive(Debug, clap::Args)]
pub struct LatencyArgs {
    /// Period of the measuring thread, in microseconds.
    #[arg(long, default_value_t = 1000)]
    pub period_us: u64,
    /// SCHED_FIFO priority (1..=99).
    #[arg(long, default_value_t = 80)]
    pub priority: i32,
    /// How long to measure: `30s`, `2m`, `500ms` or plain seconds.
    #[arg(long, default_value = "30s", value_parser = parse_duration)]
    pub duration: Duration,
    /// CPU to pin the thread to.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Also print the 1 µs histogram (`bucket_us count` lines, cyclictest format).
    #[arg(long)]
    pub histogram: bool,
}

/// Parses `30s`, `2m`, `500ms`, `1h` or a plain number of seconds.
pub fn parse_duration(s: &str) -> Result<Duration, String> {
    let s = s.trim();
    let (num, mult_ms) = if let Some(n) = s.strip_suffix("ms") {
        (n, 1)
    } else if let Some(n) = s.strip_suffix('s') {
        (n, 1_000)
    } else if let Some(n) = s.strip_suffix('m') {
        (n, 60_000)
    } else if let Some(n) = s.strip_suffix('h') {
        (n, 3_600_000)
    } else {
        (s, 1_000)
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("invalid duration '{s}' (use e.g. 30s, 2m, 500ms)"))?;
    if !(v.is_finite() && v > 0.0) {
        return Err(format!("duration must be positive: '{s}'"));
    }
    Ok(Duration::from_secs_f64(v * mult_ms as f64 / 1000.0))
}

/// Runs the subcommand.
pub fn run(args: LatencyArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(args.period_us > 0, "--period-us must be positive");
    if let Err(e) = system::lock_memory() {
        system::warn_not_realtime(&e.to_string());
    }
    let spec = ThreadSpec {
        name: "hytask-latency".into(),
        priority: args.priority,
        period_ns: args.period_us * 1_000,
        cpu: args.cpu,
    };
    let group = TaskGroup::new(
        spec,
        TimingStats::new(1_000, HISTOGRAM_US),
        OverrunPolicy { storm_threshold: 0 },
    );
    let activity = PeriodicActivity::spawn(group).context("starting the measuring thread")?;
    std::thread::sleep(args.duration);
    let info = activity.info().clone();
    let _ = activity.stop();

    let w = &info.stats.wakeup;
    let s = w.summary();
    let h = w.histogram();
    let us = |ns: u64| ns as f64 / 1000.0;
    let q = |p: f64| {
        h.quantile_ns(p)
            .map_or("overflow".to_owned(), |v| format!("{}", v / 1000))
    };
    println!(
        "# hytask latency: period {} us, priority {}, cpu {}, realtime {}",
        args.period_us,
        args.priority,
        args.cpu.map_or("any".to_owned(), |c| c.to_string()),
        info.realtime()
    );
    println!("samples: {}", s.count);
    println!("min_us: {:.1}", us(s.min_ns));
    println!("avg_us: {:.1}", us(s.avg_ns));
    println!("p50_us: {}", q(0.50));
    println!("p90_us: {}", q(0.90));
    println!("p99_us: {}", q(0.99));
    println!("max_us: {:.1}", us(s.max_ns));
    println!("over_50us: {}", h.count_at_or_above_ns(51_000));
    println!("over_100us: {}", h.count_at_or_above_ns(101_000));
    println!(
        "over_half_period: {}",
        h.count_at_or_above_ns(args.period_us * 1_000 / 2 + 1_000)
    );
    println!("overruns: {}", info.stats.overruns());
    if args.histogram {
        for (i, c) in h.counts().iter().enumerate() {
            if *c > 0 {
                println!("{i:06} {c:06}");
            }
        }
        println!("# Histogram Overflows: {:05}", h.overflow());
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_parse() {
        assert_eq!(parse_duration("30s"), Ok(Duration::from_secs(30)));
        assert_eq!(parse_duration("2m"), Ok(Duration::from_secs(120)));
        assert_eq!(parse_duration("500ms"), Ok(Duration::from_millis(500)));
        assert_eq!(parse_duration("1.5"), Ok(Duration::from_millis(1500)));
        assert!(parse_duration("-1s").is_err());
        assert!(parse_duration("abc").is_err());
    }
}
