//! `hytask serve`.

use std::process::ExitCode;

/// Arguments of `hytask serve`.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {}

/// Runs the subcommand.
pub fn run(_args: ServeArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`hytask serve` is not built yet")
}
