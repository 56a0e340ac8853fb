//! The small sections: `[tool_table]`, `[control]`, `[logging]`, `[motion]`, `[safety]`.

use super::error::Issues;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// `[tool_table]`: where tool lengths and diameters are kept.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ToolTableConfig {
    /// Tool table file (LinuxCNC `.tbl` format); a relative path is relative to the
    /// configuration file's directory (resolved by [`load`](super::load)).
    pub path: PathBuf,
}

/// `[control]`: the control socket (JSON lines over a Unix socket), who may use it and what
/// a request may cost the daemon.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ControlConfig {
    /// Path of the Unix socket. Default: `/run/hytask/control.sock` for root (a system
    /// daemon), `$XDG_RUNTIME_DIR/hytask/control.sock` for another user: never a directory
    /// such as /tmp where another user could take the path first.
    #[serde(default = "default_socket_path")]
    pub socket_path: PathBuf,
    /// File mode of the socket, as an octal string (`"0660"`). Whoever can write the
    /// socket can reach the machine, so keep "other" bits off.
    #[serde(default = "default_mode")]
    pub mode: FileMode,
    /// Group that owns the socket (operators are members); the daemon's group if absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group: Option<String>,
    /// Directory that `job.load` may read jobs from (absolute). A path outside it, after
    /// symbolic links are resolved, is refused without being opened. Unset: any regular
    /// file the daemon can read (a personal daemon); set it for a shared machine.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jobs_dir: Option<PathBuf>,
    /// Largest job file `job.load` reads, bytes (default 256 MiB).
    #[serde(default = "default_max_job_bytes")]
    pub max_job_bytes: u64,
    /// A connection that sends no request and receives no event for this long is closed,
    /// seconds (0 = never). Frees the slots of clients that connect and go quiet.
    #[serde(default = "default_idle_timeout_s")]
    pub idle_timeout_s: u64,
    /// Connections served at once. Beyond it a connection is still accepted, but answers
    /// only `estop` and is then closed, so that an e-stop always gets through.
    #[serde(default = "default_max_clients")]
    pub max_clients: u32,
    /// Bytes of unfinished request lines buffered across all clients. Each client may
    /// buffer 64 KiB regardless; beyond that it draws on this shared budget and is
    /// disconnected, with an error reply, when the budget is spent.
    #[serde(default = "default_max_buffered_bytes")]
    pub max_buffered_bytes: u64,
    /// Users and groups that may move or change the machine. When `operators` or
    /// `observers` is set, roles apply: root and the daemon's own user are always
    /// operators, everyone else is what the lists (or `unlisted`) say. When neither is
    /// set, everyone who can open the socket is an operator (its mode and group decide).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operators: Option<Principals>,
    /// Users and groups that may only watch: `status`, `subscribe`, `unsubscribe`,
    /// `tasks`, and `estop` (stopping is never refused).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub observers: Option<Principals>,
    /// Role of a user that is in neither list, when roles apply: `"observer"` (default) or
    /// `"none"` (the connection is refused).
    #[serde(default)]
    pub unlisted: UnlistedRole,
}

/// A set of users and groups, by name.
#[derive(Debug, Clone, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Principals {
    /// User names.
    #[serde(default)]
    pub users: Vec<String>,
    /// Group names: primary or supplementary membership counts.
    #[serde(default)]
    pub groups: Vec<String>,
}

/// What a user in neither `operators` nor `observers` may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum UnlistedRole {
    /// Watch only.
    #[default]
    Observer,
    /// Nothing: the connection is refused.
    None,
}

/// The default socket path for the current user: root runs the system daemon in
/// /run/hytask; another user's daemon lives in its private runtime directory.
pub fn default_socket_path() -> PathBuf {
    let uid = nix::unistd::geteuid();
    if uid.is_root() {
        return PathBuf::from("/run/hytask/control.sock");
    }
    match std::env::var_os("XDG_RUNTIME_DIR") {
        Some(d) if !d.is_empty() => PathBuf::from(d).join("hytask/control.sock"),
        _ => PathBuf::from(format!("/run/user/{uid}/hytask/control.sock")),
    }
}

fn default_max_job_bytes() -> u64 {
    256 * 1024 * 1024
}
fn default_idle_timeout_s() -> u64 {
    300
}
fn default_max_clients() -> u32 {
    512
}
fn default_max_buffered_bytes() -> u64 {
    64 * 1024 * 1024
}

fn default_mode() -> FileMode {
    FileMode(0o660)
}

/// A Unix file mode (permission bits only, at most `0o777`), written in the file as an
/// octal string such as `"0660"` so that it reads the way `chmod` does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(try_from = "String", into = "String")]
pub struct FileMode(pub u32);

impl TryFrom<String> for FileMode {
    type Error = String;

    fn try_from(s: String) -> Result<Self, Self::Error> {
        let digits = s.strip_prefix("0o").unwrap_or(&s);
        match u32::from_str_radix(digits, 8) {
            Ok(m) if m <= 0o777 && !digits.is_empty() => Ok(FileMode(m)),
            _ => Err(format!(
                "expected an octal file mode such as \"0660\" (at most 0777), got {s:?}"
            )),
        }
    }
}

impl From<FileMode> for String {
    fn from(m: FileMode) -> String {
        format!("{:04o}", m.0)
    }
}

impl Default for ControlConfig {
    fn default() -> Self {
        ControlConfig {
            socket_path: default_socket_path(),
            mode: default_mode(),
            group: None,
            jobs_dir: None,
            max_job_bytes: default_max_job_bytes(),
            idle_timeout_s: default_idle_timeout_s(),
            max_clients: default_max_clients(),
            max_buffered_bytes: default_max_buffered_bytes(),
            operators: None,
            observers: None,
            unlisted: UnlistedRole::default(),
        }
    }
}

/// `[logging]`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LoggingConfig {
    /// Least severe level that is logged.
    #[serde(default)]
    pub level: LogLevel,
}

/// Log levels, least verbose first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
#[allow(missing_docs)] // The usual meanings.
pub enum LogLevel {
    Error,
    Warn,
    #[default]
    Info,
    Debug,
    Trace,
}

impl LogLevel {
    /// The level as a `tracing` filter directive.
    pub fn as_str(self) -> &'static str {
        match self {
            LogLevel::Error => "error",
            LogLevel::Warn => "warn",
            LogLevel::Info => "info",
            LogLevel::Debug => "debug",
            LogLevel::Trace => "trace",
        }
    }
}

/// `[motion]`: planner and interpolator settings.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MotionConfig {
    /// The `[[thread]]` the interpolator and drives run on: its period is the servo period
    /// the planner samples segments for.
    #[serde(default = "default_servo_thread")]
    pub servo_thread: String,
    /// How many moves the planner looks ahead (2 ..= 10000): more allows higher speed
    /// through many short segments, at the cost of latency to a feed hold.
    #[serde(default = "default_lookahead")]
    pub lookahead: u32,
    /// Default path blending tolerance in mm for `G64` without `P` (>= 0; 0 = exact stop).
    #[serde(default = "default_g64_tolerance")]
    pub g64_tolerance: f64,
    /// Rapid (G0) speed as a fraction of the axes' maximum velocity (0 < x <= 1).
    #[serde(default = "default_rapid_override")]
    pub rapid_override: f64,
    /// Highest feed override the operator may set (1 ..= 10).
    #[serde(default = "default_max_feed_override")]
    pub max_feed_override: f64,
    /// Digital input of the touch probe for G38.2–G38.5 (active = the stylus touches). A
    /// machine without one refuses programs that probe when they reach the probe.
    #[serde(default)]
    pub probe_input: Option<String>,
    /// Fit runs of short, gently turning XY feed chords into tangent-continuous arcs within
    /// the G64 tolerance (`motion::arcfit`; Cartesian machines only). Off plans every chord
    /// with its own corner blend: for comparing plans, or for a machine whose programs must
    /// run chord by chord.
    #[serde(default = "default_fit_arcs")]
    pub fit_arcs: bool,
    /// Plan runs of tangent moves that nothing between them slows as one speed profile
    /// (`motion::span`): the acceleration carries across the moves' ends. Off gives every
    /// move its own speed-up and slow-down: for comparing plans.
    #[serde(default = "default_fit_arcs")]
    pub spans: bool,
}

fn default_servo_thread() -> String {
    "servo".into()
}
fn default_lookahead() -> u32 {
    200
}
fn default_g64_tolerance() -> f64 {
    0.01
}
fn default_rapid_override() -> f64 {
    1.0
}
fn default_max_feed_override() -> f64 {
    2.0
}
fn default_fit_arcs() -> bool {
    true
}

impl Default for MotionConfig {
    fn default() -> Self {
        MotionConfig {
            servo_thread: default_servo_thread(),
            lookahead: default_lookahead(),
            g64_tolerance: default_g64_tolerance(),
            rapid_override: default_rapid_override(),
            max_feed_override: default_max_feed_override(),
            probe_input: None,
            fit_arcs: default_fit_arcs(),
            spans: default_fit_arcs(),
        }
    }
}

/// `[safety]`: what stops the machine.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SafetyConfig {
    /// Name of the digital input of the e-stop chain (active = e-stop pressed; use
    /// `invert` on the channel for a normally-closed chain). Required: a machine without
    /// an e-stop does not start.
    pub estop_input: String,
    /// Consecutive overruns of the servo thread that count as a storm (>= 1): the machine
    /// then stops under control and reports a fault. A single overrun is counted and shown
    /// in the thread statistics (the missed periods are skipped, not run back to back); a
    /// storm means the timing can no longer be trusted. 3 suits a PREEMPT_RT machine; a
    /// simulated machine on a desktop or a VM, whose host may deschedule it for several
    /// periods, needs more.
    #[serde(default = "default_overrun_storm_count")]
    pub overrun_storm_count: u32,
}

fn default_overrun_storm_count() -> u32 {
    3
}

impl ToolTableConfig {
    pub(super) fn validate(&self, issues: &mut Issues) {
        if self.path.as_os_str().is_empty() {
            issues.push("tool_table.path", "must not be empty");
        }
    }
}

impl ControlConfig {
    pub(super) fn validate(&self, issues: &mut Issues) {
        if self.socket_path.as_os_str().is_empty() {
            issues.push("control.socket_path", "must not be empty");
        }
        if self.mode.0 & 0o007 != 0 {
            issues.push(
                "control.mode",
                format!(
                    "{:04o} gives other users access to the machine; clear the last digit",
                    self.mode.0
                ),
            );
        }
        if let Some(g) = &self.group {
            issues.name("control.group", g);
        }
        if let Some(d) = &self.jobs_dir {
            if !d.is_absolute() {
                issues.push(
                    "control.jobs_dir",
                    format!("must be an absolute path, got {}", d.display()),
                );
            }
        }
        issues.in_range("control.max_job_bytes", self.max_job_bytes, 1, u64::MAX);
        issues.in_range("control.max_clients", self.max_clients, 1, 65_536);
        issues.in_range(
            "control.max_buffered_bytes",
            self.max_buffered_bytes,
            1024 * 1024,
            u64::MAX,
        );
        for (list, p) in [
            ("operators", &self.operators),
            ("observers", &self.observers),
        ] {
            let Some(p) = p else { continue };
            for (kind, names) in [("users", &p.users), ("groups", &p.groups)] {
                for n in names {
                    if n.is_empty() || n.contains(|c: char| c.is_whitespace() || c == ':') {
                        issues.push(
                            format!("control.{list}.{kind}"),
                            format!("{n:?} is not a valid {} name", &kind[..kind.len() - 1]),
                        );
                    }
                }
            }
        }
    }
}

impl MotionConfig {
    pub(super) fn validate(&self, issues: &mut Issues) {
        issues.in_range("motion.lookahead", self.lookahead, 2, 10_000);
        issues.non_negative("motion.g64_tolerance", self.g64_tolerance);
        if !(self.rapid_override > 0.0 && self.rapid_override <= 1.0) {
            issues.push(
                "motion.rapid_override",
                format!("must be in (0, 1], got {}", self.rapid_override),
            );
        }
        issues.in_range(
            "motion.max_feed_override",
            self.max_feed_override,
            1.0,
            10.0,
        );
    }
}

impl SafetyConfig {
    pub(super) fn validate(&self, issues: &mut Issues) {
        if self.overrun_storm_count == 0 {
            issues.push("safety.overrun_storm_count", "must be >= 1, got 0");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn issues_of(toml_text: &str) -> Vec<String> {
        let c: ControlConfig = toml::from_str(toml_text).unwrap();
        let mut issues = Issues::default();
        c.validate(&mut issues);
        issues.into_vec().iter().map(ToString::to_string).collect()
    }

    #[test]
    fn control_defaults_are_bounded_and_private() {
        let c: ControlConfig = toml::from_str("").unwrap();
        assert_eq!(c.max_job_bytes, 256 * 1024 * 1024);
        assert_eq!(c.idle_timeout_s, 300);
        assert_eq!(c.max_clients, 512);
        assert_eq!(c.max_buffered_bytes, 64 * 1024 * 1024);
        assert_eq!((c.jobs_dir, c.operators, c.observers), (None, None, None));
        assert_eq!(c.unlisted, UnlistedRole::Observer);
        assert!(!c.socket_path.starts_with("/tmp"));
    }

    #[test]
    fn roles_and_limits_parse_and_are_checked() {
        let c: ControlConfig = toml::from_str(
            "operators = { users = [\"ann\"], groups = [\"cnc\"] }\nunlisted = \"none\"\n",
        )
        .unwrap();
        assert_eq!(c.operators.unwrap().groups, vec!["cnc".to_string()]);
        assert_eq!(c.unlisted, UnlistedRole::None);
        let issues = issues_of(
            "jobs_dir = \"jobs\"\nmax_clients = 0\nmax_buffered_bytes = 10\nobservers = { users = [\"a b\"] }\n",
        );
        for key in [
            "control.jobs_dir",
            "control.max_clients",
            "control.max_buffered_bytes",
            "control.observers.users",
        ] {
            assert!(
                issues.iter().any(|i| i.starts_with(key)),
                "{key}: {issues:?}"
            );
        }
    }
}
