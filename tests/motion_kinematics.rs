//! Kinematics: identity and SCARA, forward/inverse round trips, reach limits, singularity,
//! joint limits, and the planner refusing what the arm cannot reach.
#![allow(clippy::unwrap_used)]

mod motion_util;

use hytask::motion::kinematics::{Identity, Kinematics, Scara};
use hytask::motion::{KinematicsConfig, KinematicsError, MotionConfig, PlanError, ScaraConfig};
use motion_util::*;

fn scara_cfg(l1: f64, l2: f64) -> ScaraConfig {
    let mut lo = [-1e9; 9];
    let mut hi = [1e9; 9];
    lo[0] = -180.0;
    hi[0] = 180.0;
    lo[1] = -170.0;
    hi[1] = 170.0;
    ScaraConfig {
        link1_mm: l1,
        link2_mm: l2,
        elbow_positive: true,
        joint_min: lo,
        joint_max: hi,
        joint_max_vel: [360.0, 360.0, 100.0, 1e9, 1e9, 1e9, 1e9, 1e9, 1e9],
    }
}

#[test]
fn identity_round_trip_and_rejects_nan() {
    let k = Identity;
    let p = [1.0, -2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
    assert_eq!(k.forward(&k.inverse(&p).unwrap()).unwrap(), p);
    let mut bad = p;
    bad[4] = f64::NAN;
    assert_eq!(k.inverse(&bad), Err(KinematicsError::NotFinite));
}

#[test]
fn scara_round_trip_over_the_workspace() {
    for elbow in [true, false] {
        let k = Scara::new(ScaraConfig {
            elbow_positive: elbow,
            ..scara_cfg(200.0, 150.0)
        });
        for i in 0..40 {
            for j in 1..20 {
                let ang = i as f64 * 9.0_f64.to_radians();
                let r = 50.0 + j as f64 * 15.0; // 65..335 inside [50, 350]
                let p = pose(r * ang.cos(), r * ang.sin(), -3.0);
                let q = k.inverse(&p).unwrap();
                let back = k.forward(&q).unwrap();
                for a in 0..3 {
                    assert!((back[a] - p[a]).abs() < 1e-9, "{p:?} -> {q:?} -> {back:?}");
                }
                assert_eq!(q[2], -3.0);
                assert_eq!(q[1] > 0.0, elbow);
            }
        }
    }
}

#[test]
fn scara_reach_limits_and_singularity_are_named_never_nan() {
    let k = Scara::new(scara_cfg(200.0, 150.0));
    // Full extension: unique, finite.
    let q = k.inverse(&pose(350.0, 0.0, 0.0)).unwrap();
    assert!(q.iter().all(|v| v.is_finite()));
    assert!(q[1].abs() < 1e-6);
    assert!(matches!(
        k.inverse(&pose(350.1, 0.0, 0.0)),
        Err(KinematicsError::OutOfReach { .. })
    ));
    assert!(matches!(
        k.inverse(&pose(10.0, 0.0, 0.0)),
        Err(KinematicsError::OutOfReach { .. })
    ));
    // Equal links: the centre is reachable but the shoulder angle is undefined.
    let eq = Scara::new(scara_cfg(150.0, 150.0));
    assert!(matches!(
        eq.inverse(&pose(0.0, 0.0, 0.0)),
        Err(KinematicsError::Singular { .. })
    ));
    // Elbow beyond its joint limit.
    assert!(matches!(
        eq.inverse(&pose(1.0, 0.0, 0.0)),
        Err(KinematicsError::JointLimit { joint: 1, .. })
    ));
}

#[test]
fn planner_refuses_unreachable_scara_moves_with_line() {
    let cfg = MotionConfig {
        kinematics: KinematicsConfig::Scara(scara_cfg(200.0, 150.0)),
        ..Default::default()
    };
    let mut g = Prog::new();
    g.g0(300.0, 0.0, 0.0)
        .feed(3000.0)
        .g1(300.0, 100.0, 0.0)
        .g1(400.0, 100.0, 0.0);
    let err = plan_from_start(&g, &cfg).unwrap_err();
    assert!(
        matches!(err, PlanError::Kinematics { line: 4, .. }),
        "{err}"
    );
}

#[test]
fn scara_job_runs_and_reports_joints() {
    let cfg = MotionConfig {
        kinematics: KinematicsConfig::Scara(scara_cfg(200.0, 150.0)),
        ..Default::default()
    };
    let mut g = Prog::new();
    g.feed(3000.0).g1(250.0, 50.0, 0.0).g1(200.0, 150.0, -5.0);
    let p = plan_from_start(&g, &cfg).unwrap();
    let mut it = hytask::motion::Interpolator::new(&cfg, p.start_mm);
    let mut src = hytask::motion::SliceSource::new(&p.items);
    let k = Scara::new(scara_cfg(200.0, 150.0));
    for _ in 0..100_000 {
        let out = *it.step(&mut src);
        assert!(out.fault.is_none());
        let back = k.forward(&out.joints).unwrap();
        assert!((back[0] - out.pose_mm[0]).abs() < 1e-9 && (back[1] - out.pose_mm[1]).abs() < 1e-9);
        if out.state == hytask::motion::InterpState::Done {
            assert_eq!(out.pose_mm, pose(200.0, 150.0, -5.0));
            return;
        }
    }
    panic!("job did not finish");
}

fn plan_from_start(g: &Prog, cfg: &MotionConfig) -> Result<hytask::motion::Plan, PlanError> {
    // A SCARA cannot start at machine zero (inside its dead zone): start at (300, 0).
    hytask::motion::plan_from(&g.canon, cfg, pose(300.0, 0.0, 0.0))
}

#[test]
fn planner_refuses_joint_speeds_near_full_extension() {
    let mut sc = scara_cfg(200.0, 150.0);
    sc.joint_max_vel[0] = 30.0;
    sc.joint_max_vel[1] = 30.0;
    let cfg = MotionConfig {
        kinematics: KinematicsConfig::Scara(sc),
        ..Default::default()
    };
    // Radially outward to almost full extension at 50 mm/s: the elbow must unfold fast.
    let mut g = Prog::new();
    g.feed(3000.0).g1(349.9, 0.0, 0.0);
    let err = plan_from_start(&g, &cfg).unwrap_err();
    assert!(
        matches!(
            err,
            PlanError::Kinematics {
                line: 2,
                source: KinematicsError::JointVelocity { joint: 1, .. }
            }
        ),
        "{err}"
    );
    // Slowly, it is fine.
    let mut g = Prog::new();
    g.feed(60.0).g1(320.0, 0.0, 0.0);
    assert!(plan_from_start(&g, &cfg).is_ok());
}
