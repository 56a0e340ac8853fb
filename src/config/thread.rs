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
