//! The machine description: one TOML file, typed, `deny_unknown_fields` everywhere, validated
//! with errors that name section and key.
//!
//! ```text
//! [machine]       name, kinematics (identity | scara + [machine.scara])
//! [[thread]]      realtime threads: name, period_us, priority, cpu, clock, sim_speed
//! [[axis]]        X/Y/Z/A/B/C/U/V/W: drive, scale, soft limits, velocity/acceleration/jerk,
//!                 following error limit, [axis.home]
//! [[drive]]       name, backend = "sim" | "canopen", [drive.sim] / [drive.canopen]
//! [[io]]          name, backend = "sim" | "modbus_tcp" | "modbus_rtu", named channels, [io.modbus]
//! [spindle]       max/min rpm, enable/direction/speed/at-speed channels
//! [coolant]       flood/mist outputs
//! [tool_table]    path
//! [gcode]         var_file, subroutine_path, log_dir, ini.<section>.<name> (`#<_ini[section]name>`)
//! [control]       socket_path, mode, group, jobs_dir, max_job_bytes, idle_timeout_s,
//!                 max_clients, max_buffered_bytes, operators, observers, unlisted
//! [job]           prepare_timeout_s
//! [logging]       level
//! [motion]        servo_thread, lookahead, g64_tolerance, rapid_override, max_feed_override
//! [safety]        estop_input, overrun storm policy
//! [plc]           program, thread, safety_relevant, timeouts, mcodes, instruction_budget,
//!                 [plc.inputs] / [plc.outputs]: ST variable = machine signal (see `plc`)
//! ```
//!
//! Loading has two stages. Deserialisation ([`parse`]) rejects malformed TOML, unknown keys,
//! missing keys and wrong types, stopping at the first, and names its path (e.g.
//! `axis[1].max_velocity`). Validation ([`MachineConfig::validate`]) then checks ranges and
//! cross-references and reports *every* problem, each keyed like
//! `axis[1] (Y).max_velocity: must be > 0, got -5`. Finally [`MachineConfig::resolve`] fills
//! defaults that depend on other sections, so the resolved machine states every value.
//!
//! Backends that are declared but not built yet (`canopen` drives)
//! validate normally; [`MachineConfig::unavailable_backends`] lists them and the deployment
//! refuses to start with them ([`require_available`]). That keeps one file per machine,
//! checkable on any computer.
//!
//! Adding a parameter: add one field with a doc comment (and a serde default if optional)
//! to the section's struct, and a check in its `validate` if it has a range.

mod axis;
mod drive;
mod error;
mod gcode;
mod io;
mod job;
mod machine;
pub mod modbus;
mod plc;
pub mod remote;
mod root;
mod settings;
mod spindle;
mod thread;
pub mod zenoh;

pub use axis::{AxisConfig, AxisName, HomeConfig, HomeMethod};
pub use drive::{
    CanopenDriveConfig, CanopenHoming, CanopenMode, DriveBackend, DriveConfig, SimDriveConfig,
    SwitchConfig, SIM_DRIVE_HEADROOM, SIM_INTERFACE,
};
pub use error::{ConfigError, Issue, Issues};
pub use gcode::GcodeConfig;
pub use io::{AnalogPoint, DigitalPoint, IoBackend, IoConfig, IoKind, IoRef, TouchPlate};
pub use job::{JobConfig, DEFAULT_PREPARE_TIMEOUT_S};
pub use machine::{Kinematics, KinematicsKind, MachineSection, ScaraConfig};
pub use plc::PlcConfig;
pub use root::MachineConfig;
pub use settings::{
    default_socket_path, ControlConfig, FileMode, LogLevel, LoggingConfig, MotionConfig,
    Principals, SafetyConfig, ToolTableConfig, UnlistedRole,
};
pub use spindle::{CoolantConfig, SpindleConfig};
pub use thread::{ThreadClock, ThreadConfig, MAX_PERIOD_US, MIN_PERIOD_US};
pub use zenoh::{ZenohConfig, ZenohRole};

use std::path::Path;

/// The text of `config/sim.toml`, compiled into the binary: the default machine.
pub const BUILTIN_SIM_TOML: &str = include_str!("../../config/sim.toml");
/// The text of `config/plc/mill.st`, the built-in machine's PLC program.
pub const BUILTIN_MILL_ST: &str = include_str!("../../config/plc/mill.st");

/// Deserialises TOML `text` into `T`; a malformed document, or an unknown, missing or
/// mistyped key, is a [`ConfigError::Parse`] naming `origin` and the key's path. Shared by
/// every file hytask reads (machines, cells) so they all name keys the same way.
pub fn deserialize<T: serde::de::DeserializeOwned>(
    text: &str,
    origin: &str,
) -> Result<T, ConfigError> {
    let de = toml::Deserializer::new(text);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let key = e.path().to_string();
        ConfigError::Parse {
            origin: origin.to_string(),
            key: if key == "." { "(root)".into() } else { key },
            message: e.into_inner().to_string().trim_end().to_string(),
        }
    })
}

/// Reads a configuration file's text; failure is a [`ConfigError::Io`] naming the file.
pub fn read(path: &Path) -> Result<String, ConfigError> {
    std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Parses and validates a machine description. `origin` names the text in messages (a
/// path, or "built-in sim"). Relative paths inside are left as written.
pub fn parse(text: &str, origin: &str) -> Result<MachineConfig, ConfigError> {
    let mut config: MachineConfig = deserialize(text, origin)?;
    let issues = config.validate();
    if !issues.is_empty() {
        return Err(ConfigError::Invalid {
            origin: origin.to_string(),
            issues,
        });
    }
    config.resolve();
    Ok(config)
}

/// Reads, parses and validates a machine file. A relative `tool_table.path`,
/// `gcode.var_file`, `gcode.log_dir` or `gcode.subroutine_path` entry is made relative to the file's directory (and `[plc]` paths are resolved against it).
pub fn load(path: &Path) -> Result<MachineConfig, ConfigError> {
    let text = read(path)?;
    let mut config = parse(&text, &path.display().to_string())?;
    if let (Some(t), Some(dir)) = (&mut config.tool_table, path.parent()) {
        if t.path.is_relative() {
            t.path = dir.join(&t.path);
        }
    }
    for p in [&mut config.gcode.var_file, &mut config.gcode.log_dir] {
        if let (Some(v), Some(dir)) = (p, path.parent()) {
            if v.is_relative() {
                *v = dir.join(&*v);
            }
        }
    }
    if let Some(dir) = path.parent() {
        for p in config
            .gcode
            .subroutine_path
            .iter_mut()
            .filter(|p| p.is_relative())
        {
            *p = dir.join(&*p);
        }
    }
    if let Some(p) = &mut config.plc {
        p.base_dir = path.parent().map(Path::to_path_buf);
    }
    if let Some(dir) = path.parent() {
        drive::resolve_eds_paths(&mut config.drives, dir);
    }
    Ok(config)
}

/// The built-in simulated 3-axis mill (`config/sim.toml`). The shipped file is validated by
/// the test suite, so an error here is a build defect; it is still returned, not panicked,
/// so the daemon reports it like any other configuration error.
pub fn builtin_sim() -> Result<MachineConfig, ConfigError> {
    parse(BUILTIN_SIM_TOML, "built-in sim")
}

/// Fails with [`ConfigError::Unavailable`] when the configuration names backends this build
/// cannot run. Called by the deployment before it builds any backend.
pub fn require_available(config: &MachineConfig) -> Result<(), ConfigError> {
    let missing = config.unavailable_backends();
    if missing.is_empty() {
        Ok(())
    } else {
        Err(ConfigError::Unavailable(missing))
    }
}
