//! `hytask latency`.

use std::process::ExitCode;

/// Arguments of `hytask latency`.
#[derive(Debug, clap::Args)]
pub struct LatencyArgs {}

/// Runs the subcommand.
pub fn run(_args: LatencyArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`hytask latency` is not built yet")
}
