//! Compensated G2/G3: the entry arc, and after it the corner with the held move (convex:
//! a corner arc first; concave: where the offset paths meet).

use super::{
    add_half_pi, corner_arc, find_turn, inside, ArcSpec, Item, Side, SMALL, TOLERANCE_EQUAL,
    TOOL_TOO_BIG,
};
use crate::gcode::canon::CanonCmd;
use crate::gcode::interp::Interp;
use crate::gcode::ldouble::{add_pi, add_pi_then, mul_sin_minus_half_pi};
use crate::gcode::GcodeError;
use std::f64::consts::PI;

impl Interp<'_> {
    /// G2/G3 with compensation on.
    pub(in crate::gcode::interp) fn comp_arc(
        &mut self,
        spec: &ArcSpec,
        end: [f64; 6],
    ) -> Result<(), GcodeError> {
        let ax = self.comp_plane()?;
        let col = self.loc.col;
        let (ex, ey, ez) = (end[ax.0], end[ax.1], end[ax.2]);
        let rest = [ez, end[3], end[4], end[5]];
        let radius = self.comp.radius;
        let side = self.comp.side.unwrap_or(Side::Left);
        let (cx, cy, cz) = self.comp_current(ax);
        if self.comp.first {
            if (ex - cx).hypot(ey - cy) <= radius {
                return Err(self.err(col, format!("Radius of cutter compensation entry arc is not greater than the tool radius ({radius:.4})")));
            }
            let (cenx, ceny, turn) = spec
                .center((cx, cy), (ex, ey))
                .map_err(|m| self.err(col, m))?;
            let arc_r = match spec.r {
                Some(r) => r.abs(),
                None => (cenx - cx).hypot(ceny - cy),
            };
            if arc_r <= radius && inside(side, turn) {
                return Err(self.err(col, TOOL_TOO_BIG));
            }
            self.comp_inverse_time_arc(spec, (cx, cy, cz), (cenx, ceny), turn, (ex, ey, ez))?;
            let gamma = if inside(side, turn) {
                (ceny - ey).atan2(cenx - ex)
            } else {
                (ey - ceny).atan2(ex - cenx)
            };
            self.comp.first = false;
            let (nx, ny) = (ex + radius * gamma.cos(), ey + radius * gamma.sin());
            let b_len = (cy - ny).hypot(cx - nx) / 2.0;
            let ab_ang = (ceny - ny).atan2(cenx - nx);
            let a_ang = (cy - ny).atan2(cx - nx) - ab_ang;
            if a_ang.cos().abs() < TOLERANCE_EQUAL {
                return Err(self.err(col, TOOL_TOO_BIG));
            }
            let c_len = b_len / a_ang.cos();
            let (ncx, ncy) = (nx + c_len * ab_ang.cos(), ny + c_len * ab_ang.sin());
            if ((ncx - nx).hypot(ncy - ny) - (ncx - cx).hypot(ncy - cy)).abs() > spec.spiral_abs {
                return Err(self.err(
                    col,
                    "Cutter compensation could not find the entry arc (bug in tool radius comp)",
                ));
            }
            if self.comp.orientation != 0 && self.comp.orientation != 9 {
                let mut p = [0.0; 6];
                p[0] = cx;
                p[1] = cy;
                p[2] = cz;
                p[3..].copy_from_slice(&end[3..]);
                self.enqueue(Item::Line {
                    feed: true,
                    dir: (0.0, 0.0),
                    end: p,
                });
                self.set_endpoint(cx, cy);
            }
            self.enqueue(Item::Arc {
                sweep: find_turn(cx, cy, ncx, ncy, turn, nx, ny),
                end: (nx, ny),
                center: (ncx, ncy),
                turn,
                rest,
            });
            self.comp_finish(ax, (nx, ny, ez), &end);
            return Ok(());
        }
        let (opx, opy, opz) = self.comp_programmed(ax);
        let (cenx, ceny, turn) = spec
            .center((opx, opy), (ex, ey))
            .map_err(|m| self.err(col, m))?;
        self.comp_inverse_time_arc(spec, (opx, opy, opz), (cenx, ceny), turn, (ex, ey, ez))?;
        let arc_radius = (cenx - ex).hypot(ceny - ey);
        let theta = add_half_pi(
            (cy - opy).atan2(cx - opx),
            if side == Side::Left { -1.0 } else { 1.0 },
        );
        let mut delta = (ceny - opy).atan2(cenx - opx);
        let alpha = add_half_pi(delta, if spec.cw { 1.0 } else { -1.0 });
        let mut beta = if side == Side::Left {
            theta - alpha
        } else {
            alpha - theta
        };
        if beta > 1.5 * PI {
            beta = add_pi(beta, -2.0);
        } else if beta < -std::f64::consts::FRAC_PI_2 {
            beta = add_pi(beta, 2.0);
        }
        let cutting_inside = (side == Side::Left && !spec.cw) || (side == Side::Right && spec.cw);
        let gamma = if cutting_inside {
            if arc_radius < radius {
                return Err(self.err(
                    col,
                    format!("{TOOL_TOO_BIG} (arc radius {arc_radius:.4}, tool radius {radius:.4})"),
                ));
            }
            (ceny - ey).atan2(cenx - ex)
        } else {
            delta = add_pi(delta, 1.0);
            (ey - ceny).atan2(ex - cenx)
        };
        let (nx, ny) = (ex + radius * gamma.cos(), ey + radius * gamma.sin());
        let sweep = find_turn(opx, opy, cenx, ceny, turn, ex, ey);
        let main = Item::Arc {
            sweep,
            end: (nx, ny),
            center: (cenx, ceny),
            turn,
            rest,
        };
        let gouge = "Arc move in concave corner cannot be reached by the tool without gouging";
        if !(-SMALL..=PI + SMALL).contains(&beta)
            || ((beta - PI).abs() < SMALL && !inside(side, turn))
        {
            // concave corner
            let (mx, my) = match self.front_arc() {
                None => {
                    let ccy = mul_sin_minus_half_pi(arc_radius, beta);
                    let (dist, ang) = if inside(side, turn) {
                        let dist = arc_radius - radius;
                        let l = (ccy + radius) / dist;
                        if !(-1.0..=1.0).contains(&l) {
                            return Err(self.err(col, gouge));
                        }
                        (
                            dist,
                            if turn > 0 {
                                theta + l.asin()
                            } else {
                                theta - l.asin()
                            },
                        )
                    } else {
                        let dist = arc_radius + radius;
                        let l = (ccy - radius) / dist;
                        if !(-1.0..=1.0).contains(&l) {
                            return Err(self.err(col, gouge));
                        }
                        (
                            dist,
                            if turn > 0 {
                                add_pi_then(theta, 1.0, -l.asin())
                            } else {
                                add_pi_then(theta, 1.0, l.asin())
                            },
                        )
                    };
                    (cenx + dist * ang.cos(), ceny + dist * ang.sin())
                }
                Some((pend, pcen, pturn)) => {
                    let oldrad = (pcen.1 - pend.1).hypot(pcen.0 - pend.0);
                    let newrad = if inside(side, turn) {
                        arc_radius - radius
                    } else {
                        arc_radius + radius
                    };
                    let arc_cc = (pcen.1 - ceny).hypot(pcen.0 - cenx);
                    if oldrad == 0.0 || arc_cc == 0.0 {
                        return Err(self.err(
                            col,
                            "Arc to arc motion is invalid because the arcs have the same center",
                        ));
                    }
                    let a = (oldrad * oldrad + arc_cc * arc_cc - newrad * newrad)
                        / (2.0 * oldrad * arc_cc);
                    if !(-1.0..=1.0).contains(&a) {
                        return Err(self.err(col, format!("Arc to arc motion makes a corner the compensated tool (radius {radius:.4}) can't fit in without gouging")));
                    }
                    let pullback = a.acos();
                    let cc_dir = (ceny - pcen.1).atan2(cenx - pcen.0);
                    let plus = if inside(side, pturn) {
                        turn > 0
                    } else {
                        turn <= 0
                    };
                    let dir = if plus {
                        cc_dir + pullback
                    } else {
                        cc_dir - pullback
                    };
                    (pcen.0 + oldrad * dir.cos(), pcen.1 + oldrad * dir.sin())
                }
            };
            self.move_endpoint_and_flush(mx, my)?;
            self.enqueue(main);
        } else if beta > SMALL {
            // convex corner: an arc around the programmed corner first
            let (mx, my) = (opx + radius * delta.cos(), opy + radius * delta.sin());
            self.dequeue()?;
            self.enqueue(corner_arc(side, (mx, my), (opx, opy), cz, &end));
            self.dequeue()?;
            self.set_endpoint(mx, my);
            self.enqueue(main);
        } else {
            self.dequeue()?;
            self.set_endpoint(cx, cy);
            self.enqueue(main);
        }
        self.comp_finish(ax, (nx, ny, ez), &end);
        Ok(())
    }

    /// Inverse-time feed of a compensated arc: the programmed arc's length (LinuxCNC).
    fn comp_inverse_time_arc(
        &mut self,
        spec: &ArcSpec,
        start: (f64, f64, f64),
        center: (f64, f64),
        turn: i32,
        end: (f64, f64, f64),
    ) -> Result<(), GcodeError> {
        if self.s.feed_mode != crate::gcode::canon::FeedMode::InverseTime {
            return Ok(());
        }
        let radius = (start.0 - center.0).hypot(start.1 - center.1);
        let theta = find_turn(start.0, start.1, center.0, center.1, turn, end.0, end.1);
        let len = if end.2 == start.2 {
            radius * theta.abs()
        } else {
            (radius * theta).hypot(end.2 - start.2)
        };
        let rate = (len * spec.f.unwrap_or(0.0)).max(0.1);
        self.s.feed_rate = rate;
        self.emit(CanonCmd::SetFeedRate(rate))
    }
}
