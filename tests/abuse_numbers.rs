//! Numbers of every class in the socket's numeric fields (session 10): subnormals, values
//! below any machine's resolution, values far above its limits. Expected: an invalid-params
//! reply (-32602) naming the field, and nothing moves. The real daemon on the simulated
//! clock; waits are hang guards (60 s and more).
#![allow(clippy::unwrap_used)]

mod support;

use serde_json::{json, Value};
use support::*;

/// Calls `method` with `params`, expects -32602 naming `field`; returns the message.
fn refused(c: &mut hytask::control::client::Client, method: &str, params: Value, field: &str) {
    let (code, msg) = err(c, method, params.clone());
    assert_eq!(code, -32602, "{method} {params}: {msg}");
    assert!(msg.contains(field), "{method} {params}: {msg}");
}

/// Found in session 10: `jog` at velocity 1e-320 (a subnormal) was accepted and planned a
/// move of ~1e320 s; distances had the same hole.
#[test]
fn absurd_jog_numbers_and_overrides_are_refused_naming_the_field() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    let before = ok(&mut c, "status", Value::Null);
    for v in [1e-320, -5e-324, 1e-9, -1e-4] {
        refused(
            &mut c,
            "jog",
            json!({"axis": "X", "velocity": v}),
            "velocity",
        );
        let p = json!({"axis": "X", "velocity": v, "distance": 1.0});
        refused(&mut c, "jog", p, "velocity");
    }
    for dist in [1e-320, 1e-9, 1e300, -1.0] {
        let p = json!({"axis": "X", "velocity": 5.0, "distance": dist});
        refused(&mut c, "jog", p, "distance");
    }
    let (_, msg) = err(&mut c, "jog", json!({"axis": "X", "velocity": 1e-320}));
    assert!(msg.contains("1e-320") && msg.contains("1e-3"), "{msg}");
    for field in ["feed", "rapid", "spindle"] {
        for v in [1e-320, 5e-324, 1e-6] {
            refused(&mut c, "override", json!({ field: v }), field);
        }
    }
    // Nothing moved, nothing changed.
    let s = ok(&mut c, "status", Value::Null);
    assert_eq!(s["mode"], json!("idle"), "{s}");
    for a in ["X", "Y", "Z"] {
        assert_eq!(
            axis(&s, a)["commanded"],
            axis(&before, a)["commanded"],
            "{a}"
        );
    }
    assert_eq!(s["overrides"], before["overrides"], "{s}");
    // The legal edges still work: 0 (a hold) and the smallest override, a slow short jog,
    // a speed above the axis limit (clamped).
    let o = ok(&mut c, "override", json!({"feed": 0.0, "rapid": 0.001}));
    assert_eq!(
        (o["feed"].as_f64(), o["rapid"].as_f64()),
        (Some(0.0), Some(0.001))
    );
    ok(&mut c, "override", json!({"feed": 1.0, "rapid": 1.0}));
    ok(
        &mut c,
        "jog",
        json!({"axis": "X", "velocity": -1e300, "distance": 0.5}),
    );
    wait_status(&mut c, "the jog ended", GUARD, |s| {
        s["mode"] == json!("idle")
    });
}

const GUARD: std::time::Duration = std::time::Duration::from_secs(120);

/// Found in session 10: a feed written with 320 zeros (`F0.000…1`, a subnormal) was planned
/// as a move of ~1e321 s (and made `hytask plan` overflow). Refused by position, as a
/// G-code error (code 3), by MDI and by `job.load`.
#[test]
fn a_feed_below_any_resolution_is_refused_by_position() {
    let d = Daemon::start_sim();
    let mut c = d.client();
    ready(&mut c);
    let tiny = format!("0.{}1", "0".repeat(318));
    let (code, msg) = err(&mut c, "mdi", json!({"line": format!("G1 X10 F{tiny}")}));
    assert_eq!(code, 3, "{msg}");
    assert!(
        msg.contains("mdi:1:") && msg.contains("below the slowest accepted 1e-6"),
        "{msg}"
    );
    let text = "G21 G90\nG0 X20 Y20 Z-5\nG1 X30 F0.0000001\nM2\n";
    let (code, msg) = err(
        &mut c,
        "job.load",
        json!({"text": text, "name": "slow.ngc"}),
    );
    assert_eq!(code, 3, "{msg}");
    assert!(
        msg.contains("slow.ngc:3:") && msg.contains("F1e-7"),
        "{msg}"
    );
    let s = ok(&mut c, "status", Value::Null);
    assert_eq!(s["mode"], json!("idle"), "{s}");
}
