//! Key expressions of the bridge. One place, so that the exporter, remote peers, the tests and
//! the documentation agree:
//!
//! | key | what |
//! |---|---|
//! | `hytask/<machine>/tasks` | queryable: the task list, as `hytask tasks` prints it (JSON) |
//! | `hytask/<machine>/status` | publication (and queryable): the machine status, as `status` |
//! | `hytask/<machine>/events/<topic>` | publication: the control socket's event stream |
//! | `hytask/<machine>/control/<method>` | queryable: a control-socket method, params as payload |
//! | `hytask/<machine>/<task>/port/<object>` | publication (and queryable): a data object |
//! | `hytask/<machine>/<task>/event/<name>` | publication: a realtime event of the task |
//! | `hytask/<machine>/<task>/op/<name>` | queryable: a task operation, run as a command |
//! | `hytask/<machine>/alive` | liveliness token, while the exporter runs (`remote::alive_key`) |
//!
//! Names keep their dots (`axis.x.position_mm`); characters Zenoh reserves (`/ * $ # ?`)
//! and spaces become `_`.

/// Root of every key.
pub const ROOT: &str = "hytask";

/// `name` made usable as one key segment.
pub fn segment(name: &str) -> String {
    name.chars()
        .map(|c| match c {
            '/' | '*' | '$' | '#' | '?' | ' ' => '_',
            c => c,
        })
        .collect()
}

/// `hytask/<machine>`.
pub fn machine(machine: &str) -> String {
    format!("{ROOT}/{}", segment(machine))
}

/// The task list queryable.
pub fn tasks(m: &str) -> String {
    format!("{}/tasks", machine(m))
}

/// The status publication.
pub fn status(m: &str) -> String {
    format!("{}/status", machine(m))
}

/// A control-socket event topic.
pub fn news(m: &str, topic: &str) -> String {
    format!("{}/events/{}", machine(m), segment(topic))
}

/// A control method.
pub fn control(m: &str, method: &str) -> String {
    format!("{}/control/{}", machine(m), segment(method))
}

/// A task's data port.
pub fn port(m: &str, task: &str, object: &str) -> String {
    format!("{}/{}/port/{}", machine(m), segment(task), segment(object))
}

/// A task's event (`name` without the task prefix).
pub fn event(m: &str, task: &str, name: &str) -> String {
    format!("{}/{}/event/{}", machine(m), segment(task), segment(name))
}

/// A task's operation.
pub fn op(m: &str, task: &str, name: &str) -> String {
    format!("{}/{}/op/{}", machine(m), segment(task), segment(name))
}

/// What a key under `hytask/<machine>/` addresses, for the queryable that serves them all.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target<'a> {
    /// `tasks`.
    Tasks,
    /// `status`.
    Status,
    /// `control/<method>`.
    Control(&'a str),
    /// `<task>/port/<object>`.
    Port(&'a str, &'a str),
    /// `<task>/op/<name>`.
    Op(&'a str, &'a str),
}

/// Parses `key` under machine prefix `prefix` (from [`machine`]).
pub fn parse<'a>(prefix: &str, key: &'a str) -> Option<Target<'a>> {
    let rest = key.strip_prefix(prefix)?.strip_prefix('/')?;
    let parts: Vec<&str> = rest.split('/').collect();
    match parts.as_slice() {
        ["tasks"] => Some(Target::Tasks),
        ["status"] => Some(Target::Status),
        ["control", m] => Some(Target::Control(m)),
        [t, "port", o] => Some(Target::Port(t, o)),
        [t, "op", o] => Some(Target::Op(t, o)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_round_trip_through_the_parser() {
        let m = machine("mill 1");
        assert_eq!(m, "hytask/mill_1");
        assert_eq!(parse(&m, &tasks("mill 1")), Some(Target::Tasks));
        assert_eq!(parse(&m, &status("mill 1")), Some(Target::Status));
        assert_eq!(
            parse(&m, &control("mill 1", "job.run")),
            Some(Target::Control("job.run"))
        );
        assert_eq!(
            parse(&m, &port("mill 1", "axis.x", "axis.x.feedback")),
            Some(Target::Port("axis.x", "axis.x.feedback"))
        );
        assert_eq!(
            parse(&m, &op("mill 1", "spindle", "set_speed")),
            Some(Target::Op("spindle", "set_speed"))
        );
        assert_eq!(parse(&m, "hytask/other/tasks"), None);
        assert_eq!(parse(&m, "hytask/mill_1/a/b/c/d"), None);
    }

    #[test]
    fn reserved_characters_never_reach_a_key() {
        assert_eq!(segment("a/b*c$d#e?f g"), "a_b_c_d_e_f_g");
    }
}
