//! Planar NURBS curves (G5, G5.1 splines; see `gcode::interp::splines`): evaluation by de
//! Boor's algorithm on a clamped uniform knot vector, and flattening into chords that stay
//! within a tolerance of the curve, as arcs are flattened.

/// A rational B-spline in the plane: control points `[x, y, weight]`, clamped uniform knots.
#[derive(Debug, Clone)]
pub struct Nurbs<'a> {
    points: &'a [[f64; 3]],
    order: usize,
    knots: Vec<f64>,
}

/// Deepest subdivision: 2^16 chords at most per curve.
const MAX_DEPTH: u32 = 16;

impl<'a> Nurbs<'a> {
    /// The curve of `points` and `order` (degree + 1), or `None` when there are fewer points
    /// than the order, the order is below 2, or a weight is not positive.
    pub fn new(points: &'a [[f64; 3]], order: usize) -> Option<Nurbs<'a>> {
        let n = points.len();
        if order < 2
            || n < order
            || points
                .iter()
                .any(|p| p[2] <= 0.0 || !p.iter().all(|v| v.is_finite()))
        {
            return None;
        }
        // Clamped: `order` knots at 0 and at 1, uniform in between.
        let spans = n - order + 1;
        let mut knots = Vec::with_capacity(n + order);
        knots.extend(std::iter::repeat_n(0.0, order));
        for s in 1..spans {
            knots.push(s as f64 / spans as f64);
        }
        knots.extend(std::iter::repeat_n(1.0, order));
        Some(Nurbs {
            points,
            order,
            knots,
        })
    }

    /// The point at parameter `u` in `[0, 1]`.
    pub fn point(&self, u: f64) -> [f64; 2] {
        let u = u.clamp(0.0, 1.0);
        let k = self.order;
        let n = self.points.len();
        // The knot span: knots[s] <= u < knots[s + 1], the last span for u = 1.
        let mut s = k - 1;
        while s + 1 < n && self.knots[s + 1] <= u {
            s += 1;
        }
        // Homogeneous de Boor.
        let mut d: Vec<[f64; 3]> = (0..k)
            .map(|j| {
                let p = self.points[j + s + 1 - k];
                [p[0] * p[2], p[1] * p[2], p[2]]
            })
            .collect();
        for r in 1..k {
            for j in (r..k).rev() {
                let i = j + s + 1 - k;
                let den = self.knots[i + k - r] - self.knots[i];
                let a = if den > 0.0 {
                    (u - self.knots[i]) / den
                } else {
                    0.0
                };
                for c in 0..3 {
                    d[j][c] = (1.0 - a) * d[j - 1][c] + a * d[j][c];
                }
            }
        }
        let w = d[k - 1][2];
        [d[k - 1][0] / w, d[k - 1][1] / w]
    }

    /// Points along the curve after the start, ending exactly at the last control point,
    /// such that each chord stays within `tol` of the curve (checked at its quarter, half and
    /// three-quarter parameters).
    pub fn chord_points(&self, tol: f64) -> Vec<[f64; 2]> {
        let tol = if tol > 0.0 { tol } else { 1e-3 };
        let mut out = Vec::new();
        let a = self.point(0.0);
        let b = self.point(1.0);
        self.subdivide(0.0, a, 1.0, b, tol, 0, &mut out);
        if let (Some(last), Some(end)) = (out.last_mut(), self.points.last()) {
            *last = [end[0], end[1]];
        }
        out
    }

    #[allow(clippy::too_many_arguments)]
    fn subdivide(
        &self,
        u0: f64,
        p0: [f64; 2],
        u1: f64,
        p1: [f64; 2],
        tol: f64,
        depth: u32,
        out: &mut Vec<[f64; 2]>,
    ) {
        let um = 0.5 * (u0 + u1);
        let pm = self.point(um);
        let flat = depth >= MAX_DEPTH
            || [0.25, 0.5, 0.75].iter().all(|&f| {
                let u = u0 + f * (u1 - u0);
                let p = if f == 0.5 { pm } else { self.point(u) };
                distance_to_segment(p, p0, p1) <= tol
            });
        // At least two chords for a curve whose ends meet (a closed loop is not flat).
        if flat && (depth > 0 || distance(p0, p1) > tol) {
            out.push(p1);
        } else {
            self.subdivide(u0, p0, um, pm, tol, depth + 1, out);
            self.subdivide(um, pm, u1, p1, tol, depth + 1, out);
        }
    }
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn distance_to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let d = [b[0] - a[0], b[1] - a[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    if len2 == 0.0 {
        return distance(p, a);
    }
    let t = (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0);
    distance(p, [a[0] + t * d[0], a[1] + t * d[1]])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bezier3(p: &[[f64; 3]], t: f64) -> [f64; 2] {
        let m = 1.0 - t;
        let c = [m * m * m, 3.0 * m * m * t, 3.0 * m * t * t, t * t * t];
        let mut out = [0.0; 2];
        for (w, q) in c.iter().zip(p) {
            out[0] += w * q[0];
            out[1] += w * q[1];
        }
        out
    }

    #[test]
    fn a_cubic_with_four_points_is_the_bezier_curve() {
        let pts = [
            [0.0, 0.0, 1.0],
            [1.0, 3.0, 1.0],
            [3.0, 3.0, 1.0],
            [4.0, 0.0, 1.0],
        ];
        let c = Nurbs::new(&pts, 4).unwrap();
        for i in 0..=10 {
            let t = f64::from(i) / 10.0;
            let (a, b) = (c.point(t), bezier3(&pts, t));
            assert!(distance(a, b) < 1e-12, "t={t}: {a:?} vs {b:?}");
        }
    }

    #[test]
    fn a_quadratic_with_unit_weights_is_a_parabola_and_a_weighted_one_a_circle() {
        let pts = [[0.0, 0.0, 1.0], [1.0, 1.0, 1.0], [2.0, 0.0, 1.0]];
        let c = Nurbs::new(&pts, 3).unwrap();
        assert!(distance(c.point(0.5), [1.0, 0.5]) < 1e-12);
        // A quarter circle of radius 1: middle weight cos(45°).
        let w = std::f64::consts::FRAC_1_SQRT_2;
        let q = [[1.0, 0.0, 1.0], [1.0, 1.0, w], [0.0, 1.0, 1.0]];
        let c = Nurbs::new(&q, 3).unwrap();
        for i in 0..=8 {
            let p = c.point(f64::from(i) / 8.0);
            assert!((p[0].hypot(p[1]) - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn chords_stay_within_tolerance_and_end_on_the_end_point() {
        let pts = [
            [0.0, 0.0, 1.0],
            [0.0, 10.0, 1.0],
            [10.0, 10.0, 1.0],
            [10.0, 0.0, 1.0],
        ];
        let c = Nurbs::new(&pts, 4).unwrap();
        for tol in [0.1, 0.01, 0.001] {
            let chords = c.chord_points(tol);
            assert_eq!(chords.last(), Some(&[10.0, 0.0]));
            let mut worst: f64 = 0.0;
            // Dense samples of the curve lie within tol of the polyline.
            for i in 0..=1000 {
                let p = c.point(f64::from(i) / 1000.0);
                let mut best = f64::MAX;
                let mut a = [0.0, 0.0];
                for b in &chords {
                    best = best.min(distance_to_segment(p, a, *b));
                    a = *b;
                }
                worst = worst.max(best);
            }
            assert!(worst <= tol * 1.0001, "tol {tol}: {worst}");
            assert!(chords.len() < 2000);
        }
    }

    #[test]
    fn bad_curves_are_refused() {
        let pts = [[0.0, 0.0, 1.0], [1.0, 1.0, 0.0], [2.0, 0.0, 1.0]];
        assert!(Nurbs::new(&pts, 3).is_none());
        assert!(Nurbs::new(&pts[..2], 3).is_none());
    }
}
