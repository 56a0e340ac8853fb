//! Client subcommands that talk to a running daemon over the control socket.

use std::process::ExitCode;

/// Client subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum ClientCommand {
    /// Print the machine status.
    Status,
}

/// Runs a client subcommand.
pub fn run(_cmd: ClientCommand) -> anyhow::Result<ExitCode> {
    anyhow::bail!("client commands are not built yet")
}
