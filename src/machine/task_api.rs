//! The operator API's view of realtime tasks, shared by every deployment served on the
//! control socket (the machine, the pick-and-place cell): task interfaces as data, thread
//! timing, and calling an operation by name with JSON arguments.

use super::api::{ApiError, MinAvgMax, OperationInfo, TaskInfo, ThreadTiming};
use crate::rt::activity::ThreadInfo;
use crate::rt::prelude::{ArgValue, CommandHandle, CommandStatus};
use serde_json::{json, Value};
use std::sync::Arc;
use std::time::Duration;

fn us(ns: u64) -> f64 {
    ns as f64 / 1000.0
}

/// Timing of each realtime thread, for `status`.
pub fn thread_timings(threads: &[Arc<ThreadInfo>]) -> Vec<ThreadTiming> {
    threads
        .iter()
        .map(|t| {
            let s = t.stats.summary();
            ThreadTiming {
                name: t.spec.name.clone(),
                period_us: t.spec.period_ns / 1000,
                priority: t.spec.priority,
                cycles: s.wakeup.count,
                latency_us: MinAvgMax {
                    min: us(s.wakeup.min_ns),
                    avg: us(s.wakeup.avg_ns),
                    max: us(s.wakeup.max_ns),
                },
                exec_us: MinAvgMax {
                    min: us(s.exec.min_ns),
                    avg: us(s.exec.avg_ns),
                    max: us(s.exec.max_ns),
                },
                overruns: s.overruns,
            }
        })
        .collect()
}

/// The tasks of a runtime kept as `Mutex<Option<Runtime>>` (`None` once stopped: no tasks), as
/// the cell daemon and the peer host keep theirs. Why here: both answer `tasks` this way; a
/// poisoned lock still answers (a panicked holder must not hide the tasks).
pub fn runtime_task_infos(
    runtime: &std::sync::Mutex<Option<crate::rt::deploy::Runtime>>,
) -> Vec<TaskInfo> {
    runtime
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .as_ref()
        .map(|rt| task_infos(rt.tasks()))
        .unwrap_or_default()
}

/// Every task with its interface, for `tasks`.
pub fn task_infos(tasks: &[crate::rt::runner::TaskInfo]) -> Vec<TaskInfo> {
    tasks
        .iter()
        .map(|t| {
            let i = t.interface();
            let timing = t.timing();
            TaskInfo {
                exec_us: MinAvgMax {
                    min: us(timing.exec.min_ns),
                    avg: us(timing.exec.avg_ns),
                    max: us(timing.exec.max_ns),
                },
                name: t.name().to_string(),
                state: format!("{:?}", t.state()).to_lowercase(),
                thread: t.thread().to_string(),
                operations: i
                    .operations
                    .iter()
                    .map(|o| OperationInfo {
                        name: o.name.into(),
                        doc: o.doc.into(),
                        params: o
                            .params
                            .iter()
                            .map(|p| format!("{}: {:?}", p.name, p.ty).to_lowercase())
                            .collect(),
                    })
                    .collect(),
                events: i.emits.iter().map(|e| e.name.clone()).collect(),
                ports: i
                    .ports
                    .iter()
                    .map(|p| {
                        use crate::rt::interface::{PortDirection as D, PortKind as K};
                        let dir = match (p.direction, p.kind) {
                            (D::Input, K::Data) => "in",
                            (D::Output, K::Data) => "out",
                            (D::Input, K::Buffer) => "in (buffer)",
                            (D::Output, K::Buffer) => "out (buffer)",
                        };
                        format!("{dir} {}", p.object)
                    })
                    .collect(),
            }
        })
        .collect()
}

/// Sends `task.operation(args)`: `args` is null, an array in parameter order, an object by
/// parameter name, or a single value.
pub fn send_call(
    tasks: &[crate::rt::runner::TaskInfo],
    task: &str,
    operation: &str,
    args: &Value,
) -> Result<CommandHandle, ApiError> {
    let t = tasks
        .iter()
        .find(|t| t.name() == task)
        .ok_or_else(|| ApiError::InvalidParams(format!("no task '{task}'")))?;
    let op = t
        .commands()
        .operations()
        .iter()
        .find(|o| o.name == operation)
        .ok_or_else(|| {
            ApiError::InvalidParams(format!("task '{task}' has no operation '{operation}'"))
        })?;
    let values: Vec<Value> = match args {
        Value::Null => Vec::new(),
        Value::Array(a) => a.clone(),
        Value::Object(o) => op
            .params
            .iter()
            .map(|p| o.get(p.name).cloned().unwrap_or(Value::Null))
            .collect(),
        other => vec![other.clone()],
    };
    let parsed: Vec<ArgValue> = values
        .into_iter()
        .map(serde_json::from_value)
        .collect::<Result<_, _>>()
        .map_err(|e| ApiError::InvalidParams(format!("arguments: {e}")))?;
    t.commands()
        .send_args(operation, &parsed)
        .map_err(|e| ApiError::InvalidParams(e.to_string()))
}

/// Waits (up to 5 s) for the command to be final and words the reply: `done`, or
/// `accepted` for an operation still running when the wait ends.
pub fn call_reply(handle: &CommandHandle, task: &str) -> Result<Value, ApiError> {
    match handle.wait(Duration::from_secs(5)) {
        CommandStatus::Rejected(r) => Err(ApiError::Rejected(r.to_string())),
        CommandStatus::Failed(why) => Err(ApiError::Failed(why.into())),
        CommandStatus::Done => Ok(json!({"status": "done"})),
        CommandStatus::Accepted => Ok(json!({"status": "accepted"})),
        CommandStatus::Pending => Err(ApiError::Timeout(format!(
            "task '{task}' did not take the command"
        ))),
    }
}
