//! `hytask plan`.

use std::process::ExitCode;

/// Arguments of `hytask plan`.
#[derive(Debug, clap::Args)]
pub struct PlanArgs {}

/// Runs the subcommand.
pub fn run(_args: PlanArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`hytask plan` is not built yet")
}
