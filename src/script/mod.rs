#![doc = include_str!("README.md")]

pub mod ast;
pub mod bind;
mod code;
mod compile;
pub mod engine;
pub mod host;
pub mod hosts;
pub mod parser;

pub use bind::{BindError, Bindings, Loaded};
pub use code::Script;
pub use compile::{compile, compile_with};
pub use engine::{
    Ctl, Engine, EngineError, Limits, RunStatus, ScriptError, ScriptErrorKind, Status,
};
pub use host::{ControlError, ItemStatus, ScriptControl, ScriptHost, ScriptTask};
pub use hosts::{HostsError, ScriptHosts};

/// Reads and compiles a script file.
pub fn load_file(path: &std::path::Path) -> Result<Script, crate::plc::LoadError> {
    let src = std::fs::read_to_string(path).map_err(|e| crate::plc::LoadError::Read {
        path: path.display().to_string(),
        source: e,
    })?;
    Ok(compile(&path.display().to_string(), &src)?)
}
