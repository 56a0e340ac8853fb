//! Property tests: random polylines (random lengths, angles, feeds, tolerances, modes) never
//! exceed a limit on the interpolated trace, stay within tolerance and end exactly.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::gcode::canon::MotionControl;
use hytask::gcode::CanonCmd;
use hytask::motion::{plan, MotionConfig};
use motion_util::*;
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    #[test]
    fn random_polylines_respect_limits_and_tolerance(
        pts in prop::collection::vec((-40.0f64..40.0, -40.0f64..40.0, -5.0f64..5.0), 2..25),
        feed in 100.0f64..6000.0,
        tol in 0.001f64..0.5,
        exact in any::<bool>(),
        scale in prop::sample::select(vec![0.01, 0.1, 1.0]),
    ) {
        let cfg = MotionConfig::default();
        let mut g = Prog::new();
        g.feed(feed).g64(tol);
        if exact {
            g.cmd(CanonCmd::SetMotionControl(MotionControl::ExactPath));
        }
        let mut path = vec![pose(0.0, 0.0, 0.0)];
        for (x, y, z) in pts {
            let (x, y, z) = (x * scale, y * scale, z * scale);
            g.g1(x, y, z);
            path.push(pose(x, y, z));
        }
        let p = plan(&g.canon, &cfg).unwrap();
        let tr = run(&p, &cfg);
        assert_within_limits(&tr, &cfg);
        let allowed = if exact { cfg.exact_path_tolerance_mm } else { tol };
        let dev = max_deviation(&tr, &path);
        prop_assert!(dev <= allowed + 1e-9, "deviation {} > {}", dev, allowed);
        prop_assert_eq!(last(&tr), *path.last().unwrap());
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, .. ProptestConfig::default() })]

    /// Random override changes, holds, resumes and an optional abort at random periods
    /// never push an axis past a limit, never leave the path, and a job that is not aborted
    /// ends exactly at its end point.
    #[test]
    fn random_override_hold_abort_schedules_respect_limits(
        pts in prop::collection::vec((-30.0f64..30.0, -30.0f64..30.0), 2..12),
        feed in 300.0f64..3000.0,
        events in prop::collection::vec((0usize..6000, 0u8..5, 0.0f64..2.0), 0..8),
        abort_at in prop::option::of(0usize..4000),
    ) {
        let cfg = MotionConfig::default();
        let mut g = Prog::new();
        g.feed(feed).g64(0.05);
        let mut path = vec![pose(0.0, 0.0, 0.0)];
        for (x, y) in pts {
            g.g1(x, y, 0.0);
            path.push(pose(x, y, 0.0));
        }
        let p = plan(&g.canon, &cfg).unwrap();
        let tr = hytask::motion::trace::run(&p, &cfg, max_periods(&p, &cfg) + 20_000, |n, it| {
            for (at, what, val) in &events {
                if *at == n {
                    match what {
                        0 | 1 => it.set_feed_override(*val),
                        2 => it.hold(),
                        3 => it.resume(),
                        _ => it.set_rapid_override(*val),
                    }
                }
            }
            if n == 7000 {
                it.resume();
                it.set_feed_override(1.0);
            }
            if Some(n) == abort_at {
                it.abort();
            }
        });
        assert_within_limits(&tr, &cfg);
        let dev = max_deviation(&tr, &path);
        prop_assert!(dev <= 0.05 + 1e-9, "deviation {}", dev);
        if abort_at.is_none() {
            prop_assert_eq!(last(&tr), *path.last().unwrap());
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, .. ProptestConfig::default() })]

    /// Random chains of lines and arcs (any radius from 0.01 mm, both directions, full
    /// turns, helices) stay within limits and end exactly.
    #[test]
    fn random_arcs_and_lines_respect_limits(
        arcs in prop::collection::vec(
            (0.01f64..20.0, -3.2f64..3.2, -3.2f64..3.2, prop::sample::select(vec![-2, -1, 1, 2]), -2.0f64..2.0, 0.0f64..5.0),
            1..6),
        feed in 200.0f64..6000.0,
        tol in 0.001f64..0.2,
    ) {
        use hytask::gcode::canon::Plane;
        let cfg = MotionConfig::default();
        let mut g = Prog::new();
        g.feed(feed).g64(tol);
        let (mut x, mut y, mut z) = (0.0f64, 0.0f64, 0.0f64);
        for (r, a_center, a_end, rotation, dz, lead) in arcs {
            // A straight lead-in, then an arc around a centre at distance r.
            x += lead;
            g.g1(x, y, z);
            let (cx, cy) = (x - r * a_center.cos(), y - r * a_center.sin());
            let (ex, ey) = (cx + r * a_end.cos(), cy + r * a_end.sin());
            z += dz;
            g.cmd(CanonCmd::ArcFeed {
                first_end: ex,
                second_end: ey,
                first_center: cx,
                second_center: cy,
                rotation,
                axis_end: z,
                plane: Plane::Xy,
                end: pose(ex, ey, z),
            });
            x = ex;
            y = ey;
        }
        let p = plan(&g.canon, &cfg).unwrap();
        let tr = run(&p, &cfg);
        assert_within_limits(&tr, &cfg);
        prop_assert_eq!(last(&tr), pose(x, y, z));
    }
}
