//! Compensated G0/G1: the entry move, and after it the corner with the held move (convex:
//! an arc or traverse round the programmed corner; concave: the intersection).

use super::{add_half_pi, corner_arc, inside, Item, Side, SMALL};
use crate::gcode::interp::Interp;
use crate::gcode::ldouble::{add_pi, half_add_pi};
use crate::gcode::modal::Block;
use crate::gcode::GcodeError;
use std::f64::consts::PI;

impl Interp<'_> {
    /// G0/G1 with compensation on (`end` is the programmed end, program frame).
    pub(in crate::gcode::interp) fn comp_straight(
        &mut self,
        m: u16,
        b: &Block,
        end: [f64; 6],
    ) -> Result<(), GcodeError> {
        if b.gcode(0) == Some(530) {
            return Err(self.err(self.loc.col, "Cannot use G53 with cutter radius comp"));
        }
        let ax = self.comp_plane()?;
        let (px, py, pz) = (end[ax.0], end[ax.1], end[ax.2]);
        let mut rest = [0.0; 6];
        rest[2] = pz;
        rest[3..].copy_from_slice(&end[3..]);
        let feed = m == 10;
        let radius = self.comp.radius;
        let side = self.comp.side.unwrap_or(Side::Left);
        let (cx, cy, cz) = self.comp_current(ax);
        if self.comp.first {
            let distance = (px - cx).hypot(py - cy);
            if distance < radius {
                return Err(self.err(
                    self.loc.col,
                    format!("Length of cutter compensation entry move ({distance:.4}) is not greater than the tool radius ({radius:.4})"),
                ));
            }
            let alpha = add_half_pi(
                (py - cy).atan2(px - cx),
                if side == Side::Left { 1.0 } else { -1.0 },
            );
            let (ex, ey) = (px + radius * alpha.cos(), py + radius * alpha.sin());
            self.set_endpoint(cx, cy);
            rest[0] = ex;
            rest[1] = ey;
            self.enqueue(Item::Line {
                feed,
                dir: (alpha.cos(), alpha.sin()),
                end: rest,
            });
            self.comp.first = false;
            self.comp_finish(ax, (ex, ey, pz), &end);
            return Ok(());
        }
        let (opx, opy, _) = self.comp_programmed(ax);
        let (mut ex, mut ey) = (cx, cy);
        if py == opy && px == opx {
            rest[0] = cx;
            rest[1] = cy;
            self.enqueue(Item::Line {
                feed,
                dir: (0.0, 0.0),
                end: rest,
            });
        } else {
            let mut theta = (cy - opy).atan2(cx - opx);
            let mut alpha = (py - opy).atan2(px - opx);
            let (beta, gamma) = if side == Side::Left {
                if theta < alpha {
                    theta = add_pi(theta, 2.0);
                }
                (
                    add_half_pi(theta - alpha, -1.0),
                    std::f64::consts::FRAC_PI_2,
                )
            } else {
                if alpha < theta {
                    alpha = add_pi(alpha, 2.0);
                }
                (
                    add_half_pi(alpha - theta, -1.0),
                    -std::f64::consts::FRAC_PI_2,
                )
            };
            let ag = alpha + gamma;
            ex = px + radius * ag.cos();
            ey = py + radius * ag.sin();
            let (mid_x, mid_y) = (opx + radius * ag.cos(), opy + radius * ag.sin());
            let front = self.front_arc();
            let concave = !(-SMALL..=PI + SMALL).contains(&beta)
                || (beta > PI - SMALL
                    && front.is_some_and(|(_, _, t)| {
                        (side == Side::Right && t > 0) || (side == Side::Left && t < 0)
                    }));
            if !concave && beta > SMALL {
                // convex corner: an arc around the programmed corner (a traverse for G0)
                self.move_endpoint_and_flush(cx, cy)?;
                let mut p = rest;
                p[0] = mid_x;
                p[1] = mid_y;
                p[2] = cz;
                if feed {
                    self.enqueue(corner_arc(side, (mid_x, mid_y), (opx, opy), cz, &end));
                } else {
                    self.enqueue(Item::Line {
                        feed: false,
                        dir: (0.0, 0.0),
                        end: p,
                    });
                }
                self.dequeue()?;
                self.set_endpoint(mid_x, mid_y);
            } else if concave {
                let (mx, my) = match front {
                    None => {
                        // line -> line: back along the held move to the intersection
                        let halfcorner = half_add_pi(beta);
                        if halfcorner == 0.0 {
                            return Err(self.err(
                                self.loc.col,
                                "Zero degree inside corner is invalid for cutter compensation",
                            ));
                        }
                        let retreat = radius / halfcorner.tan();
                        (
                            cx + retreat * (theta + gamma).cos(),
                            cy + retreat * (theta + gamma).sin(),
                        )
                    }
                    Some((pend, pcen, pturn)) => {
                        // arc -> line: where the held (compensated) arc meets the new offset line
                        let oldrad = (pcen.1 - pend.1).hypot(pcen.0 - pend.0);
                        let base_dir = (py - opy).atan2(px - opx);
                        let th = add_half_pi(base_dir, if pturn > 0 { 1.0 } else { -1.0 });
                        let phi = (pcen.1 - opy).atan2(pcen.0 - opx);
                        let ins = inside(side, pturn);
                        let oldrad_uncomp = if ins {
                            oldrad + radius
                        } else {
                            oldrad - radius
                        };
                        let d = oldrad_uncomp * (th - phi).cos();
                        let l = if ins { d - radius } else { d + radius } / oldrad;
                        if !(-1.0..=1.0).contains(&l) {
                            return Err(self.err(self.loc.col, format!("Arc to straight motion makes a corner the compensated tool (radius {radius:.4}) can't fit in without gouging")));
                        }
                        let a = if (pturn > 0) == ins {
                            -l.acos()
                        } else {
                            l.acos()
                        };
                        let ang = add_pi(a + th, 1.0);
                        (pcen.0 + oldrad * ang.cos(), pcen.1 + oldrad * ang.sin())
                    }
                };
                self.move_endpoint_and_flush(mx, my)?;
            } else {
                self.dequeue()?;
                self.set_endpoint(cx, cy);
            }
            rest[0] = ex;
            rest[1] = ey;
            self.enqueue(Item::Line {
                feed,
                dir: (px - opx, py - opy),
                end: rest,
            });
        }
        self.comp_finish(ax, (ex, ey, pz), &end);
        Ok(())
    }
}
