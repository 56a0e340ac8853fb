//! The planner benchmark's programs (issue 14), generated rather than committed: a square
//! with blends, 3,000 chords of 0.1 mm on a spiral and on a sine (G64 P0.01), and a
//! trochoidal slot of about 11,000 short moves under a bare G64, written the way a CAM
//! post-processor such as gcmc writes them (one `G1 X Y` per line, coordinates rounded to
//! a fixed number of decimals, so the chords carry the quantisation noise of real CAM
//! output). Every program runs at F3000 (50 mm/s, the benchmark's velocity limit).
//!
//! Shared by `examples/planner_programs.rs` (writes the files for `hytask plan` and
//! LinuxCNC) and the tests (`tests/cli_plan.rs`), which include this file with `#[path]`.

#![allow(dead_code)]

use std::fmt::Write;

/// Feed of every program, mm/min (50 mm/s).
pub const FEED_MM_MIN: f64 = 3000.0;

/// One benchmark program.
pub struct Program {
    /// File name (`.ngc`).
    pub name: &'static str,
    /// What it is, for tables.
    pub title: &'static str,
    /// The G-code text.
    pub text: String,
}

/// All programs, in the order.
pub fn all() -> Vec<Program> {
    vec![
        Program {
            name: "square.ngc",
            title: "square with blends",
            text: square(),
        },
        Program {
            name: "spiral.ngc",
            title: "3,000 chords of 0.1 mm on a spiral, G64 P0.01",
            text: spiral(3000, 0.1),
        },
        Program {
            name: "sine.ngc",
            title: "3,000 chords of 0.1 mm on a sine, G64 P0.01",
            text: sine(3000, 0.1),
        },
        Program {
            name: "trochoidal.ngc",
            title: "trochoidal milling (gcmc-style, ~11k lines), bare G64",
            text: trochoidal(),
        },
    ]
}

fn header(out: &mut String, comment: &str, blend: &str) {
    let _ = writeln!(out, "({comment})");
    let _ = writeln!(out, "G21 G90 G17 G94 G40 G49 G80");
    let _ = writeln!(out, "{blend}");
}

fn footer(out: &mut String) {
    out.push_str("M2\n");
}

/// A 50 mm square at F3000 with G64 P0.05 corners, from and back to the origin.
pub fn square() -> String {
    let mut o = String::new();
    header(&mut o, "50 mm square, blended corners", "G64 P0.05");
    let _ = writeln!(o, "G0 X0 Y0 Z0");
    let _ = writeln!(o, "G1 X50 F{FEED_MM_MIN}");
    o.push_str("G1 Y50\nG1 X0\nG1 Y0\n");
    footer(&mut o);
    o
}

/// `n` chords of `step` mm along an Archimedean spiral whose radius grows from 7.5 to
/// 8.5 mm (about 6 turns for 300 mm), coordinates to 4 decimals, G64 P0.01.
pub fn spiral(n: usize, step: f64) -> String {
    let (r0, r1) = (7.5, 8.5);
    let total = n as f64 * step;
    // r(θ) = r0 + k·θ; arc length ≈ mean radius · θ_end.
    let theta_end = total / (0.5 * (r0 + r1));
    let k = (r1 - r0) / theta_end;
    let mut o = String::new();
    header(&mut o, "spiral, 0.1 mm chords", "G64 P0.01");
    let at = |th: f64| ((r0 + k * th) * th.cos(), (r0 + k * th) * th.sin());
    let (x0, y0) = at(0.0);
    let _ = writeln!(o, "G0 X{x0:.4} Y{y0:.4} Z0");
    let _ = writeln!(o, "F{FEED_MM_MIN}");
    let mut th = 0.0f64;
    for _ in 0..n {
        // Constant chord length: step the angle by the chord over the local radius, then
        // correct once with the chord actually obtained.
        let (px, py) = at(th);
        let mut dth = step / (r0 + k * th);
        let (qx, qy) = at(th + dth);
        dth *= step / (qx - px).hypot(qy - py);
        th += dth;
        let (x, y) = at(th);
        let _ = writeln!(o, "G1 X{x:.4} Y{y:.4}");
    }
    footer(&mut o);
    o
}

/// `n` chords of `step` mm (arc length) along y = 5·sin(2πx/40) mm, 4 decimals, G64 P0.01.
pub fn sine(n: usize, step: f64) -> String {
    let f = |x: f64| 5.0 * (2.0 * std::f64::consts::PI * x / 40.0).sin();
    let mut o = String::new();
    header(&mut o, "sine, 0.1 mm chords", "G64 P0.01");
    let _ = writeln!(o, "G0 X0 Y0 Z0");
    let _ = writeln!(o, "F{FEED_MM_MIN}");
    let mut x = 0.0f64;
    for _ in 0..n {
        // Advance x so the chord is `step` long (Newton on the chord length, 3 rounds).
        let y = f(x);
        let mut dx = step;
        for _ in 0..3 {
            let len = dx.hypot(f(x + dx) - y);
            dx *= step / len;
        }
        x += dx;
        let _ = writeln!(o, "G1 X{x:.4} Y{:.4}", f(x));
    }
    footer(&mut o);
    o
}

/// A trochoidal slot around a 40 × 30 mm rectangle: the tool circles with radius 5 mm,
/// 40 chords per loop (0.79 mm), while the circle's centre advances 0.5 mm per loop along
/// the rectangle: 280 loops, 11,200 moves, about 8.8 m. Bare G64 (no tolerance), three
/// decimals, one `G1 X Y` per line, like gcmc's output.
pub fn trochoidal() -> String {
    const R: f64 = 5.0;
    const PER_LOOP: usize = 40;
    const ADVANCE: f64 = 0.5;
    let corners: [(f64, f64); 5] = [
        (0.0, 0.0),
        (40.0, 0.0),
        (40.0, 30.0),
        (0.0, 30.0),
        (0.0, 0.0),
    ];
    let perimeter: f64 = corners
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
        .sum();
    let loops = (perimeter / ADVANCE).round() as usize;
    // Centre of the circle after travelling `d` mm along the rectangle.
    let centre = |mut d: f64| {
        for w in corners.windows(2) {
            let len = (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1);
            if d <= len {
                let t = d / len;
                return (
                    w[0].0 + t * (w[1].0 - w[0].0),
                    w[0].1 + t * (w[1].1 - w[0].1),
                );
            }
            d -= len;
        }
        corners[corners.len() - 1]
    };
    let mut o = String::new();
    header(&mut o, "gcmc-style trochoidal slot", "G64");
    let _ = writeln!(o, "G0 X{:.3} Y0.000 Z1.000", R);
    let _ = writeln!(o, "G1 Z-1.000 F{FEED_MM_MIN}");
    let n = loops * PER_LOOP;
    for i in 1..=n {
        let u = i as f64 / PER_LOOP as f64; // loops done
        let (cx, cy) = centre(u * ADVANCE);
        let a = 2.0 * std::f64::consts::PI * u;
        let _ = writeln!(o, "G1 X{:.3} Y{:.3}", cx + R * a.cos(), cy + R * a.sin());
    }
    let _ = writeln!(o, "G0 Z1.000");
    footer(&mut o);
    o
}
