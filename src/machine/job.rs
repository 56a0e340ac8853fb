//! Job preparation, off the realtime path: interpret a G-code program in full, plan it in
//! full (soft limits, kinematics, every axis limit), and only then hand it to the machine.
//! A job with any error is refused as a whole before anything moves, and the error names
//! file, line and column.

use super::probing::ProbingSource;
use crate::config::MachineConfig;
use crate::gcode::{self, Canon, CanonCmd, InterpOptions, NUM_AXES};
use crate::machine::api::{ApiError, JobSource};
use crate::motion::{self, AxisLimits, KinematicsConfig, MotionConfig, Plan};
use std::path::Path;

/// A job that interpreted and planned without error.
#[derive(Debug, Clone)]
pub struct PreparedJob {
    /// Display name (file name, or the given name for inline text).
    pub name: String,
    /// Lines in the source text.
    pub total_lines: u32,
    /// Canonical commands the interpreter produced.
    pub commands: usize,
    /// The plan: segment queue, messages, duration, distance. For a job that probes, the
    /// plan of the whole program with simulated probes (each trips at its programmed end):
    /// it validates the job and estimates its time; the job then runs piece by piece.
    pub plan: Plan,
    /// Set when the program probes (G38.x): what to interpret again, live, when it runs.
    pub probing: Option<ProbingSource>,
}

/// Line of the first probe move, if the program probes.
pub fn first_probe_line(canon: &[Canon]) -> Option<u32> {
    canon
        .iter()
        .find(|c| matches!(c.cmd, CanonCmd::StraightProbe { .. }))
        .map(|c| c.loc.line)
}

/// Plans a job before it runs: validation and estimates. A program without probes is checked
/// in full. One that probes is checked in full up to and including its first probe; what
/// follows depends on the measurements (the dry run's simulated probe runs each move to its
/// programmed end, which may be far from where the machine will touch), so those pieces are
/// checked against the soft limits when they are planned, before they move, and the estimate
/// plans them without soft limits.
fn plan_job(
    canon: &[Canon],
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
    name: &str,
) -> Result<Plan, ApiError> {
    let refuse = |e: motion::PlanError| ApiError::Gcode(format!("{name}: {e}"));
    let Some(k) = canon
        .iter()
        .position(|c| matches!(c.cmd, CanonCmd::StraightProbe { .. }))
    else {
        return motion::plan_from(canon, motion, start_mm).map_err(refuse);
    };
    let first = motion::plan_from(&canon[..=k], motion, start_mm).map_err(refuse)?;
    let mut relaxed = motion.clone();
    for a in relaxed.axes.iter_mut().filter(|a| a.min_mm < a.max_mm) {
        a.min_mm = -1e9;
        a.max_mm = 1e9;
    }
    Ok(motion::plan_from(canon, &relaxed, start_mm).unwrap_or(first))
}

/// Line of the first probe move of a prepared job, if it probes.
pub fn first_probe_line_of(job: &PreparedJob) -> Option<u32> {
    job.plan.items.iter().find_map(|i| match i {
        motion::Item::Aux(a) if matches!(a.kind, motion::AuxKind::ProbeArm { .. }) => Some(a.line),
        _ => None,
    })
}

fn probing_source(
    canon: &[Canon],
    name: &str,
    text: &str,
    opts: &InterpOptions,
) -> Option<ProbingSource> {
    first_probe_line(canon)?;
    Some(ProbingSource {
        name: name.to_string(),
        text: text.to_string(),
        opts: opts.clone(),
    })
}

/// Maps the machine description onto the planner's plain-data configuration.
pub fn motion_config(cfg: &MachineConfig) -> MotionConfig {
    let mut m = MotionConfig::default();
    if let Some(t) = cfg.servo_thread() {
        m.servo_period_s = t.period_us as f64 * 1e-6;
    }
    for a in &cfg.axes {
        let i = a.name as usize;
        m.axes[i] = AxisLimits {
            max_vel_mm_s: a.max_velocity,
            max_acc_mm_s2: a.max_acceleration,
            // No jerk limit configured: full acceleration within one servo period, which is
            // the trapezoidal profile at the servo's resolution.
            max_jerk_mm_s3: a.max_jerk.unwrap_or(a.max_acceleration / m.servo_period_s),
            min_mm: a.min_limit,
            max_mm: a.max_limit,
        };
    }
    // Axes the machine does not have may not move at all: zero travel.
    for (i, limits) in m.axes.iter_mut().enumerate() {
        if !cfg.axes.iter().any(|a| a.name as usize == i) {
            limits.min_mm = 0.0;
            limits.max_mm = 0.0;
        }
    }
    m.lookahead_moves = cfg.motion.lookahead as usize;
    m.default_tolerance_mm = cfg.motion.g64_tolerance;
    m.max_feed_override = cfg.motion.max_feed_override;
    m.kinematics = match cfg.machine.kinematics() {
        crate::config::Kinematics::Identity => KinematicsConfig::Identity,
        crate::config::Kinematics::Scara { link1_mm, link2_mm } => {
            let mut sc = motion::ScaraConfig {
                link1_mm,
                link2_mm,
                elbow_positive: true,
                joint_min: [-1.0e9; NUM_AXES],
                joint_max: [1.0e9; NUM_AXES],
                joint_max_vel: [1.0e9; NUM_AXES],
            };
            // Joint speeds: the configured axis velocities of the joints (deg/s for the two
            // arm joints, mm/s for Z), as the drives of those joints are limited.
            for a in &cfg.axes {
                sc.joint_max_vel[a.name as usize] = a.max_velocity;
            }
            sc.joint_min[0] = -180.0;
            sc.joint_max[0] = 180.0;
            sc.joint_min[1] = -170.0;
            sc.joint_max[1] = 170.0;
            KinematicsConfig::Scara(sc)
        }
    };
    m
}

/// Interpreter options for this machine (tool table, machine units).
pub fn interp_options(cfg: &MachineConfig) -> InterpOptions {
    InterpOptions {
        tool_table: cfg.tool_table.as_ref().map(|t| t.path.clone()),
        ..InterpOptions::default()
    }
}

/// The interpreter starts where the machine is, so that a first move naming only some axes
/// leaves the others alone and incremental moves start from the real position.
fn starting_at(opts: &InterpOptions, start_mm: [f64; NUM_AXES]) -> InterpOptions {
    let mut o = opts.clone();
    let mut p = [0.0; 6];
    p.copy_from_slice(&start_mm[..6]);
    o.initial_position = Some(p);
    o
}

/// Interprets and plans a job from a file or inline text, starting at machine pose
/// `start_mm`.
pub fn prepare(
    src: &JobSource,
    opts: &InterpOptions,
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
) -> Result<PreparedJob, ApiError> {
    let (name, text) = match (&src.path, &src.text) {
        (Some(path), None) => {
            let text = super::job_file::read(path)?;
            (path.clone(), text)
        }
        (None, Some(text)) => (
            src.name.clone().unwrap_or_else(|| "inline".into()),
            text.clone(),
        ),
        _ => {
            return Err(ApiError::InvalidParams(
                "give exactly one of 'path' or 'text'".into(),
            ))
        }
    };
    let mut opts = starting_at(opts, start_mm);
    if let Some(p) = &src.path {
        // Subroutine files are also searched next to the program.
        opts.program_dir = Path::new(p).parent().map(Path::to_path_buf);
    }
    let program =
        gcode::load_str(&name, &text, &opts).map_err(|e| ApiError::Gcode(e.to_string()))?;
    let plan = plan_job(&program.canon, motion, start_mm, &name)?;
    let probing = probing_source(&program.canon, &name, &text, &opts);
    let display = Path::new(&name)
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or(name);
    Ok(PreparedJob {
        name: display,
        total_lines: text.lines().count() as u32,
        commands: program.canon.len(),
        plan,
        probing,
    })
}

/// Interprets and plans one MDI line (the interpreter's MDI mode: no program end needed, none
/// of M2's resets); errors name `mdi:1:col`.
pub fn prepare_mdi(
    line: &str,
    opts: &InterpOptions,
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
) -> Result<PreparedJob, ApiError> {
    let mut opts = starting_at(opts, start_mm);
    opts.mdi = true;
    let text = format!("{line}\n");
    let program =
        gcode::load_str("mdi", &text, &opts).map_err(|e| ApiError::Gcode(e.to_string()))?;
    let plan = plan_job(&program.canon, motion, start_mm, "mdi")?;
    let probing = probing_source(&program.canon, "mdi", &text, &opts);
    Ok(PreparedJob {
        name: "mdi".into(),
        total_lines: 1,
        commands: program.canon.len(),
        plan,
        probing,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sim() -> MachineConfig {
        crate::config::builtin_sim().expect("built-in config")
    }

    const START: [f64; NUM_AXES] = [10.0, 10.0, -5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];

    /// Prepares inline `text` named `name` on the built-in mill, starting at [`START`].
    fn prepare_text(name: Option<&str>, text: &str) -> Result<PreparedJob, ApiError> {
        let cfg = sim();
        let src = JobSource {
            path: None,
            text: Some(text.into()),
            name: name.map(str::to_string),
        };
        prepare(&src, &interp_options(&cfg), &motion_config(&cfg), START)
    }

    #[test]
    fn motion_config_takes_axis_limits_and_servo_period() {
        let m = motion_config(&sim());
        assert_eq!(m.axes[0].max_vel_mm_s, 100.0);
        assert_eq!(m.axes[2].min_mm, -100.0);
        assert_eq!(m.servo_period_s, 0.001);
        // The sim mill has no A axis: it may not move.
        assert_eq!((m.axes[3].min_mm, m.axes[3].max_mm), (0.0, 0.0));
        m.validate().expect("valid");
    }

    #[test]
    fn a_job_with_a_gcode_error_is_refused_with_its_location() {
        let e =
            prepare_text(Some("bad.ngc"), "G21 G90\nG0 X10 Y10 Z-5\nG1 X20 F600 G0\n").unwrap_err();
        let ApiError::Gcode(msg) = e else {
            panic!("{e:?}")
        };
        assert!(msg.starts_with("bad.ngc:3:"), "{msg}");
    }

    #[test]
    fn a_job_leaving_the_soft_limits_is_refused_before_motion() {
        let e = prepare_text(
            Some("far.ngc"),
            "G21 G90\nG0 X10 Y10 Z-5\nG1 X400 F600\nM2\n",
        )
        .unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("far.ngc") && msg.contains("line 3") && msg.contains("400"),
            "{msg}"
        );
    }

    #[test]
    fn mdi_lines_need_no_program_end_and_errors_name_line_one() {
        let cfg = sim();
        let start = [10.0, 10.0, -5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let (o, m) = (interp_options(&cfg), motion_config(&cfg));
        let j = prepare_mdi("G0 X20", &o, &m, start).expect("plans");
        assert!((j.plan.end_mm[0] - 20.0).abs() < 1e-9);
        let e = prepare_mdi("G1 X20 G0", &o, &m, start)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("mdi:1:"), "{e}");
    }

    #[test]
    fn a_job_starts_from_the_machine_position() {
        // After homing the sim mill is at X300 Y300 Z0. A first move naming only Z must not
        // move X and Y (LinuxCNC reads the start position from the machine too).
        let cfg = sim();
        let start = [300.0, 300.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let src = JobSource {
            path: None,
            text: Some("G21 G90\nG0 Z-5\nG91 G1 X-10 F600\nM2\n".into()),
            name: None,
        };
        let j = prepare(&src, &interp_options(&cfg), &motion_config(&cfg), start).expect("plans");
        let mut moves = j.plan.items.iter().filter_map(|i| match i {
            crate::motion::Item::Segment(s) => Some(s.end_mm),
            _ => None,
        });
        let first = moves.next().expect("a segment");
        assert_eq!(
            (first[0], first[1]),
            (300.0, 300.0),
            "X/Y moved on a Z-only move"
        );
        assert_eq!(&j.plan.end_mm[..3], &[290.0, 300.0, -5.0]);
        // MDI too: an incremental move from where the machine is.
        let m = prepare_mdi(
            "G91 G0 Y-7",
            &interp_options(&cfg),
            &motion_config(&cfg),
            j.plan.end_mm,
        )
        .expect("plans");
        assert_eq!(&m.plan.end_mm[..3], &[290.0, 293.0, -5.0]);
    }

    #[test]
    fn a_good_job_is_planned_in_full() {
        let j = prepare_text(None, "G21 G90\nG0 X10 Y10 Z-5\nG1 X20 F600\nM2\n").expect("plans");
        assert_eq!(j.name, "inline");
        assert_eq!(j.total_lines, 4);
        assert!(
            j.plan.duration_s > 0.9 && j.plan.duration_s < 2.0,
            "{}",
            j.plan.duration_s
        );
        assert!((j.plan.end_mm[0] - 20.0).abs() < 1e-9);
    }
}
