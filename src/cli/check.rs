//! `hytask check [CONFIG]`: validates a machine file and prints the resolved machine.
//!
//! On success the resolved configuration (every default filled in) goes to standard output
//! as TOML, so it can be diffed or saved, and a one-line summary plus any notes (backends
//! declared but not available in this build) go to standard error; the exit status is 0.
//! On failure every problem is listed on standard error, one per line with its section and
//! key, and the exit status is 1. Without CONFIG the built-in simulated machine is checked.

use crate::config::{self, ConfigError, MachineConfig};
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `hytask check`.
#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    /// Machine configuration file (TOML); the built-in simulated mill if omitted.
    pub config: Option<PathBuf>,
    /// Print only problems and the summary, not the resolved machine.
    #[arg(short, long)]
    pub quiet: bool,
}

/// Runs the subcommand.
pub fn run(args: CheckArgs) -> anyhow::Result<ExitCode> {
    let (origin, result) = match &args.config {
        Some(path) => (path.display().to_string(), config::load(path)),
        None => ("built-in sim".to_string(), config::builtin_sim()),
    };
    match result {
        Ok(machine) => {
            if !args.quiet {
                print!("{}", machine.to_toml()?);
            }
            eprintln!("{origin}: OK: {}", summary(&machine));
            for note in machine.unavailable_backends() {
                eprintln!("note: {note} (it validates, but cannot be deployed)");
            }
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            report(&e);
            Ok(ExitCode::FAILURE)
        }
    }
}

fn summary(m: &MachineConfig) -> String {
    let axes: Vec<String> = m.axes.iter().map(|a| a.name.to_string()).collect();
    let period = m.servo_thread().map_or_else(String::new, |t| {
        format!(", servo period {} us", t.period_us)
    });
    format!(
        "machine {:?}, axes {}, {} drive(s), {} I/O device(s){period}",
        m.machine.name,
        axes.join(""),
        m.drives.len(),
        m.io.len()
    )
}

fn report(e: &ConfigError) {
    match e {
        ConfigError::Invalid { origin, issues } => {
            eprintln!("{origin}: {} error(s):", issues.len());
            for issue in issues {
                eprintln!("  {issue}");
            }
        }
        other => eprintln!("{other}"),
    }
}
