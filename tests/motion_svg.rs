//! The toolpath pictures (`motion::draw`): every demo job in every view, checked by parsing
//! the SVG for what a machinist looks for: the cutting moves fill the plot area and stay
//! inside it, a labelled mm grid, start/end marks, drilled holes marked, the legend inside
//! the picture; the PNG decodes at the picture's size.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::{load_file, InterpOptions, NUM_AXES};
use hytask::motion::draw::{self, Options, View};
use hytask::motion::{plan, plan_from, svg, MotionConfig, Plan};
use motion_util::*;
use std::path::{Path, PathBuf};

const VIEWS: [View; 4] = [View::Top, View::Front, View::Side, View::Iso];

fn demo_jobs() -> Vec<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples/jobs");
    let mut jobs: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "ngc"))
        .collect();
    jobs.sort();
    assert!(jobs.len() >= 2, "{jobs:?}");
    jobs
}

/// Plans `job` from the built-in sim mill's home position (X300 Y300 Z0), as `hytask run`.
fn plan_job(job: &Path, start: [f64; 3]) -> Plan {
    let canon = load_file(job, &InterpOptions::default()).unwrap().canon;
    let mut pose = [0.0; NUM_AXES];
    pose[..3].copy_from_slice(&start);
    plan_from(&canon, &MotionConfig::default(), pose).unwrap()
}

/// What the tests read from a picture.
struct Picture {
    size: (f64, f64),
    /// Plot area (clip rectangle): x, y, w, h.
    area: (f64, f64, f64, f64),
    /// Every point of the cutting moves, px.
    cuts: Vec<(f64, f64)>,
    grid_labels: Vec<String>,
    marks: Vec<String>,
    /// Legend box and every legend text position.
    legend_box: (f64, f64, f64, f64),
    legend_texts: Vec<(f64, f64, String)>,
}

fn num(n: roxmltree::Node, a: &str) -> f64 {
    n.attribute(a).unwrap().parse().unwrap()
}

fn parse(svg: &str) -> Picture {
    let doc = roxmltree::Document::parse(svg).unwrap();
    let root = doc.root_element();
    let vb: Vec<f64> = root
        .attribute("viewBox")
        .unwrap()
        .split(' ')
        .map(|v| v.parse().unwrap())
        .collect();
    let by_id = |id: &str| doc.descendants().find(|n| n.attribute("id") == Some(id));
    let clip = by_id("plot-area")
        .unwrap()
        .children()
        .find(|n| n.has_tag_name("rect"))
        .unwrap();
    let cuts = by_id("cuts")
        .unwrap()
        .children()
        .filter(|n| n.has_tag_name("polyline"))
        .flat_map(|n| {
            n.attribute("points")
                .unwrap()
                .split(' ')
                .map(|p| {
                    let (x, y) = p.split_once(',').unwrap();
                    (x.parse().unwrap(), y.parse().unwrap())
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let class_texts = |class: &str| -> Vec<String> {
        doc.descendants()
            .filter(|n| n.has_tag_name("text") && n.attribute("class") == Some(class))
            .map(|n| n.text().unwrap_or("").to_string())
            .collect()
    };
    let marks = by_id("marks")
        .unwrap()
        .descendants()
        .filter_map(|n| n.attribute("class"))
        .filter(|c| c.starts_with("mark "))
        .map(str::to_string)
        .collect();
    let legend = by_id("legend").unwrap();
    let lb = legend
        .children()
        .find(|n| n.attribute("class") == Some("legend-box"))
        .unwrap();
    Picture {
        size: (vb[2], vb[3]),
        area: (
            num(clip, "x"),
            num(clip, "y"),
            num(clip, "width"),
            num(clip, "height"),
        ),
        cuts,
        grid_labels: class_texts("grid-label"),
        marks,
        legend_box: (
            num(lb, "x"),
            num(lb, "y"),
            num(lb, "width"),
            num(lb, "height"),
        ),
        legend_texts: legend
            .descendants()
            .filter(|n| n.has_tag_name("text"))
            .map(|n| (num(n, "x"), num(n, "y"), n.text().unwrap_or("").to_string()))
            .collect(),
    }
}

fn render(plan: &Plan, view: View) -> String {
    draw::render(
        plan,
        &Options {
            title: "job".into(),
            view,
            width_px: 1000.0,
        },
    )
}

#[test]
fn every_demo_job_in_every_view_fits_its_cuts_with_grid_marks_and_legend_inside() {
    for job in demo_jobs() {
        let plan = plan_job(&job, [300.0, 300.0, 0.0]);
        for view in VIEWS {
            let what = format!("{} {view:?}", job.display());
            let p = parse(&render(&plan, view));
            let (ax, ay, aw, ah) = p.area;
            assert!(!p.cuts.is_empty(), "{what}: no cutting moves drawn");
            // Inside the plot area, which is inside the picture.
            assert!(ax >= 0.0 && ay >= 0.0 && ax + aw <= p.size.0 && ay + ah <= p.size.1);
            let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
            for &(x, y) in &p.cuts {
                assert!(
                    x >= ax - 0.01 && x <= ax + aw + 0.01 && y >= ay - 0.01 && y <= ay + ah + 0.01,
                    "{what}: cut point {x},{y} outside the plot area {:?}",
                    p.area
                );
                (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
            }
            // Fitted to the cuts (not to the rapid from home): they fill the area one way.
            let fill = ((x1 - x0) / aw).max((y1 - y0) / ah);
            assert!(
                fill > 0.8,
                "{what}: cuts fill only {fill:.2} of the plot area"
            );
            // A labelled grid: numbers, several of them.
            assert!(p.grid_labels.len() >= 6, "{what}: {:?}", p.grid_labels);
            for l in &p.grid_labels {
                l.parse::<f64>()
                    .unwrap_or_else(|_| panic!("{what}: grid label {l:?}"));
            }
            assert!(p.marks.iter().any(|m| m == "mark start"), "{what}");
            assert!(p.marks.iter().any(|m| m == "mark end"), "{what}");
            // The legend, every word of it, inside the picture.
            let (lx, ly, lw, lh) = p.legend_box;
            assert!(lx >= 0.0 && ly >= ay + ah && lx + lw <= p.size.0 && ly + lh <= p.size.1);
            assert!(p.legend_texts.len() >= 7, "{what}");
            for (x, y, t) in &p.legend_texts {
                // ~7 px per character at 12 px: the text ends inside the picture.
                let end = x + 7.0 * t.chars().count() as f64;
                assert!(
                    *x >= 0.0 && end <= p.size.0 && *y > ly && *y < ly + lh,
                    "{what}: legend text {t:?} at {x},{y} leaves the picture {:?}",
                    p.size
                );
            }
        }
    }
}

#[test]
fn demo_plate_marks_its_four_drilled_holes_and_its_plunges_in_every_view() {
    let job = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples/jobs/demo-plate.ngc");
    let plan = plan_job(&job, [300.0, 300.0, 0.0]);
    for view in VIEWS {
        let p = parse(&render(&plan, view));
        let drills = p.marks.iter().filter(|m| *m == "mark drill").count();
        let plunges = p.marks.iter().filter(|m| *m == "mark plunge").count();
        // G81 at four points; the facing pass and the two pocket passes plunge.
        assert_eq!(drills, 4, "{view:?}: {:?}", p.marks);
        assert_eq!(plunges, 3, "{view:?}: {:?}", p.marks);
    }
}

#[test]
fn rapids_never_set_the_scale() {
    let job = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples/jobs/demo-plate.ngc");
    let near = parse(&render(&plan_job(&job, [100.0, 100.0, 0.0]), View::Top));
    let far = parse(&render(&plan_job(&job, [300.0, 300.0, 0.0]), View::Top));
    assert_eq!(near.cuts, far.cuts);
    assert_eq!(near.grid_labels, far.grid_labels);
}

#[test]
fn png_decodes_at_the_picture_size_with_the_toolpath_drawn() {
    let job = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples/jobs/demo-plate.ngc");
    let plan = plan_job(&job, [300.0, 300.0, 0.0]);
    for view in [View::Top, View::Iso] {
        let svg = render(&plan, view);
        let size = parse(&svg).size;
        let png = draw::png::render(&svg).unwrap();
        let img = resvg::tiny_skia::Pixmap::decode_png(&png).unwrap();
        assert_eq!((img.width() as f64, img.height() as f64), size, "{view:?}");
        // The fast feeds are red: many strongly red pixels.
        let red = img
            .pixels()
            .iter()
            .filter(|p| p.red() > 180 && p.green() < 80 && p.blue() < 80)
            .count();
        assert!(red > 500, "{view:?}: {red} red pixels");
    }
}

#[test]
fn the_compatibility_render_is_the_top_view_with_feeds_by_speed_and_rapids_dashed() {
    let cfg = MotionConfig::default();
    let mut g = Prog::new();
    g.g0(10.0, 10.0, 0.0)
        .feed(3000.0)
        .g1(60.0, 10.0, 0.0)
        .g1(60.0, 40.0, 0.0)
        .feed(300.0)
        .g1(10.0, 40.0, 0.0);
    let p = plan(&g.canon, &cfg).unwrap();
    let s = svg::render(&p, "demo <1>");
    assert!(s.starts_with("<svg ") && s.trim_end().ends_with("</svg>"));
    assert!(s.contains("demo &lt;1&gt;"));
    assert!(s.contains("stroke-dasharray"), "rapid not dashed");
    // Fast (red, hue 0) and slow (blue-ish) feeds both present.
    assert!(s.contains(r#"stroke="hsl(0,90%,45%)""#));
    assert!(
        s.contains(r#"stroke="hsl(213,90%,45%)""#)
            || s.contains(r#"stroke="hsl(240,90%,45%)""#)
            || s.contains(r#"stroke="hsl(187,90%,45%)""#)
    );
    assert!(s.contains("feed 0 … 50.0 mm/s"));
    assert!(parse(&s).grid_labels.contains(&"40".to_string()));
}
