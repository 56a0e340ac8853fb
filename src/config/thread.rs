//! `[[thread]]`: the realtime threads, one per (period, priority).

use super::error::Issues;
use serde::{Deserialize, Serialize};

/// Shortest accepted period: below this, Linux wake-up latency dominates the cycle.
pub const MIN_PERIOD_US: u32 = 50;
/// Longest accepted period (1 s): slower work belongs on a non-realtime thread.
pub const MAX_PERIOD_US: u32 = 1_000_000;

/// `[[thread]]`: one periodic realtime thread. Periodic tasks name the thread they run on;
/// tasks on one thread run in a fixed order each cycle (the Orocos rule), so data between
/// them needs no locks.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ThreadConfig {
    /// Name tasks use to pick this thread (e.g. `servo`).
    pub name: String,
    /// Period in microseconds (50 ..= 1 000 000).
    pub period_us: u32,
    /// `SCHED_FIFO` priority (1 ..= 99). A shorter period must not have a lower priority
    /// (rate-monotonic order), so the fastest loop is never delayed by a slower one.
    pub priority: u8,
    /// CPU to pin the thread to (isolate it with `isolcpus` for best latency); unpinned if
    /// absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu: Option<u16>,
    /// Which clock the thread runs on: `realtime` (default) or `simulated`, for tests of
    /// behaviour through the real daemon: time then advances one period per cycle whatever
    /// the wall clock does (cycles never skipped, no overrun accounting, no `SCHED_FIFO`), so
    /// a loaded host cannot change what the machine does, only how fast. All threads of a
    /// machine use the same clock.
    #[serde(default, skip_serializing_if = "ThreadClock::is_realtime")]
    pub clock: ThreadClock,
    /// With `clock = "simulated"`: simulated seconds per wall-clock second (1: real time);
    /// absent or 0: cycles back to back, as fast as the CPU allows. What the machine does no
    /// longer depends on the host's load, with one exception: a job longer than the segment
    /// queue (4096 items) is topped up by its feeder thread in wall time, so at a high speed
    /// on a loaded host the queue can run dry before the job's end.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sim_speed: Option<u32>,
}

/// `[[thread]] clock`: what a thread's time is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ThreadClock {
    /// `CLOCK_MONOTONIC`: absolute-deadline sleeps, `SCHED_FIFO`, overrun accounting.
    #[default]
    Realtime,
    /// Simulated time, one period per cycle (tests).
    Simulated,
}

impl ThreadClock {
    /// True for the default real-time clock.
    pub fn is_realtime(&self) -> bool {
        *self == ThreadClock::Realtime
    }

    /// The config spelling.
    pub fn as_str(&self) -> &'static str {
        match self {
            ThreadClock::Realtime => "realtime",
            ThreadClock::Simulated => "simulated",
        }
    }
}

impl ThreadConfig {
    /// The key prefix used in messages: `thread[0] (servo)`.
    pub fn key(index: usize, name: &str) -> String {
        format!("thread[{index}] ({name})")
    }
}

/// Checks each thread, unique names, and the rate-monotonic order between threads.
pub(super) fn validate(threads: &[ThreadConfig], issues: &mut Issues) {
    if threads.is_empty() {
        issues.push(
            "thread",
            "at least one [[thread]] is required (the servo thread)",
        );
    }
    for (i, t) in threads.iter().enumerate() {
        let key = ThreadConfig::key(i, &t.name);
        issues.name(format!("{key}.name"), &t.name);
        issues.in_range(
            format!("{key}.period_us"),
            t.period_us,
            MIN_PERIOD_US,
            MAX_PERIOD_US,
        );
        issues.in_range(format!("{key}.priority"), t.priority, 1, 99);
        if let Some(cpu) = t.cpu {
            issues.in_range(format!("{key}.cpu"), cpu, 0, 1023);
        }
        if t.sim_speed.is_some() && t.clock.is_realtime() {
            issues.push(
                format!("{key}.sim_speed"),
                "only applies with clock = \"simulated\"",
            );
        }
        if let Some(first) = threads.first().filter(|f| f.clock != t.clock) {
            issues.push(
                format!("{key}.clock"),
                format!(
                    "\"{}\" differs from {}'s \"{}\": all threads of a machine share one clock",
                    t.clock.as_str(),
                    ThreadConfig::key(0, &first.name),
                    first.clock.as_str()
                ),
            );
        }
        for (j, earlier) in threads[..i].iter().enumerate() {
            let other = ThreadConfig::key(j, &earlier.name);
            if earlier.name == t.name {
                issues.push(format!("{key}.name"), format!("duplicate of {other}"));
            }
            if earlier.period_us == t.period_us && earlier.priority == t.priority {
                issues.push(
                    format!("{key}.priority"),
                    format!(
                        "same period and priority as {other}: one thread per (period, priority); merge them"
                    ),
                );
            }
            let (fast, slow, fast_key, slow_key) = if t.period_us < earlier.period_us {
                (t, earlier, &key, &other)
            } else {
                (earlier, t, &other, &key)
            };
            // Out-of-range priorities are reported above; comparing them would only repeat it.
            let both_valid = [fast.priority, slow.priority]
                .iter()
                .all(|p| (1..=99).contains(p));
            if both_valid && fast.period_us < slow.period_us && fast.priority < slow.priority {
                issues.push(
                    format!("{fast_key}.priority"),
                    format!(
                        "{} is lower than {slow_key}'s {} although its period ({} us) is shorter than {} us; shorter periods need higher (or equal) priority",
                        fast.priority, slow.priority, fast.period_us, slow.period_us
                    ),
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{parse, BUILTIN_SIM_TOML};

    /// The built-in mill with `extra` lines added to its first and second `[[thread]]`.
    fn with_thread_keys(first: &str, second: &str) -> Result<Vec<ThreadConfig>, String> {
        let mut parts = BUILTIN_SIM_TOML.splitn(3, "[[thread]]\n");
        let text = format!(
            "{}[[thread]]\n{first}{}[[thread]]\n{second}{}",
            parts.next().unwrap_or_default(),
            parts.next().unwrap_or_default(),
            parts.next().unwrap_or_default()
        );
        parse(&text, "t")
            .map(|c| c.threads)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn the_clock_is_realtime_unless_every_thread_says_simulated() {
        let t = with_thread_keys("", "").unwrap();
        assert!(t.iter().all(|t| t.clock == ThreadClock::Realtime));
        let sim = "clock = \"simulated\"\nsim_speed = 4\n";
        let t = with_thread_keys(sim, "clock = \"simulated\"\n").unwrap();
        assert_eq!(t[0].clock, ThreadClock::Simulated);
        assert_eq!((t[0].sim_speed, t[1].sim_speed), (Some(4), None));
        let e = with_thread_keys(sim, "").unwrap_err();
        assert!(
            e.contains("thread[1] (plc).clock") && e.contains("share one clock"),
            "{e}"
        );
        let e = with_thread_keys("sim_speed = 2\n", "").unwrap_err();
        assert!(e.contains("thread[0] (servo).sim_speed"), "{e}");
        let e = with_thread_keys("clock = \"fast\"\n", "").unwrap_err();
        assert!(e.contains("clock"), "{e}");
    }
}
