//! JSON forms of the servo tasks' ports and events, for exporters (the Zenoh bridge):
//! what a remote peer needs of each (positions, states, lines), with enums by name.
//!
//! Why views and not `Serialize`: these `Copy` structs carry planner and drive types
//! (`AuxItem`, `DriveState`, ...) whose wire form is nobody's business outside the process;
//! a view exports what is meaningful and stays stable when the internals change.

use super::{
    AxisFeedback, FaultEvent, Inputs, JobNews, ModeEvent, MonitorSnapshot, Outputs, Setpoints,
};
use crate::rt::json::{register_data_view, register_event_view, JsonView};
use serde_json::{json, Value};

/// Registers every view below (idempotent; called when a machine is deployed).
pub fn register() {
    register_data_view::<AxisFeedback>();
    register_data_view::<Setpoints>();
    register_data_view::<Inputs>();
    register_data_view::<Outputs>();
    register_data_view::<MonitorSnapshot>();
    register_event_view::<FaultEvent>();
    register_event_view::<ModeEvent>();
    register_event_view::<JobNews>();
}

fn name(v: impl std::fmt::Debug) -> String {
    let s = format!("{v:?}");
    // Variants with fields: their name only (`Failed { .. }` → `Failed`).
    s.split([' ', '(', '{'])
        .next()
        .unwrap_or_default()
        .to_owned()
}

impl JsonView for AxisFeedback {
    fn json(&self) -> Value {
        json!({
            "actual": self.actual,
            "velocity": self.velocity,
            "state": name(self.state),
            "fault": self.fault,
            "homed": self.homed,
            "homing": self.homing,
            "limit_switch": self.limit_switch,
            "valid": self.valid,
        })
    }
}

impl JsonView for Setpoints {
    fn json(&self) -> Value {
        json!({
            "pose_mm": self.pose_mm,
            "joints": self.joints,
            "line": self.line,
            "state": name(self.state),
            "distance_to_go_mm": self.distance_to_go_mm,
            "scale": self.scale,
            "job": self.job,
        })
    }
}

impl JsonView for Inputs {
    fn json(&self) -> Value {
        json!({"digital": self.digital, "analog": self.analog, "link_ok": self.link_ok})
    }
}

impl JsonView for Outputs {
    fn json(&self) -> Value {
        json!({"digital": self.digital, "analog": self.analog})
    }
}

impl JsonView for MonitorSnapshot {
    fn json(&self) -> Value {
        json!({
            "following_error": self.following_error,
            "max_following_error": self.max_following_error,
        })
    }
}

impl JsonView for FaultEvent {
    fn json(&self) -> Value {
        json!({"trip": format!("{:?}", self.trip), "line": self.line})
    }
}

impl JsonView for ModeEvent {
    fn json(&self) -> Value {
        json!({"mode": self.mode})
    }
}

impl JsonView for JobNews {
    fn json(&self) -> Value {
        json!({"job": self.job, "event": name(self.event), "detail": format!("{:?}", self.event)})
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enum_names_drop_their_fields() {
        let n = JobNews {
            job: 3,
            event: super::super::JobEvent::Finished { line: 7 },
            cycle: 12,
        };
        let v = n.json();
        assert_eq!(v["event"], "Finished");
        assert_eq!(v["job"], 3);
        assert!(v["detail"].as_str().unwrap().contains("line: 7"));
    }
}
