//! `hytask serve`: the daemon. Loads the machine, starts its realtime tasks, serves the
//! control socket until SIGTERM/SIGINT, then stops every axis under control and exits 0.

use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `hytask serve`.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    /// Machine description (TOML), or a cell (a file with a `[cell]` table, e.g.
    /// config/pickplace.toml). Default: the built-in simulated mill.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Control socket path; overrides `[control] socket` of the config.
    #[arg(long)]
    pub socket: Option<PathBuf>,
}

/// Runs the daemon.
pub fn run(args: ServeArgs) -> anyhow::Result<ExitCode> {
    use crate::control::{listen, server::ServerOptions};
    init_logging();
    if let Some(cell) = args
        .config
        .as_deref()
        .filter(|p| crate::cell::config::is_cell_file(p))
    {
        return super::run_cell::serve(cell, args.socket);
    }
    let config = crate::machine::load_config(args.config.as_deref())?;
    let socket = listen::SocketOptions::from_config(&config.control, args.socket);
    let options = ServerOptions::from_config(&config.control)?;
    // Take the socket path before deploying anything: a second daemon must stop here, before
    // it locks memory, starts realtime threads or opens the buses the first one drives.
    let claim = listen::claim(&socket)?;
    let machine = crate::machine::deploy_from(args.config.as_deref())?;
    // The Zenoh bridge (if configured) exports the machine once it runs; it stops after the
    // machine has, so remote peers see its last status and events.
    // It also watches the `[[remote]]` peers the machine depends on.
    let bridge = match &config.zenoh {
        Some(z) => {
            let mut b = crate::bridge::Bridge::start(machine.clone(), &config.machine.name, z)?;
            b.watch(&(machine.clone() as _), &config.remotes)?;
            Some(b)
        }
        None => None,
    };
    let listener = claim.bind()?;
    tracing::info!("control socket at {}", socket.path.display());
    crate::daemon::run_with(machine, listener, options, std::future::pending())?;
    if let Some(b) = bridge {
        b.stop();
    }
    tracing::info!("machine stopped; exiting");
    Ok(ExitCode::SUCCESS)
}

/// Logs to stderr without timestamps when journald captures it (it stamps lines itself),
/// with them otherwise; in colour only on a terminal (a log file or the journal would keep
/// the escape codes). `RUST_LOG` overrides the level.
pub(super) fn init_logging() {
    use std::io::IsTerminal;
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let under_journald = std::env::var_os("JOURNAL_STREAM").is_some();
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_target(false);
    let _ = if under_journald {
        builder.without_time().try_init()
    } else {
        builder.try_init()
    };
}
