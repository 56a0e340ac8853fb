//! `hytask gcode`: G-code tools. `canon` prints the canonical trace in `rs274 -g` layout so
//! it can be diffed against LinuxCNC; `check` only validates a program.

use crate::gcode::trace_spill::Spill;
use crate::gcode::{load_file, trace_file, trace_file_spilled, InterpOptions, LengthUnits};
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
    /// LinuxCNC tool table (`.tbl`). Default: the `[tool_table]` of `--config`, else none
    /// (the same default as `hytask plan`).
    #[arg(long)]
    pub tool_table: Option<PathBuf>,
    /// Machine description (TOML, as for `hytask serve`): interpret with its tool table and
    /// millimetre machine units, as the daemon does.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Directory searched for `o<name> call` files (repeatable).
    #[arg(long)]
    pub subroutine_path: Vec<PathBuf>,
    /// Honour `/` block delete.
    #[arg(long)]
    pub block_delete: bool,
    /// Units of the tool table: `inch` or `mm`. Default: `inch` (rs274 without an INI
    /// file, so traces diff cleanly), or `mm` with `--config` (the daemon's units).
    #[arg(long)]
    pub machine_units: Option<String>,
    /// LinuxCNC ini file, as `rs274 -i` reads it, so that a trace can be diffed against
    /// rs274 run with the same file: its numbers are the `#<_ini[section]name>` values
    /// (instead of `--config`'s), its `[RS274NGC] SUBROUTINE_PATH` is searched after
    /// `--subroutine-path` (relative entries from the ini file's directory), and its
    /// `[PYTHON]` section (`TOPLEVEL`, `PATH_PREPEND`, `PATH_APPEND`) makes the TOPLEVEL's
    /// `oword` functions O-word procedures (run by `python3`, as rs274's embedded Python).
    #[arg(long)]
    pub ini: Option<PathBuf>,
    /// Run `;py,` and `(py,…)` comments with `python3` even without an ini `[PYTHON]`
    /// section (as rs274's embedded Python does). Without it, or a `[PYTHON]` section in
    /// `--ini`, they are ordinary comments: a program alone never runs code on this host.
    #[arg(long)]
    pub python: bool,
}

impl InterpArgs {
    fn options(&self) -> anyhow::Result<InterpOptions> {
        let machine = match &self.config {
            Some(p) => Some(crate::config::load(p)?),
            None => None,
        };
        let default_units = if machine.is_some() { "mm" } else { "inch" };
        let machine_units = match self.machine_units.as_deref().unwrap_or(default_units) {
            "inch" | "in" => LengthUnits::Inches,
            "mm" => LengthUnits::Millimeters,
            other => anyhow::bail!("--machine-units must be inch or mm, not {other:?}"),
        };
        let base = match &machine {
            Some(m) => crate::machine::job::interp_options(m),
            // no machine: rs274's standalone canon, whose traces these commands reproduce
            None => InterpOptions {
                start_pocket: crate::gcode::RS274_START_POCKET,
                ..InterpOptions::default()
            },
        };
        let mut subroutine_path = self.subroutine_path.clone();
        let mut ini = base.ini.clone();
        let mut python = base.python.clone();
        if let Some(p) = &self.ini {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading the ini file {}", p.display()))?;
            let dir = p.parent().unwrap_or(std::path::Path::new("."));
            subroutine_path.extend(
                crate::gcode::ini::subroutine_path(&text)
                    .iter()
                    .map(|d| dir.join(d)),
            );
            ini = std::sync::Arc::new(crate::gcode::IniValues::parse(&text));
            python = crate::gcode::python::PythonConfig::from_ini(&text, dir);
        }
        if self.python && python.is_none() {
            python = Some(crate::gcode::python::PythonConfig::bare());
        }
        Ok(InterpOptions {
            tool_table: super::plan::tool_table(self.tool_table.as_deref(), machine.as_ref()),
            subroutine_path,
            block_delete: self.block_delete,
            machine_units,
            ini,
            python,
            ..base
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

/// Standard output as a [`Spill`] when it is a file or the null device.
fn stdout_spill() -> Option<Spill> {
    use std::os::fd::AsFd as _;
    let fd = std::io::stdout().as_fd().try_clone_to_owned().ok()?;
    Spill::onto(std::fs::File::from(fd))
}

/// Runs the subcommand.
pub fn run(args: GcodeArgs) -> anyhow::Result<ExitCode> {
    match args.command {
        GcodeCommand::Canon(a) => {
            // Formatted while interpreting; printed only once the whole program is valid,
            // except onto a file or /dev/null, which can take a partial trace back.
            let opts = a.options()?;
            if let Some(mut spill) = stdout_spill() {
                let rest = trace_file_spilled(&a.file, &opts, &mut spill)?;
                spill.finish(&rest).context("writing the trace")?;
                return Ok(ExitCode::SUCCESS);
            }
            let trace = trace_file(&a.file, &opts)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    fn args(config: Option<PathBuf>, tool_table: Option<PathBuf>) -> InterpArgs {
        InterpArgs {
            file: PathBuf::from("p.ngc"),
            tool_table,
            config,
            subroutine_path: Vec::new(),
            block_delete: false,
            machine_units: None,
            ini: None,
            python: false,
        }
    }

    /// `--ini` reads the ini's `[PYTHON]` section, its paths from the ini's directory; without
    /// `--ini` there is none.
    #[test]
    fn ini_python_section_configures_embedded_python() {
        let dir = tempfile::tempdir().unwrap();
        let ini = dir.path().join("m.ini");
        std::fs::write(&ini, "[PYTHON]\nPATH_PREPEND = py\nTOPLEVEL = py/top.py\n").unwrap();
        let mut a = args(None, None);
        assert_eq!(a.options().unwrap().python, None);
        a.ini = Some(ini);
        let py = a.options().unwrap().python.unwrap();
        assert_eq!(py.toplevel, Some(dir.path().join("py/top.py")));
        assert_eq!(py.path_prepend, vec![dir.path().join("py")]);
    }

    /// `gcode canon` picks its table as `plan` does: the flag, else the machine's, else
    /// none; with a machine file the table is in the daemon's millimetres.
    #[test]
    fn tool_table_default_is_the_one_plan_uses() {
        let dir = tempfile::tempdir().unwrap();
        let sim = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim.toml"),
        )
        .unwrap();
        let cfg = dir.path().join("machine.toml");
        std::fs::write(&cfg, format!("{sim}\n[tool_table]\npath = \"tools.tbl\"\n")).unwrap();

        let none = args(None, None).options().unwrap();
        assert_eq!(none.tool_table, None);
        assert_eq!(none.machine_units, LengthUnits::Inches);
        let from_cfg = args(Some(cfg.clone()), None).options().unwrap();
        assert_eq!(from_cfg.tool_table, Some(dir.path().join("tools.tbl")));
        assert_eq!(from_cfg.machine_units, LengthUnits::Millimeters);
        let plan_args = crate::cli::plan::MotionArgs {
            config: Some(cfg.clone()),
            ..Default::default()
        };
        assert_eq!(
            plan_args.interp_options().unwrap().tool_table,
            from_cfg.tool_table
        );
        let flag = args(Some(cfg), Some(PathBuf::from("other.tbl")))
            .options()
            .unwrap();
        assert_eq!(flag.tool_table, Some(PathBuf::from("other.tbl")));
    }
}
