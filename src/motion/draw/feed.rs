//! The feed chart of `hytask plot --velocity`: the XYZ path speed of the servo-period trace
//! against time, with the programmed feed of every move (rapids have none) and the axis
//! velocity limit marked, on a labelled grid. Machinists read a program's quality off this
//! picture: where the feed drops below the programmed one, and how far.
//!
//! The curve keeps, per pixel column, the samples with the lowest and the highest speed
//! (in time order), so no dip or peak is lost however long the job. The plot area's data
//! box is written on the chart group (`data-t0 data-t1 data-v0 data-v1`, `data-area`), so
//! a reader can map the curve's pixels back to seconds and mm/s.

use super::doc::Doc;
use super::frame::{Bounds, Frame};
use super::grid;
use super::Options;
use crate::motion::trace::Trace;

/// Colour of the speed curve.
const SPEED: &str = "#1f5fbf";
/// Style of the programmed feed.
const PROGRAMMED: &str = r##"stroke="#2a9d3a" stroke-width="1.4" stroke-dasharray="7 4""##;
/// Style of the velocity limit.
const LIMIT: &str = r##"stroke="#d62728" stroke-width="1.2" stroke-dasharray="3 3""##;

/// What the chart shows besides the trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Marks<'a> {
    /// Programmed feed of every period of the trace, mm/s (infinite for rapids, none drawn).
    pub programmed_mm_s: &'a [f64],
    /// The axis velocity limit (the smallest of X Y Z), mm/s.
    pub limit_mm_s: f64,
}

/// Renders the chart of `tr` as an SVG document.
pub fn render(tr: &Trace, marks: Marks<'_>, o: &Options) -> String {
    let n = tr.poses_mm.len();
    let speed: Vec<f64> = (0..n).map(|i| tr.speed_mm_s(i)).collect();
    let t = |i: usize| i as f64 * tr.dt_s;
    let finite_feed = marks
        .programmed_mm_s
        .iter()
        .copied()
        .filter(|f| f.is_finite())
        .fold(0.0, f64::max);
    let top = speed
        .iter()
        .copied()
        .fold(marks.limit_mm_s.max(finite_feed), f64::max);
    let fit = Bounds {
        u0: 0.0,
        u1: t(n.saturating_sub(1)).max(tr.dt_s),
        v0: 0.0,
        v1: top.max(1e-3),
    };
    let f = Frame::new(fit, o.width_px, false, 0.45);
    let mut doc = f.titled_doc(&o.title, &format!("{} — feed along the path", o.title));
    grid::chart(&mut doc, &f, "time (s)", "path speed (mm/s)");
    doc.raw(&format!("<defs>{}</defs>", f.clip_path("chart-area")));
    let d = f.data;
    let (ax, ay, aw, ah) = f.area;
    doc.open(&format!(
        r#"id="feed-chart" clip-path="url(#chart-area)" data-t0="{}" data-t1="{}" data-v0="{}" data-v1="{}" data-area="{ax},{ay},{aw},{ah}""#,
        d.u0, d.u1, d.v0, d.v1
    ));
    let (l0, l1) = (
        f.px((d.u0, marks.limit_mm_s)),
        f.px((d.u1, marks.limit_mm_s)),
    );
    doc.line(l0, l1, &format!(r#"id="limit" {LIMIT}"#));
    doc.open(&format!(r#"id="programmed" {PROGRAMMED}"#));
    for (i0, i1, feed) in runs(marks.programmed_mm_s) {
        doc.polyline(&[f.px((t(i0), feed)), f.px((t(i1), feed))], "");
    }
    doc.close();
    let pts: Vec<(f64, f64)> = column_extremes(&speed, aw.max(1.0) as usize)
        .into_iter()
        .map(|i| f.px((t(i), speed[i])))
        .collect();
    doc.polyline(
        &pts,
        &format!(r#"id="speed" stroke="{SPEED}" stroke-width="1.3""#),
    );
    doc.close();
    let peak = speed.iter().copied().fold(0.0, f64::max);
    legend(
        &mut doc,
        &f,
        marks.limit_mm_s,
        &format!(
            "trace {:.3} s at the {:.3} ms servo period, peak path speed {peak:.2} mm/s",
            t(n.saturating_sub(1)),
            tr.dt_s * 1e3
        ),
    );
    doc.finish()
}

/// Runs of equal finite programmed feed: (first period, last period, feed).
fn runs(feed: &[f64]) -> Vec<(usize, usize, f64)> {
    let mut out: Vec<(usize, usize, f64)> = Vec::new();
    for (i, &v) in feed.iter().enumerate() {
        match out.last_mut() {
            Some(r) if r.2 == v && r.1 + 1 == i => r.1 = i,
            _ if v.is_finite() => out.push((i, i, v)),
            _ => {}
        }
    }
    out
}

/// Indices of the samples to draw: all of them when there are few, else per column of
/// `columns` the lowest and the highest (in time order), with the first and the last.
fn column_extremes(v: &[f64], columns: usize) -> Vec<usize> {
    let n = v.len();
    if n <= 4 * columns {
        return (0..n).collect();
    }
    let mut out = Vec::with_capacity(2 * columns + 2);
    out.push(0);
    for c in 0..columns {
        let (a, b) = (
            c * n / columns,
            ((c + 1) * n / columns).max(c * n / columns + 1),
        );
        let (mut lo, mut hi) = (a, a);
        for i in a..b.min(n) {
            if v[i] < v[lo] {
                lo = i;
            }
            if v[i] > v[hi] {
                hi = i;
            }
        }
        out.push(lo.min(hi));
        out.push(lo.max(hi));
    }
    out.push(n - 1);
    out.dedup();
    out
}

/// The key: curve, programmed feed, limit, then `summary`.
fn legend(doc: &mut Doc, f: &Frame, limit: f64, summary: &str) {
    let y = super::legend::open_box(doc, f);
    let items = [
        (
            format!(r#"stroke="{SPEED}" stroke-width="1.6""#),
            "path speed (trace)".to_string(),
        ),
        (PROGRAMMED.to_string(), "programmed feed".to_string()),
        (
            LIMIT.to_string(),
            format!("axis velocity limit {limit:.1} mm/s"),
        ),
    ];
    let mut x = 16.0;
    for (style, name) in items {
        doc.line((x, y - 4.0), (x + 30.0, y - 4.0), &style);
        doc.text((x + 36.0, y), 12.0, "start", "legend-text", &name);
        x += 60.0 + 7.0 * name.len() as f64;
    }
    doc.text((16.0, y + 22.0), 12.0, "start", "legend-text", summary);
    doc.close();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_keep_every_dip_and_peak() {
        let v: Vec<f64> = (0..10_000)
            .map(|i| if i == 5_123 { -1.0 } else { (i % 7) as f64 })
            .collect();
        let keep = column_extremes(&v, 100);
        assert!(keep.len() <= 202);
        assert!(keep.contains(&5_123));
        assert!(keep.windows(2).all(|w| w[0] < w[1]));
        assert_eq!((keep[0], *keep.last().unwrap()), (0, 9_999));
    }

    #[test]
    fn programmed_feed_runs_skip_rapids() {
        let f = [f64::INFINITY, 10.0, 10.0, 20.0, f64::INFINITY, 20.0];
        assert_eq!(runs(&f), vec![(1, 2, 10.0), (3, 3, 20.0), (5, 5, 20.0)]);
    }
}
