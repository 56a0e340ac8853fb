//! The job family: `job.load`, `job.run`, `job.pause`, `job.resume`, `job.abort`, `job.step`.
//!
//! ```text
//! → {"id":1,"method":"job.load","params":{"path":"/srv/jobs/part.ngc"}}
//! → {"id":1,"method":"job.load","params":{"text":"G21\nG1 X10 F600\nM2\n","name":"inline"}}
//! ← {"id":1,"result":{"name":"part.ngc","lines":300,"commands":512,"planned_time_s":61.2,"distance_mm":1200.0}}
//! ← {"id":1,"error":{"code":3,"message":"part.ngc:17:5: ..."}}    (refused as a whole)
//! → {"id":2,"method":"job.run"}     ← {"id":2,"result":{"ok":true}}
//! → {"id":3,"method":"job.pause"}   feed hold: decelerate to a stop on the path
//! → {"id":4,"method":"job.resume"}
//! → {"id":5,"method":"job.step"}    hold when the next source line begins (resumes a hold)
//! → {"id":6,"method":"job.abort"}   controlled stop, the rest of the job is dropped
//! ```
//! A job is interpreted and planned in full (soft limits included) by `job.load`, before any
//! motion. Progress arrives as `progress` events and in `status.job`. A client that
//! disconnects mid-job does not stop the job.

use super::{no_params, ok, parse, ControlError};
use crate::machine::api::{JobSource, MachineApi};
use serde_json::Value;

pub(super) fn handle_load(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let src: JobSource = parse(params)?;
    if src.path.is_some() == src.text.is_some() {
        return Err(ControlError::params("give exactly one of 'path' or 'text'"));
    }
    let info = m.job_load(&src)?;
    serde_json::to_value(info)
        .map_err(|e| ControlError::new(super::ErrorCode::Failed, e.to_string()))
}

macro_rules! simple {
    ($name:ident, $call:ident) => {
        pub(super) fn $name(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
            no_params(&params)?;
            m.$call()?;
            Ok(ok())
        }
    };
}

simple!(handle_run, job_run);
simple!(handle_pause, job_pause);
simple!(handle_resume, job_resume);
simple!(handle_abort, job_abort);
simple!(handle_step, job_step);
