//! The toolpath picture: fitted to the cutting moves (rapids are drawn, clipped to the plot
//! area, but never set the scale, so a long rapid from the home position does not shrink
//! the part into a corner), grid, path, marks, legend.

use super::doc::Doc;
use super::frame::{Bounds, Frame};
use super::legend::{self, colour, marks, RAPID_STYLE};
use super::path::{self, RunKind, Toolpath};
use super::view::{Projector, View};
use super::{grid, Options};
use crate::motion::Plan;

/// Renders `plan` as an SVG document.
pub fn render(plan: &Plan, o: &Options) -> String {
    let tp = path::toolpath(plan);
    let p = Projector::new(o.view);
    let (fit, grid_plane) = fit(&tp, &p, o.view);
    let f = Frame::new(fit, o.width_px, true, 0.0);
    let mut doc = f.titled_doc(&o.title, &format!("{} — {} view", o.title, o.view.name()));
    match o.view.plane_axes() {
        Some((a, b)) => {
            let names = ["X", "Y", "Z"];
            grid::plane(&mut doc, &f, names[a], names[b], "mm");
        }
        None => {
            let (x, y, z) = grid_plane;
            grid::xy_plane(&mut doc, &f, &p, x, y, z);
        }
    }
    doc.raw(&format!("<defs>{}</defs>", f.clip_path("plot-area")));
    doc.open(r#"id="toolpath" clip-path="url(#plot-area)""#);
    let px = |q: &[f64; 3]| f.px(p.uv(*q));
    doc.open(&format!(r#"id="rapids" {RAPID_STYLE}"#));
    for r in tp.runs.iter().filter(|r| r.kind == RunKind::Rapid) {
        let pts: Vec<_> = r.points.iter().map(px).collect();
        doc.polyline(&pts, "");
    }
    doc.close();
    doc.open(r#"id="cuts" stroke-width="1.6" stroke-linejoin="round""#);
    for r in &tp.runs {
        if let RunKind::Feed(b) = r.kind {
            let pts: Vec<_> = r.points.iter().map(px).collect();
            doc.polyline(&pts, &format!(r#"class="feed" stroke="{}""#, colour(b)));
        }
    }
    doc.close();
    doc.close();
    draw_marks(&mut doc, &f, &tp, &px);
    let (drills, plunges) =
        tp.plunges.iter().fold(
            (0, 0),
            |(d, pl), m| {
                if m.drill {
                    (d + 1, pl)
                } else {
                    (d, pl + 1)
                }
            },
        );
    let summary = format!(
        "planned {:.1} s, {:.1} mm; start X{:.1} Y{:.1} Z{:.1}; {drills} drilled, {plunges} plunges",
        plan.duration_s, plan.distance_mm, tp.start[0], tp.start[1], tp.start[2]
    );
    legend::toolpath(&mut doc, &f, tp.vmax, &summary);
    doc.finish()
}

/// The data box to fit: the cutting moves' projection (all moves when there is no cut);
/// in the isometric view also the grid plane under the cuts, returned as X and Y ranges
/// and its Z.
#[allow(clippy::type_complexity)]
fn fit(tp: &Toolpath, p: &Projector, view: View) -> (Bounds, ((f64, f64), (f64, f64), f64)) {
    let cuts = || {
        tp.runs
            .iter()
            .filter(|r| matches!(r.kind, RunKind::Feed(_)))
            .flat_map(|r| r.points.iter())
    };
    let all = || tp.runs.iter().flat_map(|r| r.points.iter());
    let pts: Vec<[f64; 3]> = if cuts().next().is_some() {
        cuts().copied().collect()
    } else if all().next().is_some() {
        all().copied().collect()
    } else {
        vec![tp.start]
    };
    let mut b = Bounds::empty();
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for q in &pts {
        b.add(p.uv(*q));
        for a in 0..3 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    let plane = ((lo[0], hi[0]), (lo[1], hi[1]), lo[2]);
    if view == View::Iso {
        for c in grid::xy_plane_corners(plane.0, plane.1, plane.2) {
            b.add(p.uv(c));
        }
    }
    (b, plane)
}

/// Start and end (kept inside the plot area, labelled "off view" when outside it), plunges
/// and drilled holes.
fn draw_marks(doc: &mut Doc, f: &Frame, tp: &Toolpath, px: &dyn Fn(&[f64; 3]) -> (f64, f64)) {
    doc.open(r#"id="marks""#);
    for m in &tp.plunges {
        if m.drill {
            marks::drill(doc, px(&m.at));
        } else {
            marks::plunge(doc, px(&m.at));
        }
    }
    for (q, name, mark) in [
        (&tp.start, "start", marks::start as legend::Mark),
        (&tp.end, "end", marks::end),
    ] {
        let at = px(q);
        let shown = f.clamp_px(at);
        mark(doc, shown);
        let label = if shown == at {
            name.to_string()
        } else {
            format!("{name} (off view)")
        };
        let right = shown.0 < f.area.0 + f.area.2 - 100.0;
        doc.text(
            (shown.0 + if right { 9.0 } else { -9.0 }, shown.1 - 8.0),
            12.0,
            if right { "start" } else { "end" },
            "mark-label",
            &label,
        );
    }
    doc.close();
}
