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
    if let Some(path) = &args.config {
        // The TOML reader only says "stream did not contain valid UTF-8": name the place.
        if let Ok(bytes) = std::fs::read(path) {
            if let Some((line, col, byte)) = invalid_utf8_at(&bytes) {
                eprintln!(
                    "{}:{line}:{col}: invalid UTF-8 (byte 0x{byte:02X}); a machine file must be UTF-8 text",
                    path.display()
                );
                return Ok(ExitCode::FAILURE);
            }
        }
    }
    let (origin, result) = match &args.config {
        Some(path) => (path.display().to_string(), config::load(path)),
        None => ("built-in sim".to_string(), config::builtin_sim()),
    };
    // The PLC program compiles and its bindings resolve, as the daemon requires to start.
    let result = result.map(|m| {
        let plc = crate::plc::deploy::check(&m);
        (m, plc)
    });
    match result {
        Ok((_, Err(plc))) => {
            eprintln!("{origin}: [plc]:");
            eprintln!("{plc}");
            Ok(ExitCode::FAILURE)
        }
        Ok((machine, Ok(()))) => {
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

/// Where `bytes` stop being UTF-8: 1-based line, 1-based byte column in that line, and the
/// offending byte. None for valid UTF-8.
pub fn invalid_utf8_at(bytes: &[u8]) -> Option<(usize, usize, u8)> {
    let e = std::str::from_utf8(bytes).err()?;
    let at = e.valid_up_to();
    let before = &bytes[..at];
    let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
    let line_start = before
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |i| i + 1);
    Some((line, at - line_start + 1, bytes[at]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invalid_utf8_is_located_by_line_and_column() {
        assert_eq!(invalid_utf8_at(b"[machine]\nname = \"ok\"\n"), None);
        assert_eq!(
            invalid_utf8_at(b"[machine]\nname = \"caf\xe9\"\n"),
            Some((2, 12, 0xE9))
        );
        assert_eq!(invalid_utf8_at(b"\xff"), Some((1, 1, 0xFF)));
    }

    #[test]
    fn check_fails_on_invalid_utf8_without_parsing() {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        std::io::Write::write_all(&mut f, b"[machine]\nname = \"caf\xe9\"\n").unwrap();
        let code = run(CheckArgs {
            config: Some(f.path().into()),
            quiet: true,
        })
        .unwrap();
        assert_eq!(code, ExitCode::FAILURE);
    }
}
