//! The SVG picture of a plan: feeds coloured by speed, rapids dashed, legend, sane viewBox.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::motion::{plan, svg, MotionConfig};
use motion_util::*;

#[test]
fn plot_has_feeds_by_speed_rapids_dashed_and_a_legend() {
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
    assert!(s.contains("hsl(0,90%,45%)\" points"));
    assert!(s.matches("<polyline").count() >= 4);
    // Legend: ten colour boxes and the speed scale.
    assert_eq!(s.matches("<rect").count(), 11);
    assert!(s.contains("50.0 mm/s planned feed"));
    // Y is flipped: the path's y = 40 appears as -40.
    assert!(s.contains(",-40.0000"));
}
