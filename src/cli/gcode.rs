//! `hytask gcode`: G-code tools. `canon` prints the canonical trace in `rs274 -g` layout so
//! it can be diffed against LinuxCNC; `check` only validates a program.

use crate::gcode::{load_file, trace_file, InterpOptions, LengthUnits};
use anyhow::Context as _;
use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `hytask gcode`.
#[derive(Debug, clap::Args)]
pub struct GcodeArgs {
    /// What to do.
    #[command(subcommand)]
    pub command: GcodeCommand,
}

/// Options shared by the `gcode` subcommands.
#[derive(Debug, clap::Args)]
pub struct InterpArgs {
    /// The program.
    pub file: PathBuf,
    /// LinuxCNC tool table (`.tbl`).
    #[arg(long)]
    pub tool_table: Option<PathBuf>,
    /// Directory searched for `o<name> call` files (repeatable).
    #[arg(long)]
    pub subroutine_path: Vec<PathBuf>,
    /// Honour `/` block delete.
    #[arg(long)]
    pub block_delete: bool,
    /// Units of the tool table: `inch` (rs274 without an INI file, the default so traces
    /// diff cleanly) or `mm`.
    #[arg(long, default_value = "inch")]
    pub machine_units: String,
}

impl InterpArgs {
    fn options(&self) -> anyhow::Result<InterpOptions> {
        let machine_units = match self.machine_units.as_str() {
            "inch" | "in" => LengthUnits::Inches,
            "mm" => LengthUnits::Millimeters,
            other => anyhow::bail!("--machine-units must be inch or mm, not {other:?}"),
        };
        Ok(InterpOptions {
            tool_table: self.tool_table.clone(),
            subroutine_path: self.subroutine_path.clone(),
            block_delete: self.block_delete,
            machine_units,
            ..InterpOptions::default()
        })
    }
}

/// The `gcode` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum GcodeCommand {
    /// Print the canonical commands in `rs274 -g` layout.
    Canon(InterpArgs),
    /// Interpret a program and report its first error, if any.
    Check(InterpArgs),
}

/// Runs the subcommand.
pub fn run(args: GcodeArgs) -> anyhow::Result<ExitCode> {
    match args.command {
        GcodeCommand::Canon(a) => {
            // Formatted while interpreting; printed only once the whole program is valid.
            let trace = trace_file(&a.file, &a.options()?)?;
            let stdout = std::io::stdout();
            let mut lock = stdout.lock();
            lock.write_all(&trace).context("writing the trace")?;
            lock.flush().context("writing the trace")?;
            Ok(ExitCode::SUCCESS)
        }
        GcodeCommand::Check(a) => {
            let prog = load_file(&a.file, &a.options()?)?;
            println!(
                "{}: ok, {} canonical commands",
                a.file.display(),
                prog.canon.len()
            );
            Ok(ExitCode::SUCCESS)
        }
    }
}
