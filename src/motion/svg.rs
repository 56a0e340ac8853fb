//! Hand-written SVG of a plan: the XY projection of the planned toolpath, feeds coloured by
//! planned speed (blue slow → red fast), rapids dashed grey, with a legend. Consecutive
//! pieces of one colour are joined into one polyline so dense CAM files stay small.

use super::segment::{norm, Item, SegmentKind};
use super::Plan;
use std::fmt::Write;

/// Number of colour steps of the speed scale.
const BUCKETS: usize = 10;

fn colour(bucket: usize) -> String {
    // Hue 240 (blue, slow) to 0 (red, fast).
    let h = 240.0 * (1.0 - bucket as f64 / (BUCKETS - 1) as f64);
    format!("hsl({h:.0},90%,45%)")
}

/// Renders `plan` as an SVG document.
pub fn render(plan: &Plan, title: &str) -> String {
    // Sample every motion segment: (x, y, speed mm/s, rapid).
    let mut pts: Vec<(f64, f64, f64, bool)> = Vec::new();
    let mut vmax = 0.0f64;
    for it in &plan.items {
        let Item::Segment(s) = it else { continue };
        if s.kind == SegmentKind::Dwell {
            continue;
        }
        let n = ((s.length_mm / 0.5).ceil() as usize).clamp(1, 16);
        let sh = s.shape();
        for i in 0..n {
            let t = s.duration_s * (i as f64 + 0.5) / n as f64;
            let (f, _) = sh.eval(t);
            let mut v = [0.0; crate::gcode::NUM_AXES];
            for (a, v) in v.iter_mut().enumerate() {
                *v = s.v0_mm_s[a] + (s.v1_mm_s[a] - s.v0_mm_s[a]) * f;
            }
            let speed = norm(&[v[0], v[1], v[2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
            let p = s.pose_at(s.duration_s * i as f64 / n as f64);
            pts.push((p[0], p[1], speed, s.kind == SegmentKind::Rapid));
            if s.kind != SegmentKind::Rapid {
                vmax = vmax.max(speed);
            }
        }
        pts.push((
            s.end_mm[0],
            s.end_mm[1],
            f64::NAN,
            s.kind == SegmentKind::Rapid,
        ));
    }
    let (mut x0, mut y0, mut x1, mut y1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y, _, _) in &pts {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    if !x0.is_finite() {
        (x0, y0, x1, y1) = (0.0, 0.0, 1.0, 1.0);
    }
    let span = (x1 - x0).max(y1 - y0).max(1e-3);
    let margin = 0.05 * span;
    let (w, h) = (x1 - x0 + 2.0 * margin, y1 - y0 + 2.0 * margin);
    let stroke = span / 400.0;
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="{:.4} {:.4} {:.4} {:.4}" width="1000" height="{:.0}">"#,
        x0 - margin,
        -(y1 + margin),
        w,
        h + 0.12 * span,
        1000.0 * (h + 0.12 * span) / w
    );
    let _ = writeln!(svg, "<title>{}</title>", escape(title));
    let _ = writeln!(
        svg,
        r#"<rect x="{:.4}" y="{:.4}" width="{w:.4}" height="{:.4}" fill="white"/>"#,
        x0 - margin,
        -(y1 + margin),
        h + 0.12 * span
    );
    // Polylines by colour bucket (y flipped: SVG y grows downwards).
    let bucket_of = |speed: f64, rapid: bool| -> Option<usize> {
        if rapid {
            None
        } else if vmax > 0.0 {
            Some(
                ((speed / vmax) * (BUCKETS as f64 - 1.0))
                    .round()
                    .clamp(0.0, BUCKETS as f64 - 1.0) as usize,
            )
        } else {
            Some(0)
        }
    };
    let mut cur: Option<(Option<usize>, String)> = None;
    let flush = |svg: &mut String, cur: &mut Option<(Option<usize>, String)>| {
        if let Some((b, points)) = cur.take() {
            let style = match b {
                None => format!(r##"stroke="#999" stroke-dasharray="{:.4}""##, 4.0 * stroke),
                Some(b) => format!(r#"stroke="{}""#, colour(b)),
            };
            let _ = writeln!(
                svg,
                r#"<polyline fill="none" stroke-width="{stroke:.4}" {style} points="{points}"/>"#
            );
        }
    };
    for w2 in pts.windows(2) {
        let (a, b) = (w2[0], w2[1]);
        if a.2.is_nan() {
            continue; // segment end marker: the next piece starts from it
        }
        let bk = bucket_of(a.2, a.3);
        let same = matches!(&cur, Some((cb, _)) if *cb == bk);
        if !same {
            flush(&mut svg, &mut cur);
            cur = Some((bk, format!("{:.4},{:.4}", a.0, -a.1)));
        }
        if let Some((_, s)) = &mut cur {
            let _ = write!(s, " {:.4},{:.4}", b.0, -b.1);
        }
    }
    flush(&mut svg, &mut cur);
    // Legend.
    let ly = -(y0 - margin) + 0.04 * span;
    let lw = span / 25.0;
    for b in 0..BUCKETS {
        let _ = writeln!(
            svg,
            r#"<rect x="{:.4}" y="{ly:.4}" width="{lw:.4}" height="{:.4}" fill="{}"/>"#,
            x0 + b as f64 * lw,
            0.03 * span,
            colour(b)
        );
    }
    let fs = 0.03 * span;
    let _ = writeln!(
        svg,
        r#"<text x="{:.4}" y="{:.4}" font-size="{fs:.4}" font-family="sans-serif">0 … {:.1} mm/s planned feed; dashed: rapid; {:.2} s, {:.1} mm</text>"#,
        x0 + (BUCKETS as f64 + 0.5) * lw,
        ly + 0.025 * span,
        vmax,
        plan.duration_s,
        plan.distance_mm
    );
    svg.push_str("</svg>\n");
    svg
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
