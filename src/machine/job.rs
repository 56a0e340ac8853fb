//! Job preparation, off the realtime path: interpret a G-code program in full, plan it in
//! full (soft limits, kinematics, every axis limit), and only then hand it to the machine.
//! A job with any error is refused as a whole before anything moves, and the error names
//! file, line and column.
//!
//! # Memory: plan twice, keep the text
//!
//! A planned segment is ~400 bytes and a CAM surfacing job has ~2.3 segments per line, so a
//! million-line job's queue alone is ~900 MB; the interpreter's commands and the planner's
//! intermediates used to add as much again while it was prepared. A job is therefore
//! interpreted and planned as a stream ([`gcode::Chunked`] → [`motion::stream::PlanStream`]),
//! a chunk of commands at a time, in bounded memory. The first pass validates the whole job
//! (every interpreter error, soft limit, kinematic and axis limit, as before) and keeps the
//! summary, a digest of each batch of items, and the items themselves only while there are
//! at most [`KEEP_ITEMS_MAX`]. A larger job keeps its text instead ([`Replay`]) and its
//! feeder plans it again while it runs: the planner is deterministic, so the second pass
//! produces the same items, and each batch is checked against the first pass' digest
//! *before* it is queued, so nothing that was not validated can move (a subroutine file
//! changed on disk in between, say, ends the job at that batch with an error instead).
//! The feeder plans on a thread of its own up to two batches ahead of the queue
//! ([`Replay::run_ahead`]), so refilling the queue never waits for planning.
//!
//! Why not store a compact plan instead (segments relative to the previous end, profile
//! parameters only)? The segments carry per-segment override limits computed from what
//! follows them, and a lossless encoding of their f64 fields stays above ~150 bytes per
//! segment, ~350 bytes per line: more than ten times the text (~30 bytes per line).
//! Re-planning costs CPU on an ordinary thread (a few µs a line, thousands of times faster
//! than the machine runs it) and no memory. Figures: `benches/README.md`, "Job memory".
//!
//! Errors are found chunk by chunk, in program order: a program with an interpreter error
//! late and a planning error (a soft limit, say) thousands of lines earlier now reports the
//! planning error; both were, and are, refused before anything moves.
//!
//! Preparations are serialised ([`prepare`] waits for the one in progress): parallel loads
//! cannot add up their peaks. A job that probes (G38.x) or waits for an input (M66) is
//! prepared whole as before and runs piece by piece ([`super::probing`]): what follows the
//! probe or the M66 may depend on what the machine measures or reads (#5061–#5070, #5399).

use super::job_cancel::{self, Cancel};
pub use super::job_stream::Replay;
use super::job_stream::{digest, stream_pass, Streamed};
use super::probing::ProbingSource;
use crate::config::MachineConfig;
use crate::gcode::{self, Canon, CanonCmd, InterpOptions, NUM_AXES};
use crate::machine::api::{ApiError, JobSource};
use crate::motion::{self, AxisLimits, KinematicsConfig, MotionConfig, Plan};
use std::path::Path;
use std::sync::Mutex;
use std::time::Duration;

/// Items a prepared job keeps in memory (~25 MB); a job with more keeps its text and is
/// planned again while it runs (see the module doc).
pub const KEEP_ITEMS_MAX: usize = 65_536;

/// One preparation at a time (see the module doc).
static PREPARING: Mutex<()> = Mutex::new(());

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
    /// Set when the program probes (G38.x) or waits for an input (M66): what to interpret
    /// again, live, when it runs.
    pub probing: Option<ProbingSource>,
    /// Set for a job too large to keep its items: `plan.items` is empty and the feeder plans
    /// the job again from this.
    pub replay: Option<Replay>,
    /// The persistent parameters (var file) as the program leaves them: saved when the job
    /// has run to its end (a probing job's: with the simulated probe results).
    /// `None` for a jog.
    pub parameters: Option<gcode::VarFile>,
}

impl PreparedJob {
    /// Items the job puts in the segment queue (the first piece's for a probing job).
    pub fn item_count(&self) -> u64 {
        self.replay
            .as_ref()
            .map_or(self.plan.items.len() as u64, |r| r.items)
    }
}

/// Plans a job before it runs: validation and estimates. A program without probes or M66 is
/// checked in full. One that probes is checked in full up to and including its first probe
/// or M66; what follows depends on the measurements (the dry run's simulated probe runs each
/// move to its programmed end, which may be far from where the machine will touch) or on the
/// input read (the dry run leaves #5399 as it is, so it may take the other branch), so those
/// pieces are checked against the soft limits when they are planned, before they move, and
/// the estimate plans them without soft limits.
fn plan_job(
    canon: &[Canon],
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
    name: &str,
) -> Result<Plan, ApiError> {
    let refuse = |e: motion::PlanError| ApiError::Gcode(format!("{name}: {e}"));
    let Some(k) = first_piece_end(canon) else {
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

/// Where a live job's first piece ends: the first probe move or M66, if any. What follows it
/// depends on what the machine measures (G38.x) or reads (M66, into #5399).
pub fn first_piece_end(canon: &[Canon]) -> Option<usize> {
    canon.iter().position(|c| {
        matches!(
            c.cmd,
            CanonCmd::StraightProbe { .. } | CanonCmd::Wait { .. }
        )
    })
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
    first_piece_end(canon)?;
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
    m.fit_arcs = cfg.motion.fit_arcs;
    m.spans = cfg.motion.spans;
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
        // `#<_ini[section]name>` (issue 13; mapping in config::gcode).
        ini: std::sync::Arc::new(cfg.gcode.ini_values(&cfg.axes)),
        subroutine_path: cfg.gcode.subroutine_path.clone(),
        // The user M codes the PLC handles (issue 11).
        user_mcodes: cfg
            .plc
            .as_ref()
            .map(|p| p.mcodes.clone())
            .unwrap_or_default(),
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
/// `start_mm`, within the default budget ([`crate::config::DEFAULT_PREPARE_TIMEOUT_S`]).
/// Waits while another job is being prepared.
pub fn prepare(
    src: &JobSource,
    opts: &InterpOptions,
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
) -> Result<PreparedJob, ApiError> {
    let budget = Duration::from_secs_f64(crate::config::DEFAULT_PREPARE_TIMEOUT_S);
    prepare_within(src, opts, motion, start_mm, budget)
}

/// [`prepare`] within `budget` of wall-clock time (`[job] prepare_timeout_s`).
pub fn prepare_within(
    src: &JobSource,
    opts: &InterpOptions,
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
    budget: Duration,
) -> Result<PreparedJob, ApiError> {
    prepare_keeping(src, opts, motion, start_mm, KEEP_ITEMS_MAX, budget)
}

/// [`prepare_within`], keeping the items of a plan of at most `keep_items` (tests use 0 to
/// plan every job again when it runs). Once it holds the one-at-a-time lock the preparation
/// can be cancelled ([`job_cancel`]): by `job.abort` or `estop`, by its client disconnecting,
/// or when `budget` has passed.
pub fn prepare_keeping(
    src: &JobSource,
    opts: &InterpOptions,
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
    keep_items: usize,
    budget: Duration,
) -> Result<PreparedJob, ApiError> {
    job_cancel::guarded(&PREPARING, "job", budget, |token| {
        prepare_locked(src, opts, motion, start_mm, keep_items, token)
    })
}

/// [`prepare_keeping`] once it holds the lock; `token` stops the interpreter and the planner.
fn prepare_locked(
    src: &JobSource,
    opts: &InterpOptions,
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
    keep_items: usize,
    token: &Cancel,
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
    // The options kept for running (replay, probing pieces) carry no cancel flag: the
    // token belongs to this preparation only.
    let mut cancellable = opts.clone();
    cancellable.cancel = Some(token.flag());
    let display = Path::new(&name)
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_else(|| name.clone());
    let total_lines = text.lines().count() as u32;
    let mut kept = Some(Vec::new());
    let mut digests = Vec::new();
    let streamed = stream_pass(
        &name,
        text.clone(),
        &cancellable,
        motion,
        start_mm,
        &mut |items| {
            digests.push(digest(items));
            if kept
                .as_ref()
                .is_some_and(|k| k.len() + items.len() > keep_items)
            {
                kept = None;
            }
            if let Some(k) = &mut kept {
                k.extend_from_slice(items);
            }
            true
        },
    )?;
    let (finished, commands, parameters) = match streamed {
        Streamed::Planned(f, c, v) => (*f, c, *v),
        Streamed::Probes | Streamed::Stopped => {
            // A probing job: validated whole with simulated probes, run piece by piece.
            let (program, parameters) = gcode::load_str_persistent(&name, &text, &cancellable)
                .map_err(|e| ApiError::Gcode(e.to_string()))?;
            let plan = plan_job(&program.canon, motion, start_mm, &name)?;
            let probing = probing_source(&program.canon, &name, &text, &opts);
            return Ok(PreparedJob {
                name: display,
                total_lines,
                commands: program.canon.len(),
                plan,
                probing,
                replay: None,
                parameters: Some(parameters),
            });
        }
    };
    let mut plan = finished.plan;
    let replay = match kept {
        Some(items) => {
            plan.items = items;
            None
        }
        None => Some(Replay {
            name,
            text,
            opts,
            motion: motion.clone(),
            start_mm,
            items: finished.items,
            digests,
        }),
    };
    Ok(PreparedJob {
        name: display,
        total_lines,
        commands,
        plan,
        probing: None,
        replay,
        parameters: Some(parameters),
    })
}

/// Interprets and plans one MDI line (the interpreter's MDI mode: no program end needed, none
/// of M2's resets); errors name `mdi:1:col`. Within the default budget, as [`prepare`].
pub fn prepare_mdi(
    line: &str,
    opts: &InterpOptions,
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
) -> Result<PreparedJob, ApiError> {
    let budget = Duration::from_secs_f64(crate::config::DEFAULT_PREPARE_TIMEOUT_S);
    prepare_mdi_within(line, opts, motion, start_mm, budget)
}

/// [`prepare_mdi`] within `budget`. One line may call a subroutine or start a runaway loop,
/// so it is prepared as a job is ([`job_cancel::guarded`]): one at a time, cancelled by
/// `job.abort`, an e-stop, its client hanging up, or the budget running out.
pub fn prepare_mdi_within(
    line: &str,
    opts: &InterpOptions,
    motion: &MotionConfig,
    start_mm: [f64; NUM_AXES],
    budget: Duration,
) -> Result<PreparedJob, ApiError> {
    let mut opts = starting_at(opts, start_mm);
    opts.mdi = true;
    let text = format!("{line}\n");
    job_cancel::guarded(&PREPARING, "MDI", budget, |token| {
        // As for a job: the options kept for probing pieces carry no cancel flag.
        let mut cancellable = opts.clone();
        cancellable.cancel = Some(token.flag());
        let (program, parameters) = gcode::load_str_persistent("mdi", &text, &cancellable)
            .map_err(|e| ApiError::Gcode(e.to_string()))?;
        let plan = plan_job(&program.canon, motion, start_mm, "mdi")?;
        let probing = probing_source(&program.canon, "mdi", &text, &opts);
        Ok(PreparedJob {
            name: "mdi".into(),
            total_lines: 1,
            commands: program.canon.len(),
            plan,
            probing,
            replay: None,
            parameters: Some(parameters),
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sim() -> MachineConfig {
        crate::config::builtin_sim().expect("built-in config")
    }

    const START: [f64; NUM_AXES] = [10.0, 10.0, -5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    /// A budget no test job comes near.
    const LONG: Duration = Duration::from_secs(3600);

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
    fn an_m66_makes_a_job_live_and_only_what_follows_it_is_checked_when_it_runs() {
        // The dry run leaves #5399 at 0: it takes the "else" branch, far outside the soft
        // limits; the machine may answer -1 (a timeout), so that branch is checked against
        // the limits only when its piece is planned, with the answer known.
        let text = "G21 G90\nG0 X10 Y10 Z-5\nM66 P0 L3 Q1\n\
                    O1 if [#5399 LT 0]\n  G0 X20\nO1 else\n  G0 X900\nO1 endif\nM2\n";
        let j = prepare_text(Some("m66.ngc"), text).expect("prepared");
        assert!(j.probing.is_some(), "runs piece by piece");
        // Without an M66 (or a probe) a job is checked whole and runs from its plan.
        let j = prepare_text(None, "G21 G90\nM62 P0\nG0 X20\nM2\n").expect("prepared");
        assert!(j.probing.is_none());
        // Before the first M66 the soft limits hold as for any job.
        let e = prepare_text(Some("m66.ngc"), "G21 G90\nG0 X900\nM66 P0 L0\nM2\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2"), "{e}");
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

    /// A program with a long G64 run, messages and a dwell, prepared so that it keeps no
    /// items (`keep` 0) or all of them.
    fn replayed(keep: usize) -> PreparedJob {
        let mut text = String::from("G21 G90 G64 P0.01\nG0 X10 Y10 Z-5\nF1500\n(MSG, go)\n");
        for i in 0..3000 {
            let x = 10.0 + (i % 400) as f64 * 0.2;
            let y = 10.0 + (i / 400) as f64 * 0.5;
            let z = -6.0 + (x * std::f64::consts::PI).sin();
            text.push_str(&format!("G1 X{x:.3} Y{y:.3} Z{z:.4}\n"));
            if i == 1500 {
                text.push_str("G4 P0.5\n(MSG, half way)\n");
            }
        }
        text.push_str("M2\n");
        let cfg = sim();
        let src = JobSource {
            path: None,
            text: Some(text),
            name: Some("big.ngc".into()),
        };
        prepare_keeping(
            &src,
            &interp_options(&cfg),
            &motion_config(&cfg),
            START,
            keep,
            LONG,
        )
        .expect("plans")
    }

    #[test]
    fn a_job_planned_again_while_it_runs_queues_exactly_the_validated_items() {
        let kept = replayed(usize::MAX);
        assert!(kept.replay.is_none());
        let big = replayed(0);
        assert!(big.plan.items.is_empty(), "a replayed job keeps no items");
        let replay = big.replay.as_ref().expect("replayed");
        let mut fed = Vec::new();
        let done = replay.run(&mut |batch| {
            fed.extend_from_slice(batch);
            true
        });
        assert_eq!(done, Ok(true));
        assert_eq!(fed, kept.plan.items);
        let mut ahead = Vec::new();
        let done = replay.run_ahead(&mut |batch| {
            ahead.extend_from_slice(batch);
            true
        });
        assert_eq!(done, Ok(true));
        assert_eq!(ahead, kept.plan.items);
        assert_eq!(big.item_count(), fed.len() as u64);
        assert_eq!(big.plan.messages, kept.plan.messages);
        assert_eq!(big.plan.messages.len(), 2);
        assert_eq!(
            (big.plan.duration_s, big.plan.segment_count, big.commands),
            (kept.plan.duration_s, kept.plan.segment_count, kept.commands)
        );
        // A cancelled feed stops at once.
        let mut batches = 0;
        assert_eq!(
            replay.run(&mut |_| {
                batches += 1;
                false
            }),
            Ok(false)
        );
        assert_eq!(batches, 1);
    }

    #[test]
    fn a_replay_that_plans_differently_stops_before_queuing_that_batch() {
        let mut big = replayed(0);
        let replay = big.replay.as_mut().expect("replayed");
        let last = replay.digests.len() - 1;
        replay.digests[last] ^= 1;
        let mut fed = 0;
        let e = replay
            .run(&mut |_| {
                fed += 1;
                true
            })
            .unwrap_err();
        assert_eq!(fed, last, "only the matching batches were queued");
        assert!(e.contains("big.ngc") && e.contains("differently"), "{e}");
        fed = 0;
        let e = replay
            .run_ahead(&mut |_| {
                fed += 1;
                true
            })
            .unwrap_err();
        assert_eq!(fed, last, "planned ahead, queued only when it matched");
        assert!(e.contains("differently"), "{e}");
    }

    #[test]
    fn preparations_wait_for_the_one_in_progress() {
        let guard = PREPARING.lock().unwrap_or_else(|p| p.into_inner());
        let (tx, rx) = std::sync::mpsc::channel();
        let t = std::thread::spawn(move || {
            let r = prepare_text(None, "G0 X20\nM2\n").map(|j| j.plan.end_mm[0]);
            let _ = tx.send(r.is_ok());
        });
        std::thread::sleep(std::time::Duration::from_millis(200));
        assert!(
            rx.try_recv().is_err(),
            "prepared while another preparation ran"
        );
        drop(guard);
        let ok = rx
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect("prepared once the other one ended");
        assert!(ok);
        t.join().expect("joins");
    }

    #[test]
    fn a_cancelled_replay_stops_planning_at_once() {
        // Long enough for several batches; a line near the end that only the interpreter
        // refuses shows whether the replay went on after it was told to stop.
        let mut text = String::from("G21 G90 G64 P0.01\nG0 X10 Y10 Z-5\nF1500\n");
        for i in 0..40_000 {
            let x = 10.0 + (i % 400) as f64 * 0.2;
            let y = 10.0 + (i / 400) as f64 * 0.5;
            let z = -6.0 + (x * std::f64::consts::PI).sin();
            text.push_str(&format!("G1 X{x:.3} Y{y:.3} Z{z:.4}\n"));
        }
        let good = format!("{text}M2\n");
        let cfg = sim();
        let src = JobSource {
            path: None,
            text: Some(good),
            name: Some("long.ngc".into()),
        };
        let (o, m) = (interp_options(&cfg), motion_config(&cfg));
        let mut job = prepare_keeping(&src, &o, &m, START, 0, LONG).expect("plans");
        let replay = job.replay.as_mut().expect("replayed");
        assert!(replay.digests.len() >= 2, "{}", replay.digests.len());
        replay.text = format!("{text}G1 X10 G0\nM2\n");
        let mut batches = 0;
        let out = replay.run(&mut |_| {
            batches += 1;
            false
        });
        assert_eq!((out, batches), (Ok(false), 1));
        batches = 0;
        let out = replay.run_ahead(&mut |_| {
            batches += 1;
            false
        });
        assert_eq!((out, batches), (Ok(false), 1));
    }

    /// `o1 repeat [99999999]`: ten million iterations, a minute or more to the loop limit.
    const RUNAWAY: &str = "o1 repeat [99999999]\n#1=[#1+1]\no1 endrepeat\nM2\n";

    fn inline(text: &str) -> JobSource {
        JobSource {
            path: None,
            text: Some(text.into()),
            name: Some("runaway.ngc".into()),
        }
    }

    #[test]
    fn a_preparation_past_its_budget_is_refused_naming_the_key_and_the_next_one_runs() {
        let cfg = sim();
        let (o, m) = (interp_options(&cfg), motion_config(&cfg));
        let budget = Duration::from_millis(50);
        let t0 = std::time::Instant::now();
        let e = prepare_within(&inline(RUNAWAY), &o, &m, START, budget).unwrap_err();
        let ApiError::Timeout(msg) = &e else {
            panic!("{e:?}")
        };
        assert_eq!(
            msg,
            "job preparation took longer than 0.05 s (job.prepare_timeout_s)"
        );
        // Hang guard only: without the budget this ran to the loop limit.
        assert!(t0.elapsed() < Duration::from_secs(60), "{:?}", t0.elapsed());
        // The lock is free again.
        let j = prepare_within(&inline("G0 X20\nM2\n"), &o, &m, START, LONG).expect("plans");
        assert!((j.plan.end_mm[0] - 20.0).abs() < 1e-9);
    }

    #[test]
    fn a_cancelled_request_token_stops_its_preparation_and_no_other() {
        let cfg = sim();
        let (o, m) = (interp_options(&cfg), motion_config(&cfg));
        let token = Cancel::new();
        let (tx, rx) = std::sync::mpsc::channel();
        let t = {
            let (token, o, m) = (token.clone(), o.clone(), m.clone());
            std::thread::spawn(move || {
                let r = job_cancel::with_request_token(&token, || {
                    prepare_within(&inline(RUNAWAY), &o, &m, START, LONG)
                });
                let _ = tx.send(r.map(|_| ()));
            })
        };
        // Before the preparation began or while it runs: either way it ends cancelled.
        token.cancel(job_cancel::Why::Disconnected);
        let r = rx
            .recv_timeout(Duration::from_secs(60))
            .expect("cancelled preparation ended");
        t.join().expect("joins");
        let e = r.unwrap_err().to_string();
        assert!(e.contains("client disconnected"), "{e}");
        // A job prepared under a token keeps running when the token is cancelled later: what
        // it stores to plan again carries no cancel flag.
        let token = Cancel::new();
        let mut text = String::from("G21 G90 G64 P0.01\nG0 X10 Y10 Z-5\nF1500\n");
        for i in 0..3000 {
            text.push_str(&format!("G1 X{} Y{}\n", 10 + i % 100, 10 + i / 100));
        }
        text.push_str("M2\n");
        let job = job_cancel::with_request_token(&token, || {
            prepare_keeping(&inline(&text), &o, &m, START, 0, LONG)
        })
        .expect("plans");
        token.cancel(job_cancel::Why::Disconnected);
        let replay = job.replay.as_ref().expect("replayed");
        assert_eq!(replay.run(&mut |_| true), Ok(true));
    }

    /// Interpreter options whose subroutine path holds `spin.ngc`, a sub running [`RUNAWAY`]'s
    /// loop: `o<spin> call` is a one-line runaway MDI.
    fn with_spin_sub(o: &InterpOptions) -> (InterpOptions, tempfile::TempDir) {
        let dir = tempfile::tempdir().expect("temp dir");
        let sub = "o<spin> sub\no1 repeat [99999999]\n#1=[#1+1]\no1 endrepeat\no<spin> endsub\n";
        std::fs::write(dir.path().join("spin.ngc"), sub).expect("writes");
        let mut o = o.clone();
        o.subroutine_path = vec![dir.path().to_path_buf()];
        (o, dir)
    }

    #[test]
    fn a_runaway_mdi_line_is_bounded_by_the_budget_and_cancelled_by_its_token() {
        let cfg = sim();
        let (o, m) = (interp_options(&cfg), motion_config(&cfg));
        let (o, _dir) = with_spin_sub(&o);
        let t0 = std::time::Instant::now();
        let e = prepare_mdi_within("o<spin> call", &o, &m, START, Duration::from_millis(50))
            .unwrap_err();
        assert_eq!(
            e,
            ApiError::Timeout(
                "MDI preparation took longer than 0.05 s (job.prepare_timeout_s)".into()
            )
        );
        // Hang guard only: without the budget this ran to the loop limit.
        assert!(t0.elapsed() < Duration::from_secs(60), "{:?}", t0.elapsed());
        // Cancelled before or while it runs: it ends cancelled. (Its own token: these
        // preparations belong to no machine, see `job_cancel::with_owner`.)
        let token = Cancel::new();
        let (tx, rx) = std::sync::mpsc::channel();
        let t = std::thread::spawn({
            let (o, m, token) = (o.clone(), m.clone(), token.clone());
            move || {
                let r = job_cancel::with_request_token(&token, || {
                    prepare_mdi_within("o<spin> call", &o, &m, START, LONG)
                });
                let _ = tx.send(r);
            }
        });
        token.cancel(job_cancel::Why::Abort);
        let r = rx
            .recv_timeout(Duration::from_secs(60))
            .expect("cancelled preparation ended");
        t.join().expect("joins");
        assert_eq!(
            r.map(|_| ()),
            Err(ApiError::Failed(
                "MDI preparation cancelled by job.abort".into()
            ))
        );
        // The lock is free again and an ordinary line plans.
        let j = prepare_mdi_within("G0 X20", &o, &m, START, LONG).expect("plans");
        assert!((j.plan.end_mm[0] - 20.0).abs() < 1e-9);
    }

    #[test]
    fn a_preparation_cancelled_after_its_last_poll_is_refused_all_the_same() {
        let cfg = sim();
        let (o, m) = (interp_options(&cfg), motion_config(&cfg));
        let token = Cancel::new();
        // Cancelled inside the preparation, after the interpreter's last poll: the plan
        // succeeds, the answer is the cancel (an MDI line must not move after job.abort).
        let r = job_cancel::with_request_token(&token, || {
            job_cancel::guarded(&PREPARING, "MDI", LONG, |t| {
                let j = prepare_locked(&inline("G0 X20\nM2\n"), &o, &m, START, 10, t);
                t.cancel(job_cancel::Why::Abort);
                j
            })
        });
        assert_eq!(
            r.map(|_| ()),
            Err(ApiError::Failed(
                "MDI preparation cancelled by job.abort".into()
            ))
        );
    }
}
