//! `hytask check`.

use std::process::ExitCode;

/// Arguments of `hytask check`.
#[derive(Debug, clap::Args)]
pub struct CheckArgs {}

/// Runs the subcommand.
pub fn run(_args: CheckArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`hytask check` is not built yet")
}
