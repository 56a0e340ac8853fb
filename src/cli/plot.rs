//! `hytask plot`.

use std::process::ExitCode;

/// Arguments of `hytask plot`.
#[derive(Debug, clap::Args)]
pub struct PlotArgs {}

/// Runs the subcommand.
pub fn run(_args: PlotArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`hytask plot` is not built yet")
}
