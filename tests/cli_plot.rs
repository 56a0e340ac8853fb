//! `hytask plot` as a user runs it: plans from the machine's home position (or `--from`),
//! writes SVG or PNG by the output's extension, refuses a bad `--from` naming it; with
//! `--velocity` draws the trace's path speed.
#![allow(clippy::unwrap_used)]

#[path = "../benches/programs/gen.rs"]
mod gen;
mod support;

use support::{hytask, hytask_ok};

#[test]
fn plot_writes_png_from_the_home_position_and_svg_from_a_given_start() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("plate.png");
    let out = hytask_ok(&[
        "plot",
        "examples/jobs/demo-plate.ngc",
        "--view",
        "iso",
        "-o",
        png.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    // The built-in sim mill homes to X300 Y300 Z0: `hytask run` starts there.
    assert!(stdout.contains("from X300 Y300 Z0"), "{stdout}");
    let img = resvg::tiny_skia::Pixmap::decode_png(&std::fs::read(&png).unwrap()).unwrap();
    assert_eq!(img.width(), 1000);

    let svg = dir.path().join("plate.svg");
    hytask_ok(&[
        "plot",
        "examples/jobs/demo-plate.ngc",
        "--from",
        "-10,0,50",
        "--view",
        "front",
        "-o",
        svg.to_str().unwrap(),
    ]);
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("front view") && text.contains("start X-10.0 Y0.0 Z50.0"));

    let out = hytask(&[
        "plot",
        "examples/jobs/demo-plate.ngc",
        "--from",
        "1,2",
        "-o",
        "x.svg",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--from \"1,2\": give X,Y,Z"));
}

/// `--velocity`: the chart's speed curve, mapped back from pixels through the data box the
/// chart declares, lies on the path speed of `hytask plan --trace` for the same program,
/// reaches its peak, and the programmed feed and limit are marked; PNG works too.
#[test]
fn velocity_plot_curve_is_the_trace_speed() {
    let dir = tempfile::tempdir().unwrap();
    let program = dir.path().join("sine.ngc");
    std::fs::write(&program, gen::sine(600, 0.1)).unwrap();
    let csv = dir.path().join("sine.csv");
    hytask_ok(&[
        "plan",
        program.to_str().unwrap(),
        "--trace",
        csv.to_str().unwrap(),
    ]);
    let speed: Vec<f64> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let r: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            (r[2] * r[2] + r[6] * r[6] + r[10] * r[10]).sqrt()
        })
        .collect();

    let svg_path = dir.path().join("feed.svg");
    hytask_ok(&[
        "plot",
        program.to_str().unwrap(),
        "--velocity",
        "--from",
        "0,0,0",
        "-o",
        svg_path.to_str().unwrap(),
    ]);
    let svg = std::fs::read_to_string(&svg_path).unwrap();
    let attr = |tag_id: &str, name: &str| -> String {
        let at = svg.find(&format!(r#"id="{tag_id}""#)).unwrap();
        let tag = &svg[at..at + svg[at..].find('>').unwrap()];
        let key = format!(r#"{name}=""#);
        let from = tag.find(&key).unwrap() + key.len();
        tag[from..from + tag[from..].find('"').unwrap()].to_string()
    };
    let num = |tag_id: &str, name: &str| attr(tag_id, name).parse::<f64>().unwrap();
    let (t0, t1) = (num("feed-chart", "data-t0"), num("feed-chart", "data-t1"));
    let (v0, v1) = (num("feed-chart", "data-v0"), num("feed-chart", "data-v1"));
    let area: Vec<f64> = attr("feed-chart", "data-area")
        .split(',')
        .map(|x| x.parse().unwrap())
        .collect();
    let points: Vec<(f64, f64)> = attr("speed", "points")
        .split(' ')
        .map(|xy| {
            let (x, y) = xy.split_once(',').unwrap();
            let (x, y): (f64, f64) = (x.parse().unwrap(), y.parse().unwrap());
            (
                t0 + (x - area[0]) / area[2] * (t1 - t0),
                v0 + (area[1] + area[3] - y) / area[3] * (v1 - v0),
            )
        })
        .collect();
    assert!(points.len() > 500, "{}", points.len());
    let px_v = (v1 - v0) / area[3] * 0.01;
    for (t, v) in &points {
        let i = (t / 0.001).round() as usize;
        assert!(
            (v - speed[i]).abs() <= 2.0 * px_v + 1e-9,
            "t {t}: curve {v}, trace {}",
            speed[i]
        );
    }
    let peak = speed.iter().copied().fold(0.0, f64::max);
    let drawn = points.iter().map(|p| p.1).fold(0.0, f64::max);
    assert!((peak - drawn).abs() <= 2.0 * px_v, "{peak} vs {drawn}");
    assert!(peak <= 50.0 * 1.000_001 && peak > 40.0, "{peak}");
    assert!(svg.contains(r#"id="programmed""#) && svg.contains("axis velocity limit 50.0 mm/s"));

    let png = dir.path().join("feed.png");
    hytask_ok(&[
        "plot",
        program.to_str().unwrap(),
        "--velocity",
        "--width",
        "600",
        "-o",
        png.to_str().unwrap(),
    ]);
    let img = resvg::tiny_skia::Pixmap::decode_png(&std::fs::read(&png).unwrap()).unwrap();
    assert_eq!(img.width(), 600);
}
