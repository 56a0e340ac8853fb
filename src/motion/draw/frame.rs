//! The page: a plot area in pixels showing a box of data coordinates at one scale in both
//! directions (a drawing keeps its shape), with room for the title above, axis labels
//! beside and below, and the legend band at the bottom, all inside the picture.
//!
//! The data-to-pixel map is nalgebra's orthographic projection of the data box to
//! normalised device coordinates, then the viewport transform of the plot area.

use super::doc::Doc;
use nalgebra::{Orthographic3, Point3};

/// Space above the plot area (title), px.
pub const TOP: f64 = 40.0;
/// Space left of the plot area (vertical axis labels), px.
pub const LEFT: f64 = 70.0;
/// Space right of the plot area, px.
pub const RIGHT: f64 = 30.0;
/// Space below the plot area for the horizontal axis labels, px.
pub const BELOW: f64 = 40.0;
/// Height of the legend band under the labels, px.
pub const LEGEND: f64 = 64.0;

/// A box of data coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Smallest u.
    pub u0: f64,
    /// Largest u.
    pub u1: f64,
    /// Smallest v.
    pub v0: f64,
    /// Largest v.
    pub v1: f64,
}

impl Bounds {
    /// The empty box (grows with [`add`](Self::add)).
    pub fn empty() -> Self {
        Bounds {
            u0: f64::INFINITY,
            u1: f64::NEG_INFINITY,
            v0: f64::INFINITY,
            v1: f64::NEG_INFINITY,
        }
    }

    /// Grows the box to hold (u, v).
    pub fn add(&mut self, (u, v): (f64, f64)) {
        self.u0 = self.u0.min(u);
        self.u1 = self.u1.max(u);
        self.v0 = self.v0.min(v);
        self.v1 = self.v1.max(v);
    }

    /// Whether nothing was added.
    pub fn is_empty(&self) -> bool {
        !(self.u0 <= self.u1 && self.v0 <= self.v1)
    }

    /// Whether (u, v) lies inside (with `tol`).
    pub fn contains(&self, (u, v): (f64, f64), tol: f64) -> bool {
        u >= self.u0 - tol && u <= self.u1 + tol && v >= self.v0 - tol && v <= self.v1 + tol
    }
}

/// The page layout and the data-to-pixel map.
#[derive(Debug, Clone)]
pub struct Frame {
    /// The data box shown (padded, with the plot area's aspect ratio when `same_scale`).
    pub data: Bounds,
    /// Picture width, px.
    pub width: f64,
    /// Picture height, px.
    pub height: f64,
    /// Plot area: left, top, width, height, px.
    pub area: (f64, f64, f64, f64),
    proj: Orthographic3<f64>,
}

impl Frame {
    /// Lays out a picture `width` px wide showing `fit` (padded by 5 %). With `same_scale`
    /// one data unit is as long across as up (drawings); the height follows the data's
    /// shape, between 0.35 and 1.1 of the plot area's width (the data box widens to fill
    /// the rest). Without it (charts), the plot area is `chart_aspect` × its width.
    pub fn new(fit: Bounds, width: f64, same_scale: bool, chart_aspect: f64) -> Frame {
        let mut d = if fit.is_empty() {
            Bounds {
                u0: 0.0,
                u1: 1.0,
                v0: 0.0,
                v1: 1.0,
            }
        } else {
            fit
        };
        let span = (d.u1 - d.u0).max(d.v1 - d.v0).max(1e-3);
        // At least 1 % of the larger span in both directions (a flat part still shows).
        for (lo, hi) in [(&mut d.u0, &mut d.u1), (&mut d.v0, &mut d.v1)] {
            let pad = 0.05 * (*hi - *lo).max(0.01 * span) + 0.005 * span;
            *lo -= pad;
            *hi += pad;
        }
        let aw = width - LEFT - RIGHT;
        let ah = if same_scale {
            let (du, dv) = (d.u1 - d.u0, d.v1 - d.v0);
            let ah = (aw * dv / du).clamp(0.35 * aw, 1.1 * aw);
            // Widen the data box to the area's aspect ratio: same mm per px both ways.
            let (want_du, want_dv) = (dv * aw / ah, du * ah / aw);
            if want_du > du {
                let c = 0.5 * (d.u0 + d.u1);
                (d.u0, d.u1) = (c - 0.5 * want_du, c + 0.5 * want_du);
            } else if want_dv > dv {
                let c = 0.5 * (d.v0 + d.v1);
                (d.v0, d.v1) = (c - 0.5 * want_dv, c + 0.5 * want_dv);
            }
            ah
        } else {
            aw * chart_aspect
        };
        let height = TOP + ah + BELOW + LEGEND;
        Frame {
            data: d,
            width,
            height,
            area: (LEFT, TOP, aw, ah),
            proj: Orthographic3::new(d.u0, d.u1, d.v0, d.v1, -1.0, 1.0),
        }
    }

    /// Pixel position of data point (u, v).
    pub fn px(&self, (u, v): (f64, f64)) -> (f64, f64) {
        let n = self.proj.project_point(&Point3::new(u, v, 0.0));
        let (x, y, w, h) = self.area;
        (x + 0.5 * (n.x + 1.0) * w, y + 0.5 * (1.0 - n.y) * h)
    }

    /// Pixels per data unit along u.
    pub fn scale(&self) -> f64 {
        self.area.2 / (self.data.u1 - self.data.u0)
    }

    /// A document of this frame's size titled `title`, with `heading` centred over the plot
    /// area (every picture starts so).
    pub fn titled_doc(&self, title: &str, heading: &str) -> Doc {
        let mut doc = Doc::new(self.width, self.height, title);
        doc.text(
            (self.area.0 + self.area.2 / 2.0, 20.0),
            15.0,
            "middle",
            "title",
            heading,
        );
        doc
    }

    /// Top of the legend band, px.
    pub fn legend_top(&self) -> f64 {
        self.height - LEGEND
    }

    /// The SVG clip path `id` of the plot area.
    pub fn clip_path(&self, id: &str) -> String {
        let (x, y, w, h) = self.area;
        format!(
            r#"<clipPath id="{id}"><rect x="{x:.2}" y="{y:.2}" width="{w:.2}" height="{h:.2}"/></clipPath>"#
        )
    }

    /// Clamps a pixel position into the plot area.
    pub fn clamp_px(&self, (px, py): (f64, f64)) -> (f64, f64) {
        let (x, y, w, h) = self.area;
        (px.clamp(x, x + w), py.clamp(y, y + h))
    }
}
