//! Deployment of a machine: builds HAL backends, tasks and threads from the configuration,
//! checks the topology and runs the machine state machine and its safety paths.

pub mod api;
pub mod devices;
mod feeder;
pub mod io_devices;
pub mod job;
pub mod job_cancel;
pub mod job_file;
pub mod job_stream;
pub mod mode;
pub mod probing;
pub mod runtime;
pub mod safety;
pub mod scripts;
pub mod servo;
pub mod sim_spindle;
pub mod task_api;

pub use runtime::{DeployError, Machine};

/// Deploys the machine described by the file at `config` (default: the built-in sim mill).
pub fn deploy_from(
    config: Option<&std::path::Path>,
) -> Result<std::sync::Arc<dyn crate::daemon::Deployed>, DeployError> {
    let cfg = load_config(config)?;
    let machine: std::sync::Arc<dyn crate::daemon::Deployed> = Machine::deploy(cfg)?;
    Ok(machine)
}

/// Loads the machine description at `path`, or the built-in simulated mill.
pub fn load_config(
    path: Option<&std::path::Path>,
) -> Result<crate::config::MachineConfig, crate::config::ConfigError> {
    match path {
        Some(p) => crate::config::load(p),
        None => crate::config::builtin_sim(),
    }
}
