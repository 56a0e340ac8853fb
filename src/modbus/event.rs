//! Link events: a device's points went bad or came back, named by link, device, unit and
//! point. The pollers send them; the machine's event bridge publishes them on the control
//! socket (topic `io`) and logs them.

use hytask_hal::modbus::FaultKind;
use serde_json::{json, Value};

/// One device's change of health.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkEvent {
    /// `tcp:host:port` or `rtu:/dev/...`.
    pub link: String,
    /// The `[[io]]` device name.
    pub device: String,
    /// Modbus unit id.
    pub unit: u8,
    /// The points affected, by channel name.
    pub points: Vec<String>,
    /// The critical ones among them (their loss stops the machine).
    pub critical: Vec<String>,
    /// The fault, or `None` when the points are good again.
    pub fault: Option<FaultKind>,
}

impl LinkEvent {
    /// One line for logs and the event's `message`.
    pub fn message(&self) -> String {
        let what = match &self.fault {
            Some(f) => format!("{f}; points bad: {}", self.points.join(", ")),
            None => format!("points good again: {}", self.points.join(", ")),
        };
        let crit = if self.critical.is_empty() || self.fault.is_none() {
            String::new()
        } else {
            format!(
                " (critical: {}: the machine stops)",
                self.critical.join(", ")
            )
        };
        format!(
            "Modbus {} unit {} ({}): {what}{crit}",
            self.link, self.unit, self.device
        )
    }

    /// The event data published to subscribers.
    pub fn to_json(&self) -> Value {
        let (kind, exception) = match &self.fault {
            Some(FaultKind::Exception(c)) => ("exception", Some(*c)),
            Some(f) => (f.as_str(), None),
            None => ("recovered", None),
        };
        json!({
            "link": self.link,
            "device": self.device,
            "unit": self.unit,
            "points": self.points,
            "critical": self.critical,
            "kind": kind,
            "exception": exception,
            "message": self.message(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_name_link_unit_and_points() {
        let e = LinkEvent {
            link: "tcp:127.0.0.1:1502".into(),
            device: "panel".into(),
            unit: 3,
            points: vec!["estop".into(), "lamp".into()],
            critical: vec!["estop".into()],
            fault: Some(FaultKind::Exception(2)),
        };
        let m = e.message();
        assert!(m.contains("tcp:127.0.0.1:1502 unit 3 (panel)"), "{m}");
        assert!(m.contains("exception 2 (illegal data address)"), "{m}");
        assert!(m.contains("critical: estop"), "{m}");
        let j = e.to_json();
        assert_eq!(j["kind"], "exception");
        assert_eq!(j["exception"], 2);
        assert_eq!(j["points"][1], "lamp");
    }
}
