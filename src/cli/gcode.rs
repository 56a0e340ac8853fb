//! `hytask gcode`.

use std::process::ExitCode;

/// Arguments of `hytask gcode`.
#[derive(Debug, clap::Args)]
pub struct GcodeArgs {}

/// Runs the subcommand.
pub fn run(_args: GcodeArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`hytask gcode` is not built yet")
}
