//! `hytask plan FILE [--config motion.toml] [--max-vel ...]`: interprets a G-code file,
//! plans it, and prints the cycle-time estimate (planned job time, distance, against lower
//! bounds and a stop-at-every-corner planner) and, from the trace interpolated at the servo
//! period, each axis' peak velocity, acceleration and jerk against its limit.

use crate::gcode::InterpOptions;
use crate::motion::{self, bounds, trace, MotionConfig, AXIS_NAMES};
use anyhow::Context;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Arguments of `hytask plan`.
#[derive(Debug, clap::Args)]
pub struct PlanArgs {
    /// G-code file to plan.
    pub file: PathBuf,
    /// Also write the servo-period trace as CSV: time, then per axis position, velocity,
    /// acceleration and jerk (header row with units).
    #[arg(long, value_name = "OUT.csv")]
    pub trace: Option<PathBuf>,
    /// Motion limits and planner settings.
    #[command(flatten)]
    pub motion: MotionArgs,
}

/// Motion configuration (shared by `plan` and `plot`): a machine description (`--config`,
/// the same TOML `hytask serve` runs) or generic limits, then an optional motion-only TOML
/// file of [`MotionOverrides`] (`--motion`), then command-line overrides.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct MotionArgs {
    /// Machine description (TOML, as for `hytask serve`): plan with its axis limits, soft
    /// limits, servo period, lookahead and kinematics. Without it: generic limits (50 mm/s,
    /// 500 mm/s², 50,000 mm/s³ per axis, 1 ms servo period).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// TOML file with motion settings applied on top (keys: max_vel_mm_s, max_acc_mm_s2,
    /// max_jerk_mm_s3, servo_period_s, default_tolerance_mm, lookahead_moves,
    /// merge_fraction, override_reserve, fit_arcs, spans, min_mm, max_mm).
    #[arg(long = "motion")]
    pub motion_file: Option<PathBuf>,
    /// Most canonical commands to interpret (default 2,000,000, see
    /// [`PLAN_MAX_COMMANDS`]): plan and plot hold the whole program and its plan in memory,
    /// where a job streams; the interpreter's own cap (50 M) let one small file take GBs.
    #[arg(long)]
    pub max_commands: Option<usize>,
    /// Longest planned job, s, that `plan` and `plot` run through the interpolator at the
    /// servo period (the trace, its peaks, the optimal bound, `--trace`, `--velocity`).
    /// Default 14,400 (4 h): one period is one sample, so a job of F0.001 would otherwise
    /// take hours and GBs; the plan itself and its time are always reported.
    #[arg(long, value_name = "SECONDS")]
    pub max_trace_s: Option<f64>,
    /// Velocity limit of X Y Z, mm/s.
    #[arg(long)]
    pub max_vel: Option<f64>,
    /// Acceleration limit of X Y Z, mm/s².
    #[arg(long)]
    pub max_acc: Option<f64>,
    /// Jerk limit of X Y Z, mm/s³.
    #[arg(long)]
    pub max_jerk: Option<f64>,
    /// Servo period, ms.
    #[arg(long)]
    pub servo_period_ms: Option<f64>,
    /// G64 tolerance used without P, mm.
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Lookahead window, moves.
    #[arg(long)]
    pub lookahead: Option<usize>,
    /// Fraction of the G64 tolerance used to merge short collinear moves (0 = off).
    #[arg(long)]
    pub merge_fraction: Option<f64>,
    /// LinuxCNC tool table (`.tbl`, millimetres as in the daemon) for M6/G43. Default: the
    /// `[tool_table]` of `--config`, else none (the same default as `hytask gcode canon`).
    #[arg(long)]
    pub tool_table: Option<PathBuf>,
}

/// Default of `--max-trace-s`: 4 h of machine time (14.4 M servo periods at 1 ms).
pub const DEFAULT_MAX_TRACE_S: f64 = 14_400.0;

impl MotionArgs {
    /// `--max-trace-s`, or its default.
    pub fn max_trace_s(&self) -> f64 {
        self.max_trace_s.unwrap_or(DEFAULT_MAX_TRACE_S)
    }
}

/// Refuses to run a trace of `plan` longer than `max_s` of machine time, naming the option.
pub fn check_traceable(plan: &crate::motion::Plan, max_s: f64) -> anyhow::Result<()> {
    if plan.duration_s <= max_s {
        return Ok(());
    }
    anyhow::bail!(
        "the job is planned to take {:.0} s, longer than --max-trace-s {:.0} s: its \
         servo-period trace is not run (raise --max-trace-s to run it)",
        plan.duration_s,
        max_s
    )
}

/// Keys accepted in the `--config` file.
#[derive(Debug, Clone, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionOverrides {
    /// X Y Z velocity, mm/s.
    pub max_vel_mm_s: Option<f64>,
    /// X Y Z acceleration, mm/s².
    pub max_acc_mm_s2: Option<f64>,
    /// X Y Z jerk, mm/s³.
    pub max_jerk_mm_s3: Option<f64>,
    /// Servo period, s.
    pub servo_period_s: Option<f64>,
    /// G64 default tolerance, mm.
    pub default_tolerance_mm: Option<f64>,
    /// Lookahead window, moves.
    pub lookahead_moves: Option<usize>,
    /// Merge fraction.
    pub merge_fraction: Option<f64>,
    /// Override reserve.
    pub override_reserve: Option<f64>,
    /// Fit dense chords into arcs (`[motion] fit_arcs`).
    pub fit_arcs: Option<bool>,
    /// Plan runs of tangent moves as one speed profile (`[motion] spans`).
    pub spans: Option<bool>,
    /// X Y Z lower soft limit, mm.
    pub min_mm: Option<f64>,
    /// X Y Z upper soft limit, mm.
    pub max_mm: Option<f64>,
}

impl MotionArgs {
    /// The resulting configuration.
    pub fn config(&self) -> anyhow::Result<MotionConfig> {
        let mut o = match &self.motion_file {
            Some(p) => {
                let text = std::fs::read_to_string(p)
                    .with_context(|| format!("reading {}", p.display()))?;
                toml::from_str::<MotionOverrides>(&text)
                    .with_context(|| format!("parsing {}", p.display()))?
            }
            None => MotionOverrides::default(),
        };
        o.max_vel_mm_s = self.max_vel.or(o.max_vel_mm_s);
        o.max_acc_mm_s2 = self.max_acc.or(o.max_acc_mm_s2);
        o.max_jerk_mm_s3 = self.max_jerk.or(o.max_jerk_mm_s3);
        o.servo_period_s = self
            .servo_period_ms
            .map(|ms| ms / 1000.0)
            .or(o.servo_period_s);
        o.default_tolerance_mm = self.tolerance.or(o.default_tolerance_mm);
        o.lookahead_moves = self.lookahead.or(o.lookahead_moves);
        o.merge_fraction = self.merge_fraction.or(o.merge_fraction);
        let mut cfg = match &self.config {
            Some(p) => crate::machine::job::motion_config(&crate::config::load(p)?),
            None => MotionConfig::default(),
        };
        for a in &mut cfg.axes[0..3] {
            a.max_vel_mm_s = o.max_vel_mm_s.unwrap_or(a.max_vel_mm_s);
            a.max_acc_mm_s2 = o.max_acc_mm_s2.unwrap_or(a.max_acc_mm_s2);
            a.max_jerk_mm_s3 = o.max_jerk_mm_s3.unwrap_or(a.max_jerk_mm_s3);
            a.min_mm = o.min_mm.unwrap_or(a.min_mm);
            a.max_mm = o.max_mm.unwrap_or(a.max_mm);
        }
        cfg.servo_period_s = o.servo_period_s.unwrap_or(cfg.servo_period_s);
        cfg.default_tolerance_mm = o.default_tolerance_mm.unwrap_or(cfg.default_tolerance_mm);
        cfg.lookahead_moves = o.lookahead_moves.unwrap_or(cfg.lookahead_moves);
        cfg.merge_fraction = o.merge_fraction.unwrap_or(cfg.merge_fraction);
        cfg.override_reserve = o.override_reserve.unwrap_or(cfg.override_reserve);
        cfg.fit_arcs = o.fit_arcs.unwrap_or(cfg.fit_arcs);
        cfg.spans = o.spans.unwrap_or(cfg.spans);
        cfg.validate()?;
        Ok(cfg)
    }
}

impl MotionArgs {
    /// Interpreter options as the daemon would use them for this machine: the tool table
    /// of `--tool-table`, else of the `--config` machine (see [`tool_table`]).
    pub fn interp_options(&self) -> anyhow::Result<InterpOptions> {
        let machine = match &self.config {
            Some(p) => Some(crate::config::load(p)?),
            None => None,
        };
        let mut o = match &machine {
            Some(m) => crate::machine::job::interp_options(m),
            None => InterpOptions::default(),
        };
        o.tool_table = tool_table(self.tool_table.as_deref(), machine.as_ref());
        Ok(o)
    }
}

/// The tool table a CLI command interprets with: the one named on the command line, else
/// the machine configuration's `[tool_table]`, else none. `hytask plan`, `hytask plot` and
/// `hytask gcode` all choose it this way, so they agree with each other and with the
/// daemon running that configuration.
pub fn tool_table(
    explicit: Option<&Path>,
    machine: Option<&crate::config::MachineConfig>,
) -> Option<PathBuf> {
    explicit
        .map(Path::to_path_buf)
        .or_else(|| machine.and_then(|m| m.tool_table.as_ref().map(|t| t.path.clone())))
}

/// Default of `--max-commands`: about 0.5 GB of commands and plan held at once.
pub const PLAN_MAX_COMMANDS: usize = 2_000_000;

/// Interprets `file` into canonical commands with the options of `motion`'s machine, at most
/// `--max-commands` of them.
pub fn load(file: &Path, motion: &MotionArgs) -> anyhow::Result<Vec<crate::gcode::Canon>> {
    let mut opts = motion.interp_options()?;
    let max = motion.max_commands.unwrap_or(PLAN_MAX_COMMANDS);
    opts.limits.max_canon = opts.limits.max_canon.min(max);
    match crate::gcode::load_file(file, &opts) {
        Ok(prog) => Ok(prog.canon),
        Err(e) if e.to_string().contains("too many canonical commands") => {
            Err(anyhow::Error::new(e).context(format!(
                "{}: plan and plot hold every command in memory, at most {max} \
                 (--max-commands)",
                file.display()
            )))
        }
        Err(e) => Err(e.into()),
    }
}

/// Runs the subcommand.
pub fn run(args: PlanArgs) -> anyhow::Result<ExitCode> {
    let cfg = args.motion.config()?;
    let canon = load(&args.file, &args.motion)?;
    let mut out = String::new();
    let max_trace_s = args.motion.max_trace_s();
    let within = report(
        &args.file.display().to_string(),
        &canon,
        &cfg,
        max_trace_s,
        &mut out,
    )?;
    print!("{out}");
    if let Some(path) = &args.trace {
        write_trace(&canon, &cfg, max_trace_s, path)?;
        println!("trace:           written to {}", path.display());
    }
    Ok(if within {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// Plans `canon`, runs it through the interpolator at the servo period and writes the
/// trace to `path` as CSV (see [`trace::Trace::write_csv`]).
pub fn write_trace(
    canon: &[crate::gcode::Canon],
    cfg: &MotionConfig,
    max_trace_s: f64,
    path: &Path,
) -> anyhow::Result<()> {
    let plan = crate::motion::plan(canon, cfg)?;
    check_traceable(&plan, max_trace_s)?;
    let tr = trace::run_all(&plan, cfg);
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    tr.write_csv(&mut w)
        .and_then(|()| std::io::Write::flush(&mut w))
        .with_context(|| format!("writing {}", path.display()))
}

/// Plans `canon`, interpolates it at the servo period and writes the report; returns false
/// if a trace peak exceeds its limit (which the planner is built never to allow). A job
/// planned longer than `max_trace_s` is reported without its trace (see `--max-trace-s`).
pub fn report(
    name: &str,
    canon: &[crate::gcode::Canon],
    cfg: &MotionConfig,
    max_trace_s: f64,
    out: &mut String,
) -> anyhow::Result<bool> {
    use std::fmt::Write;
    let t0 = std::time::Instant::now();
    // Named as the daemon names a refused job (`machine::job`): most plan errors carry only
    // the line.
    let plan = crate::motion::plan(canon, cfg).map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    let plan_s = t0.elapsed().as_secs_f64();
    let b = bounds::bounds(canon, cfg)?;
    let traced = check_traceable(&plan, max_trace_s);
    let optimal = match traced {
        Ok(()) => Some(bounds::time_optimal_s(&plan, canon, cfg)?),
        Err(_) => None,
    };
    writeln!(out, "file:            {name}")?;
    writeln!(
        out,
        "planned:         {} lines, {} segments in {:.1} ms ({:.0} segments/s)",
        plan.line_count,
        plan.segment_count,
        plan_s * 1e3,
        plan.segment_count as f64 / plan_s.max(1e-9)
    )?;
    writeln!(
        out,
        "job time:        {:.3} s at 100% override",
        plan.duration_s
    )?;
    writeln!(out, "distance:        {:.3} mm", plan.distance_mm)?;
    let probes = plan
        .items
        .iter()
        .filter(|i| matches!(i, motion::Item::Aux(a) if matches!(a.kind, motion::AuxKind::ProbeArm { .. })))
        .count();
    if probes > 0 {
        writeln!(
            out,
            "probes:          {probes} (G38 moves planned to their programmed end; on the \
             machine each stops at contact and the program goes on from there)"
        )?;
    }
    let ratio = |x: f64| {
        if x > 0.0 {
            plan.duration_s / x
        } else {
            f64::NAN
        }
    };
    writeln!(
        out,
        "feed bound:      {:.3} s  (plan = {:.3}x)",
        b.feed_limited_s,
        ratio(b.feed_limited_s)
    )?;
    if let Some(optimal) = optimal {
        writeln!(
            out,
            "optimal bound:   {:.3} s  (plan = {:.3}x; time-optimal on the planned path, no jerk limit)",
            optimal,
            ratio(optimal)
        )?;
    }
    writeln!(
        out,
        "corner estimate: {:.3} s  (plan = {:.3}x; programmed polyline, not a bound)",
        b.corner_estimate_s,
        ratio(b.corner_estimate_s)
    )?;
    writeln!(
        out,
        "stop at corners: {:.3} s  (plan = {:.3}x)",
        b.naive_stop_s,
        ratio(b.naive_stop_s)
    )?;
    if let Err(e) = traced {
        writeln!(out, "trace:           not run: {e}")?;
        return Ok(true);
    }
    let tr = trace::measure(&plan, cfg, trace::max_periods(&plan, cfg));
    let pk = tr.peaks;
    writeln!(
        out,
        "trace:           {} periods of {:.3} ms = {:.3} s",
        tr.periods,
        cfg.servo_period_s * 1e3,
        tr.duration_s
    )?;
    writeln!(out, "axis   peak vel / limit (mm/s)      peak acc / limit (mm/s²)     peak jerk / limit (mm/s³)")?;
    let mut within = true;
    for (a, l) in cfg.axes.iter().enumerate() {
        if pk.vel[a] == 0.0 {
            continue;
        }
        let pct = |x: f64, lim: f64| 100.0 * x / lim;
        writeln!(
            out,
            "{}      {:>9.3} / {:<9.3} {:>5.1}%  {:>10.2} / {:<10.2} {:>5.1}%  {:>11.1} / {:<11.1} {:>5.1}%",
            AXIS_NAMES[a],
            pk.vel[a],
            l.max_vel_mm_s,
            pct(pk.vel[a], l.max_vel_mm_s),
            pk.acc[a],
            l.max_acc_mm_s2,
            pct(pk.acc[a], l.max_acc_mm_s2),
            pk.jerk[a],
            l.max_jerk_mm_s3,
            pct(pk.jerk[a], l.max_jerk_mm_s3)
        )?;
        within &= pk.vel[a] <= l.max_vel_mm_s * 1.000_001
            && pk.acc[a] <= l.max_acc_mm_s2 * 1.000_001
            && pk.jerk[a] <= l.max_jerk_mm_s3 * 1.000_001;
    }
    if !within {
        writeln!(out, "LIMIT EXCEEDED")?;
    }
    Ok(within)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn a_machine_description_gives_its_limits() {
        let args = MotionArgs {
            config: Some(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim.toml")),
            ..MotionArgs::default()
        };
        let cfg = args.config().unwrap();
        assert_eq!(cfg.axes[0].max_vel_mm_s, 100.0);
        assert_eq!(cfg.axes[2].max_vel_mm_s, 50.0);
        assert_eq!((cfg.axes[2].min_mm, cfg.axes[2].max_mm), (-100.0, 0.0));
    }

    #[test]
    fn config_file_then_flags_override_defaults() {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        writeln!(
            f,
            "max_vel_mm_s = 80.0\nmax_acc_mm_s2 = 1000.0\nservo_period_s = 0.0005\n\
             spans = false\nfit_arcs = false"
        )
        .unwrap();
        let args = MotionArgs {
            motion_file: Some(f.path().into()),
            max_acc: Some(700.0),
            ..Default::default()
        };
        let cfg = args.config().unwrap();
        assert_eq!(cfg.axes[0].max_vel_mm_s, 80.0);
        assert_eq!(cfg.axes[2].max_acc_mm_s2, 700.0);
        assert_eq!(cfg.axes[3], MotionConfig::default().axes[3]);
        assert_eq!(cfg.servo_period_s, 0.0005);
        assert!(!cfg.spans && !cfg.fit_arcs);
        assert!(MotionArgs::default().config().unwrap().spans);
    }

    #[test]
    fn report_names_time_bounds_and_axis_peaks() {
        use crate::gcode::{Canon, CanonCmd, SourceLoc};
        let loc = |line| SourceLoc {
            file: "t.ngc".into(),
            line,
            col: 1,
        };
        let mut p = [0.0; 9];
        p[0] = 30.0;
        p[1] = 10.0;
        let canon = vec![
            Canon {
                loc: loc(1),
                cmd: CanonCmd::SetFeedRate(1200.0),
            },
            Canon {
                loc: loc(2),
                cmd: CanonCmd::StraightFeed(p),
            },
        ];
        let mut out = String::new();
        assert!(report(
            "t.ngc",
            &canon,
            &MotionConfig::default(),
            DEFAULT_MAX_TRACE_S,
            &mut out
        )
        .unwrap());
        assert!(out.contains("job time:"), "{out}");
        assert!(out.contains("distance:        31.623 mm"), "{out}");
        assert!(out.contains("feed bound:      1.581 s"), "{out}");
        assert!(
            out.lines().any(|l| l.starts_with("X ")) && out.lines().any(|l| l.starts_with("Y "))
        );
        assert!(!out.lines().any(|l| l.starts_with("Z ")));
    }

    /// A program that changes tools plans with the config's tool table, or one given on
    /// the command line; without either its M6 fails as in `hytask gcode canon`.
    #[test]
    fn plan_uses_the_tool_table_of_the_command_line_or_the_config() {
        let dir = tempfile::tempdir().unwrap();
        let tbl = dir.path().join("tools.tbl");
        std::fs::write(&tbl, "T4 P4 Z12.5 D6 ;end mill\n").unwrap();
        let sim = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim.toml"),
        )
        .unwrap();
        let cfg_path = dir.path().join("machine.toml");
        std::fs::write(
            &cfg_path,
            format!("{sim}\n[tool_table]\npath = \"tools.tbl\"\n"),
        )
        .unwrap();
        let prog = dir.path().join("p.ngc");
        std::fs::write(&prog, "G21 T4 M6\nG43 H4\nG0 X10 Z0\nM2\n").unwrap();

        assert!(
            load(&prog, &MotionArgs::default()).is_err(),
            "no table: tool 4 unknown"
        );
        let with_cfg = MotionArgs {
            config: Some(cfg_path),
            ..MotionArgs::default()
        };
        let offset = |canon: &[crate::gcode::Canon]| {
            canon.iter().find_map(|c| match &c.cmd {
                crate::gcode::CanonCmd::UseToolLengthOffset(o) if o[2] != 0.0 => Some(o[2]),
                _ => None,
            })
        };
        assert_eq!(offset(&load(&prog, &with_cfg).unwrap()), Some(12.5));
        let with_flag = MotionArgs {
            tool_table: Some(tbl),
            ..MotionArgs::default()
        };
        assert_eq!(offset(&load(&prog, &with_flag).unwrap()), Some(12.5));
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        writeln!(f, "max_velocity = 80.0").unwrap();
        let args = MotionArgs {
            motion_file: Some(f.path().into()),
            ..Default::default()
        };
        assert!(args.config().is_err());
        let args = MotionArgs {
            max_vel: Some(-1.0),
            ..Default::default()
        };
        assert!(args.config().is_err());
    }
}
