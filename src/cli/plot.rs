//! `hytask plot FILE -o part.svg|part.png [--view top|front|side|iso] [--from X,Y,Z]`: the
//! planned toolpath as a picture (see `motion::draw`): planned from where the machine
//! starts, fitted to the cutting moves, on a labelled mm grid, with start/end, plunge and
//! drill marks and the legend inside. `.png` rasterises the same SVG (pure Rust).
//! `--velocity` draws the feed along the path instead (see `motion::draw::feed`).

use super::plan::{load, MotionArgs};
use crate::gcode::NUM_AXES;
use crate::motion::draw::{self, Options, View};
use anyhow::{bail, Context};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Arguments of `hytask plot`.
#[derive(Debug, clap::Args)]
pub struct PlotArgs {
    /// G-code file to plot.
    pub file: PathBuf,
    /// Output file: `.png` writes a PNG image, anything else SVG.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Which way to look at the toolpath.
    #[arg(long, value_enum, default_value_t = View::Top)]
    pub view: View,
    /// Machine position the program starts from, `X,Y,Z` in mm. Default: where `hytask run`
    /// starts it, the home position of the machine (`--config`, else the built-in sim mill).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub from: Option<String>,
    /// Draw the feed along the path instead of the toolpath: the path speed of the
    /// servo-period trace against time, with the programmed feed and the velocity limit.
    #[arg(long)]
    pub velocity: bool,
    /// Picture width in pixels (the height follows the drawing).
    #[arg(long, default_value_t = 1000)]
    pub width: u32,
    /// Motion limits and planner settings.
    #[command(flatten)]
    pub motion: MotionArgs,
}

/// Runs the subcommand.
pub fn run(args: PlotArgs) -> anyhow::Result<ExitCode> {
    let cfg = args.motion.config()?;
    let canon = load(&args.file, &args.motion)?;
    let start = match &args.from {
        Some(text) => parse_from(text)?,
        None => home_pose(args.motion.config.as_deref())?,
    };
    let plan = crate::motion::plan_from(&canon, &cfg, start).with_context(|| {
        format!(
            "planning {} from X{} Y{} Z{}",
            args.file.display(),
            start[0],
            start[1],
            start[2]
        )
    })?;
    if !(300..=8000).contains(&args.width) {
        bail!("--width {} px: give 300 to 8000", args.width);
    }
    let options = Options {
        title: args
            .file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        view: args.view,
        width_px: f64::from(args.width),
    };
    let svg = if args.velocity {
        super::plan::check_traceable(&plan, args.motion.max_trace_s())?;
        feed_chart(&plan, &canon, &cfg, start, &options)?
    } else {
        draw::render(&plan, &options)
    };
    let png = args
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    let bytes = if png {
        draw::png::render(&svg)?
    } else {
        svg.into_bytes()
    };
    std::fs::write(&args.output, bytes)
        .with_context(|| format!("writing {}", args.output.display()))?;
    println!(
        "{}: {:.3} s, {:.3} mm, from X{} Y{} Z{} -> {}",
        args.file.display(),
        plan.duration_s,
        plan.distance_mm,
        start[0],
        start[1],
        start[2],
        args.output.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// The feed chart of `--velocity`: the plan run at the servo period, each period's
/// programmed feed from its source line, the smallest X Y Z velocity limit.
fn feed_chart(
    plan: &crate::motion::Plan,
    canon: &[crate::gcode::Canon],
    cfg: &crate::motion::MotionConfig,
    start: [f64; NUM_AXES],
    options: &Options,
) -> anyhow::Result<String> {
    let tr = crate::motion::trace::run_all(plan, cfg);
    let feed = crate::motion::bounds::feed_by_line(canon, cfg, start)?;
    let programmed: Vec<f64> = tr
        .lines
        .iter()
        .map(|l| feed.get(l).copied().unwrap_or(f64::INFINITY))
        .collect();
    let limit = cfg.axes[0..3]
        .iter()
        .map(|a| a.max_vel_mm_s)
        .fold(f64::INFINITY, f64::min);
    Ok(draw::feed::render(
        &tr,
        draw::feed::Marks {
            programmed_mm_s: &programmed,
            limit_mm_s: limit,
        },
        options,
    ))
}

/// `X,Y,Z` in mm; the other axes at 0.
fn parse_from(text: &str) -> anyhow::Result<[f64; NUM_AXES]> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        bail!("--from {text:?}: give X,Y,Z in mm, e.g. --from 0,0,50");
    }
    let mut pose = [0.0; NUM_AXES];
    for (i, p) in parts.iter().enumerate() {
        pose[i] = p
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .with_context(|| format!("--from {text:?}: {p:?} is not a number of mm"))?;
    }
    Ok(pose)
}

/// Where a freshly started machine is when `hytask run` loads a job: homed, every axis at
/// its `home.position`.
fn home_pose(config: Option<&Path>) -> anyhow::Result<[f64; NUM_AXES]> {
    let machine = crate::machine::load_config(config)?;
    let mut pose = [0.0; NUM_AXES];
    for a in &machine.axes {
        pose[a.name as usize] = a.home.position;
    }
    Ok(pose)
}
