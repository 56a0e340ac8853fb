//! Merging of nearly collinear short moves (G64 Q, "naive CAM"): a run of feed moves whose
//! inner vertices all lie within the merge tolerance of the chord from the first start to
//! the last end becomes that chord. Every point of the chord is then within the tolerance of
//! the programmed polyline and vice versa, so the budget adds up with the blend tolerance.

use super::moves::{Junction, Move, MoveKind};
use crate::gcode::NUM_AXES;

/// Longest run merged into one move (bounds the work per move).
const MAX_RUN: usize = 256;

fn distance_to_segment(p: &[f64; NUM_AXES], a: &[f64; NUM_AXES], b: &[f64; NUM_AXES]) -> f64 {
    let mut ab2 = 0.0;
    let mut ap_ab = 0.0;
    for i in 0..NUM_AXES {
        ab2 += (b[i] - a[i]) * (b[i] - a[i]);
        ap_ab += (p[i] - a[i]) * (b[i] - a[i]);
    }
    let t = if ab2 > 0.0 {
        (ap_ab / ab2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut d2 = 0.0;
    for i in 0..NUM_AXES {
        let q = a[i] + t * (b[i] - a[i]);
        d2 += (p[i] - q) * (p[i] - q);
    }
    d2.sqrt()
}

fn can_join(a: &Move, b: &Move) -> bool {
    a.kind == MoveKind::Feed
        && b.kind == MoveKind::Feed
        && a.arc_id == 0
        && b.arc_id == 0
        && a.merge_tol_mm > 0.0
        && a.merge_tol_mm == b.merge_tol_mm
        && a.feed_mm_s == b.feed_mm_s
        && matches!(a.junction, Junction::Blend { .. })
        && a.junction == b.junction
}

/// Merges `moves` in place; `keep[i]` false forbids merging move `i` with `i + 1` (an
/// auxiliary item sits between them).
pub fn merge(moves: Vec<Move>, joinable: &[bool]) -> (Vec<Move>, Vec<usize>) {
    let mut out = Vec::with_capacity(moves.len());
    let mut last_index = Vec::with_capacity(moves.len());
    let mut i = 0;
    while i < moves.len() {
        let first = moves[i];
        let mut j = i;
        while j + 1 < moves.len()
            && j + 1 - i < MAX_RUN
            && joinable[j]
            && can_join(&moves[j], &moves[j + 1])
        {
            let end = moves[j + 1].end_mm;
            let ok = (i..=j).all(|k| {
                distance_to_segment(&moves[k].end_mm, &first.start_mm, &end) <= first.merge_tol_mm
            });
            if !ok {
                break;
            }
            j += 1;
        }
        let mut m = first;
        m.end_mm = moves[j].end_mm;
        m.junction = moves[j].junction;
        out.push(m);
        last_index.push(j);
        i = j + 1;
    }
    (out, last_index)
}
