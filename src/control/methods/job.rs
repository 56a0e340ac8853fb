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
//! → {"id":7,"method":"job.optional_stop","params":{"on":true}}
//! ← {"id":7,"result":{"optional_stop":true}}   M1 now holds the job as M0 does
//! ```
//! A program stop (M0, M60, M1 with optional stop on) holds the job like a feed hold (mode and
//! `job.state` "holding"); `job.resume` (or `job.step`) goes on with the next line.
//! A job file must be a regular file (within `[control] jobs_dir` when set, at most
//! `[control] max_job_bytes`); a G-code error in a file without a G-code extension does not
//! quote the file (see `withhold_content`).
//! A job is interpreted and planned in full (soft limits included) by `job.load`, before any
//! motion. Progress arrives as `progress` events and in `status.job`. A client that
//! disconnects mid-job does not stop the job.
//! Preparing takes at most `[job] prepare_timeout_s` (code 4 past it); `job.abort`, any e-stop,
//! or the requesting client hanging up cancels a preparation in progress (code 2, naming why).

use super::{no_params, ok, parse, ControlError};
use crate::machine::api::{ApiError, JobSource, MachineApi};
use serde_json::Value;

pub(super) fn handle_load(m: &dyn MachineApi, params: Value) -> Result<Value, ControlError> {
    let src: JobSource = parse(params)?;
    if src.path.is_some() == src.text.is_some() {
        return Err(ControlError::params("give exactly one of 'path' or 'text'"));
    }
    let info = match (m.job_load(&src), &src.path) {
        (Err(ApiError::Gcode(message)), Some(path)) if !is_gcode_file(path) => {
            return Err(ControlError::new(
                super::ErrorCode::Gcode,
                withhold_content(path, &message),
            ))
        }
        (r, _) => r?,
    };
    serde_json::to_value(info)
        .map_err(|e| ControlError::new(super::ErrorCode::Failed, e.to_string()))
}

/// File name extensions of G-code programs (compared without case).
pub const GCODE_EXTENSIONS: &[&str] = &["ngc", "nc", "gcode", "gc", "g", "tap", "cnc", "ncc"];

/// Whether `path` (symbolic links resolved) names a G-code program by its extension.
fn is_gcode_file(path: &str) -> bool {
    let real = std::fs::canonicalize(path).unwrap_or_else(|_| path.into());
    real.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| GCODE_EXTENSIONS.iter().any(|g| g.eq_ignore_ascii_case(e)))
}

/// The interpreter's messages quote the source (a bad character, a word, a comment). For a
/// file that is not a G-code program, e.g. `/etc/shadow` loaded by mistake or on purpose,
/// that would hand out its content: keep where the error is (`file:line:col`), drop what it
/// says.
fn withhold_content(path: &str, message: &str) -> String {
    let position = message
        .strip_prefix(path)
        .and_then(|rest| rest.strip_prefix(':'))
        .and_then(|rest| {
            let mut parts = rest.splitn(3, ':');
            let line = parts.next()?.parse::<u64>().ok()?;
            let col = parts.next()?.parse::<u64>().ok()?;
            Some(format!(":{line}:{col}"))
        })
        .unwrap_or_default();
    format!(
        "{path}{position}: not a G-code program (the interpreter's message is withheld because it \
         would quote the file; G-code files end in .{})",
        GCODE_EXTENSIONS.join(", .")
    )
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

/// Parameters of `job.optional_stop`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct OptionalStop {
    on: bool,
}

pub(super) fn handle_optional_stop(
    m: &dyn MachineApi,
    params: Value,
) -> Result<Value, ControlError> {
    let p: OptionalStop = parse(params)?;
    let on = m.set_optional_stop(p.on)?;
    Ok(serde_json::json!({ "optional_stop": on }))
}

simple!(handle_run, job_run);
simple!(handle_pause, job_pause);
simple!(handle_resume, job_resume);
simple!(handle_abort, job_abort);
simple!(handle_step, job_step);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_withheld_message_keeps_the_position_and_drops_the_quote() {
        let m = withhold_content(
            "/etc/shadow",
            "/etc/shadow:18:1: Bad character 'r' used in root:$6$secret",
        );
        assert!(
            m.starts_with("/etc/shadow:18:1: not a G-code program"),
            "{m}"
        );
        assert!(!m.contains("secret") && !m.contains("'r'"), "{m}");
        let m = withhold_content("/etc/x", "other.ngc:1:1: quoted 'x'");
        assert!(m.starts_with("/etc/x: not a G-code program"), "{m}");
    }

    #[test]
    fn gcode_files_are_known_by_their_extension() {
        assert!(is_gcode_file("/nonexistent/part.NGC"));
        assert!(is_gcode_file("job.tap"));
        assert!(!is_gcode_file("/etc/shadow"));
        assert!(!is_gcode_file("/nonexistent/notes.txt"));
    }
}
