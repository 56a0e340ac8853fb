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
