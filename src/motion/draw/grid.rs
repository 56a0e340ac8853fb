//! Labelled millimetre grids: a 1-2-5 step giving about eight lines across, lines over the
//! plot area (orthographic views and charts) or on a plane of the machine projected
//! (isometric view), labels outside the plot area.

use super::doc::Doc;
use super::frame::Frame;
use super::view::Projector;

/// About this many grid lines across the larger extent.
const LINES: f64 = 8.0;

/// The 1-2-5 step with about [`LINES`] lines over `span`.
pub fn nice_step(span: f64) -> f64 {
    let raw = (span / LINES).max(1e-6);
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw * 0.999)
        .unwrap_or(10.0 * mag)
}

/// Label of grid value `x` at `step`: as many decimals as the step needs.
pub fn label(x: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10()).ceil() as usize
    };
    let s = format!("{:.*}", decimals, x);
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        "0".into()
    } else {
        s
    }
}

/// Multiples of `step` within [lo, hi].
fn ticks(lo: f64, hi: f64, step: f64) -> impl Iterator<Item = f64> {
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(move |k| k as f64 * step)
}

/// A grid over the whole plot area in data units, labelled below (u) and left (v) with the
/// axis names `u_name`, `v_name` and `unit`. Returns the step.
pub fn plane(doc: &mut Doc, f: &Frame, u_name: &str, v_name: &str, unit: &str) -> f64 {
    let d = f.data;
    let step = nice_step((d.u1 - d.u0).max(d.v1 - d.v0));
    lines(
        doc,
        f,
        (step, step),
        &format!("{u_name} ({unit})"),
        &format!("{v_name} ({unit})"),
    );
    step
}

/// A chart's grid: each direction with its own step, labelled `u_title` (below, right)
/// and `v_title` (above the left edge), e.g. "time (s)" and "feed (mm/s)".
pub fn chart(doc: &mut Doc, f: &Frame, u_title: &str, v_title: &str) {
    let d = f.data;
    let steps = (nice_step(d.u1 - d.u0), nice_step(d.v1 - d.v0));
    lines(doc, f, steps, u_title, v_title);
}

fn lines(doc: &mut Doc, f: &Frame, (su, sv): (f64, f64), u_title: &str, v_title: &str) {
    let d = f.data;
    let (ax, ay, aw, ah) = f.area;
    doc.open(r##"id="grid" stroke="#ddd" stroke-width="1""##);
    for u in ticks(d.u0, d.u1, su) {
        let (x, _) = f.px((u, d.v0));
        doc.line((x, ay), (x, ay + ah), "");
        doc.text(
            (x, ay + ah + 16.0),
            12.0,
            "middle",
            "grid-label",
            &label(u, su),
        );
    }
    for v in ticks(d.v0, d.v1, sv) {
        let (_, y) = f.px((d.u0, v));
        doc.line((ax, y), (ax + aw, y), "");
        doc.text(
            (ax - 6.0, y + 4.0),
            12.0,
            "end",
            "grid-label",
            &label(v, sv),
        );
    }
    doc.text((ax + aw, ay + ah + 32.0), 12.0, "end", "axis-name", u_title);
    doc.text((ax, ay - 8.0), 12.0, "middle", "axis-name", v_title);
    doc.close();
    doc.rect(
        ax,
        ay,
        aw,
        ah,
        r##"fill="none" stroke="#888" stroke-width="1""##,
    );
}

/// A grid on the machine's XY plane at height `z` over [x0, x1] × [y0, y1] mm, projected by
/// `p`, labelled along its front (X) and right (Y) edges. Returns the step.
#[allow(clippy::too_many_arguments)]
pub fn xy_plane(
    doc: &mut Doc,
    f: &Frame,
    p: &Projector,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
    z: f64,
) -> f64 {
    let step = nice_step((x1 - x0).max(y1 - y0));
    // The plane is the cuts' footprint (not widened to whole steps: it fits the view).
    let (gx0, gx1, gy0, gy1) = (x0, x1, y0, y1);
    let at = |x: f64, y: f64| f.px(p.uv([x, y, z]));
    doc.open(r##"id="grid" stroke="#ddd" stroke-width="1""##);
    for x in ticks(gx0, gx1, step) {
        doc.line(at(x, gy0), at(x, gy1), "");
        let (px, py) = at(x, gy0);
        doc.text(
            (px - 4.0, py + 16.0),
            12.0,
            "end",
            "grid-label",
            &label(x, step),
        );
    }
    for y in ticks(gy0, gy1, step) {
        doc.line(at(gx0, y), at(gx1, y), "");
        let (px, py) = at(gx1, y);
        doc.text(
            (px + 6.0, py + 14.0),
            12.0,
            "start",
            "grid-label",
            &label(y, step),
        );
    }
    let (px, py) = at(gx1, gy0);
    doc.text(
        (px, py + 34.0),
        12.0,
        "middle",
        "axis-name",
        &format!("X, Y (mm) at Z {}", label(z, 0.1)),
    );
    doc.close();
    step
}

/// The grid plane's corners (for fitting the isometric view around it).
pub fn xy_plane_corners(x: (f64, f64), y: (f64, f64), z: f64) -> [[f64; 3]; 4] {
    [[x.0, y.0, z], [x.1, y.0, z], [x.0, y.1, z], [x.1, y.1, z]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_are_1_2_5_with_about_eight_lines() {
        assert_eq!(nice_step(70.0), 10.0);
        assert_eq!(nice_step(40.0), 5.0);
        assert_eq!(nice_step(12.0), 2.0);
        assert_eq!(nice_step(0.8), 0.1);
        assert_eq!(label(-0.0, 0.5), "0");
        assert_eq!(label(2.5, 0.5), "2.5");
        assert_eq!(label(20.0, 10.0), "20");
    }
}
