//! Link faults, named by link, unit and point, and the reconnect backoff.

use std::fmt;
use std::time::Duration;

/// What went wrong on a transaction.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FaultKind {
    /// No (complete) answer within the timeout.
    Timeout,
    /// The device answered with an exception code (it is there but refuses).
    Exception(u8),
    /// The connection could not be made or was dropped (transport error).
    Disconnected(String),
    /// The answer did not fit the request (wrong unit, function, length, CRC).
    Protocol(String),
}

impl FaultKind {
    /// Short name for events: `timeout`, `exception`, `disconnected`, `protocol`.
    pub fn as_str(&self) -> &'static str {
        match self {
            FaultKind::Timeout => "timeout",
            FaultKind::Exception(_) => "exception",
            FaultKind::Disconnected(_) => "disconnected",
            FaultKind::Protocol(_) => "protocol",
        }
    }
}

/// The standard name of exception `code` (Modbus application protocol, 7).
pub fn exception_name(code: u8) -> &'static str {
    match code {
        1 => "illegal function",
        2 => "illegal data address",
        3 => "illegal data value",
        4 => "server device failure",
        5 => "acknowledge",
        6 => "server device busy",
        8 => "memory parity error",
        10 => "gateway path unavailable",
        11 => "gateway target device failed to respond",
        _ => "unknown exception",
    }
}

impl fmt::Display for FaultKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FaultKind::Timeout => f.write_str("timeout"),
            FaultKind::Exception(c) => write!(f, "exception {c} ({})", exception_name(*c)),
            FaultKind::Disconnected(m) => write!(f, "connection lost: {m}"),
            FaultKind::Protocol(m) => write!(f, "bad response: {m}"),
        }
    }
}

/// Exponential reconnect backoff: `min`, doubling up to `max`, back to `min` on success.
#[derive(Debug, Clone)]
pub struct Backoff {
    min: Duration,
    max: Duration,
    next: Duration,
}

impl Backoff {
    /// A backoff between `min` and `max`.
    pub fn new(min: Duration, max: Duration) -> Backoff {
        Backoff {
            min,
            max: max.max(min),
            next: min,
        }
    }

    /// The delay before the next attempt; doubles the one after.
    pub fn next_delay(&mut self) -> Duration {
        let d = self.next;
        self.next = (self.next * 2).min(self.max);
        d
    }

    /// A successful connection: the next failure waits `min` again.
    pub fn reset(&mut self) {
        self.next = self.min;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_up_to_the_limit_and_resets() {
        let ms = Duration::from_millis;
        let mut b = Backoff::new(ms(100), ms(1000));
        let seq: Vec<_> = (0..6).map(|_| b.next_delay()).collect();
        assert_eq!(
            seq,
            [ms(100), ms(200), ms(400), ms(800), ms(1000), ms(1000)]
        );
        b.reset();
        assert_eq!(b.next_delay(), ms(100));
    }

    #[test]
    fn faults_read_distinctly() {
        assert_eq!(
            FaultKind::Exception(2).to_string(),
            "exception 2 (illegal data address)"
        );
        assert_eq!(FaultKind::Timeout.as_str(), "timeout");
        assert_ne!(
            FaultKind::Exception(4).as_str(),
            FaultKind::Disconnected("reset".into()).as_str()
        );
    }
}
