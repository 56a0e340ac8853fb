//! `hytask run`.

use std::process::ExitCode;

/// Arguments of `hytask run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {}

/// Runs the subcommand.
pub fn run(_args: RunArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`hytask run` is not built yet")
}
