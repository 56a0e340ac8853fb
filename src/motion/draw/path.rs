//! The toolpath of a plan as drawable runs: consecutive pieces of one kind and speed colour
//! joined into one polyline (dense CAM files stay small), and the points worth marking:
//! where the machine starts and ends, and where the tool goes straight down into the work
//! (a plunge, or a drill cycle's hole when the tool comes straight back up).

use crate::motion::segment::{Item, SegmentKind};
use crate::motion::Plan;

/// Number of colour steps of the speed scale.
pub const BUCKETS: usize = 10;

/// What a run is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunKind {
    /// A rapid (G0).
    Rapid,
    /// A feed, in speed bucket 0 (slowest) ..= [`BUCKETS`]−1 (fastest).
    Feed(usize),
}

/// Consecutive machine-frame points (X Y Z, mm) of one kind.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// Rapid or feed with its speed bucket.
    pub kind: RunKind,
    /// Points, mm.
    pub points: Vec<[f64; 3]>,
}

/// A straight-down feed into the work.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plunge {
    /// Bottom of the plunge, mm.
    pub at: [f64; 3],
    /// The tool comes straight back up from there (a drilled hole), rather than feeding on
    /// sideways (a plunge into a pocket or a contour).
    pub drill: bool,
}

/// The toolpath of a plan.
#[derive(Debug, Clone, PartialEq)]
pub struct Toolpath {
    /// Runs in execution order.
    pub runs: Vec<Run>,
    /// Where the machine starts and ends, mm.
    pub start: [f64; 3],
    /// End, mm.
    pub end: [f64; 3],
    /// Straight-down feeds.
    pub plunges: Vec<Plunge>,
    /// The fastest planned feed speed, mm/s (the top of the colour scale).
    pub vmax: f64,
}

fn xyz(p: &[f64]) -> [f64; 3] {
    [p[0], p[1], p[2]]
}

/// Samples `plan` (about every 0.5 mm, at most 16 points a segment).
pub fn toolpath(plan: &Plan) -> Toolpath {
    // (point, speed mm/s, rapid) per sample; a segment's end closes its last piece.
    let mut pts: Vec<([f64; 3], f64, bool)> = Vec::new();
    let mut vmax = 0.0f64;
    let segments: Vec<_> = plan
        .items
        .iter()
        .filter_map(|it| match it {
            Item::Segment(s) if s.kind != SegmentKind::Dwell => Some(s),
            _ => None,
        })
        .collect();
    for s in &segments {
        let rapid = s.kind == SegmentKind::Rapid;
        let n = ((s.length_mm / 0.5).ceil() as usize).clamp(1, 16);
        for i in 0..n {
            let t = s.duration_s * (i as f64 + 0.5) / n as f64;
            let speed = s.speed_at(t);
            if !rapid {
                vmax = vmax.max(speed);
            }
            let p = s.pose_at(s.duration_s * i as f64 / n as f64);
            pts.push((xyz(&p), speed, rapid));
        }
        pts.push((xyz(&s.end_mm), f64::NAN, rapid));
    }
    let bucket = |speed: f64| -> usize {
        if vmax > 0.0 {
            ((speed / vmax) * (BUCKETS as f64 - 1.0))
                .round()
                .clamp(0.0, BUCKETS as f64 - 1.0) as usize
        } else {
            0
        }
    };
    let mut runs: Vec<Run> = Vec::new();
    for w in pts.windows(2) {
        let (a, b) = (w[0], w[1]);
        if a.1.is_nan() {
            continue; // a segment's end: the next segment's first sample starts there
        }
        let kind = if a.2 {
            RunKind::Rapid
        } else {
            RunKind::Feed(bucket(a.1))
        };
        match runs.last_mut() {
            Some(r) if r.kind == kind && r.points.last() == Some(&a.0) => r.points.push(b.0),
            _ => runs.push(Run {
                kind,
                points: vec![a.0, b.0],
            }),
        }
    }
    Toolpath {
        runs,
        start: xyz(&plan.start_mm),
        end: xyz(&plan.end_mm),
        plunges: plunges(&segments),
        vmax,
    }
}

/// Whether a segment goes straight along Z (down when `down`).
fn vertical(s: &crate::motion::Segment, down: bool) -> bool {
    let (dx, dy, dz) = (
        s.end_mm[0] - s.start_mm[0],
        s.end_mm[1] - s.start_mm[1],
        s.end_mm[2] - s.start_mm[2],
    );
    let dxy = dx.hypot(dy);
    (if down { dz < -1e-6 } else { dz > 1e-6 }) && dxy <= 1e-4 + 0.02 * dz.abs()
}

/// Straight-down feeds: runs of vertical feed segments, each marked at its bottom; a drill
/// when the next motion goes straight up again.
fn plunges(all: &[&crate::motion::Segment]) -> Vec<Plunge> {
    // Pieces that hardly move (the ends of jerk-limited profiles, blends) say nothing about
    // direction: leave them out.
    let segments: Vec<&crate::motion::Segment> = all
        .iter()
        .copied()
        .filter(|s| {
            (0..3)
                .map(|a| (s.end_mm[a] - s.start_mm[a]).powi(2))
                .sum::<f64>()
                .sqrt()
                > 1e-4
        })
        .collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < segments.len() {
        let s = segments[i];
        if s.kind == SegmentKind::Feed && vertical(s, true) {
            let mut j = i;
            while j + 1 < segments.len()
                && segments[j + 1].kind == SegmentKind::Feed
                && vertical(segments[j + 1], true)
            {
                j += 1;
            }
            let drill = segments.get(j + 1).is_some_and(|n| vertical(n, false));
            out.push(Plunge {
                at: xyz(&segments[j].end_mm),
                drill,
            });
            i = j + 1;
        } else {
            i += 1;
        }
    }
    out
}
