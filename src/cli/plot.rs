//! `hytask plot FILE -o path.svg [--config ...]`: the planned toolpath as SVG, feeds coloured
//! by planned speed, rapids dashed.

use super::plan::{load, MotionArgs};
use anyhow::Context;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `hytask plot`.
#[derive(Debug, clap::Args)]
pub struct PlotArgs {
    /// G-code file to plot.
    pub file: PathBuf,
    /// Output SVG file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Motion limits and planner settings.
    #[command(flatten)]
    pub motion: MotionArgs,
}

/// Runs the subcommand.
pub fn run(args: PlotArgs) -> anyhow::Result<ExitCode> {
    let cfg = args.motion.config()?;
    let canon = load(&args.file, &args.motion)?;
    let plan = crate::motion::plan(&canon, &cfg)?;
    let svg = crate::motion::svg::render(&plan, &args.file.display().to_string());
    std::fs::write(&args.output, svg)
        .with_context(|| format!("writing {}", args.output.display()))?;
    println!(
        "{}: {:.3} s, {:.3} mm -> {}",
        args.file.display(),
        plan.duration_s,
        plan.distance_mm,
        args.output.display()
    );
    Ok(ExitCode::SUCCESS)
}
