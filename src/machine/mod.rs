//! Deployment of a machine: builds HAL backends, tasks and threads from the configuration,
//! checks the topology and runs the machine state machine and its safety paths.

pub mod api;
pub mod mode;
pub mod safety;

/// Deploys the machine described by the file at `config` (default: the built-in sim mill).
pub fn deploy_from(
    _config: Option<&std::path::Path>,
) -> anyhow::Result<std::sync::Arc<dyn crate::daemon::Deployed>> {
    anyhow::bail!("machine deployment is not built yet")
}

/// Control socket options: from the config's `[control]` section, with an override path.
pub fn socket_options(
    _config: Option<&std::path::Path>,
    path: Option<std::path::PathBuf>,
) -> anyhow::Result<crate::control::server::SocketOptions> {
    Ok(crate::control::server::SocketOptions {
        path: path.unwrap_or_else(|| crate::control::server::default_socket_path().into()),
        mode: 0o660,
        group: None,
    })
}
