//! `[motion] fit_arcs` (issue 14): the machine file switches the planner's arc fitting of dense
//! chords; on by default, a wrong type is refused naming the key, and a job planned with it
//! off keeps every chord (no fitted arc in its plan).
#![allow(clippy::unwrap_used)]

use hytask::config::{self, ConfigError, MachineConfig, BUILTIN_SIM_TOML};
use hytask::gcode::NUM_AXES;
use hytask::machine::api::JobSource;
use hytask::machine::job::{interp_options, motion_config, prepare};
use hytask::motion::{Item, Plan};
use std::fmt::Write;

/// The built-in sim file with `fit_arcs = VALUE` in its `[motion]` section.
fn sim_with(value: &str) -> Result<MachineConfig, ConfigError> {
    let from = "fit_arcs = true\n";
    assert!(
        BUILTIN_SIM_TOML.contains(from),
        "sim.toml lost its fit_arcs key"
    );
    config::parse(
        &BUILTIN_SIM_TOML.replacen(from, &format!("fit_arcs = {value}\n"), 1),
        "test.toml",
    )
}

/// Segments of the plan that are arcs (fitted: the program has no G2/G3).
fn arcs(p: &Plan) -> usize {
    p.items
        .iter()
        .filter(|it| matches!(it, Item::Segment(s) if s.curvature_per_mm != 0.0))
        .count()
}

/// 120 chords of 0.5 mm on a circle of radius 40 mm around (100, 100), to four decimals,
/// under G64 P0.01 at F3000: with the sim machine's limits the fitted arcs plan faster than
/// the chords (3.0 s against 3.1 s), so the planner keeps them. (The r 8 mm circle of 0.1 mm
/// chords used before plans faster as chords with these limits, 3.7 s against 5.3 s fitted
/// when written to four decimals, and since session 12 the planner keeps its chords there:
/// `motion::fit_choice`.)
fn dense_circle_job() -> JobSource {
    let mut text = String::from("G21 G90 G17 G64 P0.01\nG0 X140 Y100 Z-5\nF3000\n");
    for i in 1..=120 {
        let a = i as f64 * 0.5 / 40.0;
        let (x, y) = (100.0 + 40.0 * a.cos(), 100.0 + 40.0 * a.sin());
        writeln!(text, "G1 X{x:.4} Y{y:.4}").unwrap();
    }
    text.push_str("M2\n");
    JobSource {
        path: None,
        text: Some(text),
        name: Some("circle.ngc".into()),
    }
}

fn plan_on(cfg: &MachineConfig) -> Plan {
    let job = prepare(
        &dense_circle_job(),
        &interp_options(cfg),
        &motion_config(cfg),
        [0.0; NUM_AXES],
    )
    .unwrap();
    job.plan
}

#[test]
fn fit_arcs_defaults_to_on_and_reaches_the_planner() {
    let text = BUILTIN_SIM_TOML.replacen("fit_arcs = true\n", "", 1);
    let cfg = config::parse(&text, "test.toml").unwrap();
    assert!(cfg.motion.fit_arcs);
    assert!(motion_config(&cfg).fit_arcs);
    let off = sim_with("false").unwrap();
    assert!(!off.motion.fit_arcs);
    assert!(!motion_config(&off).fit_arcs);
    // The resolved file (`hytask check`) shows the key.
    assert!(off.to_toml().unwrap().contains("fit_arcs = false"));
}

#[test]
fn fit_arcs_of_the_wrong_type_is_refused_naming_the_key() {
    match sim_with("\"yes\"") {
        Err(ConfigError::Parse { key, .. }) => assert_eq!(key, "motion.fit_arcs"),
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn a_job_planned_with_fit_arcs_off_keeps_every_chord() {
    let on = plan_on(&sim_with("true").unwrap());
    assert!(arcs(&on) > 0, "the dense circle is fitted by default");
    let off = plan_on(&sim_with("false").unwrap());
    assert_eq!(arcs(&off), 0, "fit_arcs = false fitted arcs");
    assert_eq!(off.end_mm, on.end_mm);
    // Fitting replaces runs of chords by fewer arcs.
    let segments = |p: &Plan| {
        p.items
            .iter()
            .filter(|it| matches!(it, Item::Segment(_)))
            .count()
    };
    assert!(
        segments(&off) > segments(&on),
        "{} vs {}",
        segments(&off),
        segments(&on)
    );
}
