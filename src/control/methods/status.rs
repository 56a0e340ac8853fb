//! `status`: a snapshot of the machine.
//!
//! ```text
//! → {"id":1,"method":"status"}
//! ← {"id":1,"result":{"machine":"sim-mill","mode":"idle","realtime":true,
//!     "axes":[{"name":"X","commanded":0.0,"actual":0.0,"velocity":0.0,"following_error":0.0,
//!              "max_following_error":0.0,"homed":true,"drive_state":"operation_enabled","fault":null}],
//!     "job":{"name":"part.ngc","state":"running","line":12,"total_lines":300,"progress":0.04,
//!            "planned_time_s":61.2,"elapsed_s":2.5,"distance_mm":1200.0,"distance_to_go_mm":1150.0,"reason":null},
//!     "overrides":{"feed":1.0,"rapid":1.0,"spindle":1.0},"spindle_rpm":12000.0,"faults":[],
//!     "threads":[{"name":"servo","period_us":1000,"priority":80,"cycles":5000,
//!                 "latency_us":{"min":3.1,"avg":12.0,"max":80.5},"exec_us":{...},"overruns":0}]}}
//! ```
//!
//! While a job waits at an M66 for its input, `job` also holds
//! `"input_wait":{"line":3,"input":"digital","index":1,"until":"rise"}` (`until`: the `L`
//! word as immediate, rise, fall, high or low); the member is absent otherwise.

use super::{no_params, ControlError};
use crate::machine::api::MachineApi;
use serde_json::Value;

pub(super) fn handle(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    no_params(&params)?;
    serde_json::to_value(m.status())
        .map_err(|e| ControlError::new(super::ErrorCode::Failed, e.to_string()))
}
