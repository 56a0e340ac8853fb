//! `hytask serve`: the daemon. Loads the machine, starts its realtime tasks, serves the
//! control socket until SIGTERM/SIGINT, then stops every axis under control and exits 0.

use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `hytask serve`.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    /// Machine description (TOML). Default: the built-in simulated mill.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Control socket path; overrides `[control] socket` of the config.
    #[arg(long)]
    pub socket: Option<PathBuf>,
}

/// Runs the daemon.
pub fn run(args: ServeArgs) -> anyhow::Result<ExitCode> {
    init_logging();
    let config = crate::machine::load_config(args.config.as_deref())?;
    let socket = crate::machine::socket_options(&config, args.socket);
    let machine = crate::machine::deploy_from(args.config.as_deref())?;
    let listener = crate::control::server::bind(&socket)?;
    tracing::info!("control socket at {}", socket.path.display());
    crate::daemon::run(machine, listener, std::future::pending())?;
    tracing::info!("machine stopped; exiting");
    Ok(ExitCode::SUCCESS)
}

/// Logs to stderr without timestamps when journald captures it (it stamps lines itself),
/// with them otherwise. `RUST_LOG` overrides the level.
pub(super) fn init_logging() {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let under_journald = std::env::var_os("JOURNAL_STREAM").is_some();
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false);
    let _ = if under_journald {
        builder.without_time().try_init()
    } else {
        builder.try_init()
    };
}
