//! The running PLC online (issue 11, section 2): reads, writes, forces and program loads
//! through [`PlcOnline`] while another thread scans the mill's PLC task, as the PLC thread
//! does. The scanning thread counts its allocations: none, the swap of program versions
//! included, and it runs a scan every step (none missed around the swap).
#![allow(clippy::unwrap_used)]

mod counting_alloc;

use hytask::plc::deploy::{prepare, PreparedPlc};
use hytask::plc::online::{OnlineError, PlcOnline};
use hytask::rt::prelude::*;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

const PERIOD_NS: u64 = 10_000_000;

fn mill() -> PreparedPlc {
    let cfg = hytask::config::builtin_sim().unwrap();
    let map = hytask::machine::devices::IoMap::new(&cfg).unwrap();
    prepare(&cfg, &map, 0.001).unwrap().unwrap()
}

fn mill_source() -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/plc/mill.st"))
        .unwrap()
}

/// Scans `plc` on a thread of its own, one scan per millisecond, until `f` returns; gives
/// `f`'s result, the allocations of the scanning thread and (scans counted, steps run).
fn while_scanning<R>(plc: PreparedPlc, f: impl FnOnce(&PlcOnline) -> R) -> (R, u64, (u64, u64)) {
    let PreparedPlc {
        mut task,
        stats,
        online,
        ..
    } = plc;
    let stop = Arc::new(AtomicBool::new(false));
    let stop2 = stop.clone();
    // One warm-up scan before counting, as on the real thread.
    let first = StepContext {
        now_ns: 0,
        period_ns: PERIOD_NS,
        cycle: 0,
    };
    task.update(&first).unwrap();
    let scanner = std::thread::spawn(move || {
        let mut steps = 1u64;
        let allocs = counting_alloc::during(|| {
            while !stop2.load(Ordering::Acquire) {
                let ctx = StepContext {
                    now_ns: steps * PERIOD_NS,
                    period_ns: PERIOD_NS,
                    cycle: steps,
                };
                task.update(&ctx).unwrap();
                steps += 1;
                std::thread::sleep(Duration::from_millis(1));
            }
        });
        (allocs, steps, task)
    });
    let r = f(&online);
    stop.store(true, Ordering::Release);
    let (allocs, steps, task) = scanner.join().unwrap();
    drop(task);
    (r, allocs, (stats.scans.load(Ordering::Relaxed), steps))
}

fn value(o: &PlcOnline, name: &str) -> String {
    o.get(name).unwrap().value
}

#[test]
fn write_force_and_unforce_at_scan_boundaries() {
    let ((), allocs, (scans, steps)) = while_scanning(mill(), |o| {
        let vars = o.vars(None).unwrap();
        assert!(vars
            .iter()
            .any(|v| v.name == "Mill.door_open" && v.r#type == "BOOL"));
        assert!(vars.iter().all(|v| !v.forced));
        assert_eq!(o.vars(Some("DOOR")).unwrap().len(), 1);

        // A write holds until the program changes the variable (nothing here does).
        let v = o.set("target", "5").unwrap();
        assert_eq!((v.name.as_str(), v.value.as_str()), ("Mill.target", "5"));
        assert_eq!(value(o, "Mill.target"), "5");

        // door_open is an input: the input image writes it every scan, the force wins.
        let v = o.force("door_open", "TRUE").unwrap();
        assert!(v.forced && v.value == "TRUE", "{v:?}");
        assert_eq!(
            value(o, "start_inhibit"),
            "TRUE",
            "the program saw the forced value"
        );
        assert_eq!(o.stats().forced.load(Ordering::Relaxed), 1);
        // A write to a forced variable does not beat the force.
        o.set("door_open", "FALSE").unwrap();
        assert_eq!(value(o, "door_open"), "TRUE");
        o.unforce(Some("door_open")).unwrap();
        assert_eq!(value(o, "door_open"), "FALSE", "the input image again");
        assert_eq!(value(o, "start_inhibit"), "FALSE");
        assert_eq!(o.stats().forced.load(Ordering::Relaxed), 0);

        // Refusals name what is wrong.
        assert!(matches!(
            o.set("nosuch", "1"),
            Err(OnlineError::UnknownVar(_))
        ));
        let e = o.set("target", "TRUE").unwrap_err().to_string();
        assert!(e.contains("Mill.target") && e.contains("DINT"), "{e}");
        let e = o.force("pockets", "3").unwrap_err().to_string();
        assert!(e.contains("CONSTANT"), "{e}");
    });
    assert_eq!(allocs, 0, "allocations in the scanning thread");
    assert_eq!(scans, steps, "a scan every step");
}

#[test]
fn a_new_version_takes_over_at_a_scan_boundary_keeping_unchanged_variables() {
    let good = mill_source();
    // A new variable `extra` (initialised), target and pocket unchanged (kept),
    // `was_at_speed` renamed (removed, and the new name initialised).
    let changed = good
        .replace(
            "    pocket : DINT;",
            "    pocket : DINT;\n    extra : DINT := 7;",
        )
        .replace("    was_at_speed : BOOL;\n", "    was_at_speed2 : BOOL;\n")
        .replace("was_at_speed :=", "was_at_speed2 :=")
        .replace("ELSIF was_at_speed THEN", "ELSIF was_at_speed2 THEN");
    assert_ne!(changed, good);
    let broken = good.replace(
        "coolant_pump := flood_cmd OR mist_cmd;",
        "coolant_pump := flood_cmd + 1;\nnosuch := 1;",
    );
    let no_output = good
        .replace("    lube_pump : BOOL;\n", "")
        .replace("lube_pump := lube.Q;\n", "");

    let ((), allocs, (scans, steps)) = while_scanning(mill(), |o| {
        o.set("target", "5").unwrap();
        o.set("pocket", "3").unwrap();
        o.force("door_open", "TRUE").unwrap();

        // Every compile error with file:line:col; the old version runs on.
        let e = o.load("mill2.st", &broken).unwrap_err();
        let text = e.to_string();
        assert!(matches!(e, OnlineError::Compile(_)), "{text}");
        let at = broken.lines().position(|l| l == "nosuch := 1;").unwrap() + 1;
        assert!(text.contains(&format!("mill2.st:{}:", at - 1)), "{text}");
        assert!(text.contains(&format!("mill2.st:{at}:1:")), "{text}");
        assert!(text.contains("unchanged"), "{text}");
        // A version without a bound variable does not fit the bindings.
        let e = o.load("mill3.st", &no_output).unwrap_err().to_string();
        assert!(e.contains("plc.outputs.lube_pump"), "{e}");
        assert_eq!(value(o, "target"), "5");
        assert_eq!(o.stats().reloads.load(Ordering::Relaxed), 0);

        let r = o.load("mill4.st", &changed).unwrap();
        assert_eq!(r.generation, 2);
        assert!(r.kept.contains(&"Mill.target".to_string()), "{r:?}");
        assert!(r.kept.contains(&"Mill.chain.Q1".to_string()), "{r:?}");
        assert_eq!(r.reset, vec!["Mill.was_at_speed2", "Mill.extra"], "{r:?}");
        assert_eq!(r.removed, vec!["Mill.was_at_speed".to_string()]);
        assert_eq!(r.unforced, 1);
        assert_eq!(value(o, "target"), "5", "kept");
        assert_eq!(value(o, "pocket"), "3", "kept");
        assert_eq!(value(o, "extra"), "7");
        assert_eq!(value(o, "door_open"), "FALSE", "forces released");
        assert_eq!(o.stats().reloads.load(Ordering::Relaxed), 1);
        // The new version is the one written to now.
        o.set("extra", "9").unwrap();
        assert_eq!(value(o, "extra"), "9");

        // A type change: initialised, with its new type.
        let r = o
            .load(
                "mill5.st",
                &changed.replace("extra : DINT := 7;", "extra : INT := 4;"),
            )
            .unwrap();
        assert_eq!(r.generation, 3);
        assert_eq!(r.reset, vec!["Mill.extra"], "{r:?}");
        assert_eq!(value(o, "extra"), "4");
        assert_eq!(o.get("extra").unwrap().r#type, "INT");
        assert_eq!(value(o, "target"), "5", "kept across both loads");
    });
    assert_eq!(allocs, 0, "allocations in the scanning thread");
    assert_eq!(scans, steps, "a scan every step, the swap included");
}

/// Reading is open to observers; writing, forcing and loading need an operator.
#[test]
fn observers_read_operators_write() {
    use hytask::control::access::{permits, Role};
    for m in ["plc.vars", "plc.get"] {
        assert!(permits(Role::Observer, m), "{m}");
    }
    for m in ["plc.set", "plc.force", "plc.unforce", "plc.load"] {
        assert!(!permits(Role::Observer, m), "{m}");
        assert!(permits(Role::Operator, m), "{m}");
    }
}
