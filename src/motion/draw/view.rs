//! Views of the 3-D toolpath: orthographic top, front and side views and an isometric one,
//! each a nalgebra camera (`Isometry3::look_at_rh`) whose x and y are the picture's axes.

use nalgebra::{Isometry3, Point3, Vector3};

/// Which way the toolpath is looked at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum View {
    /// From above: X to the right, Y up.
    Top,
    /// From the front (−Y): X to the right, Z up.
    Front,
    /// From the right (+X): Y to the right, Z up.
    Side,
    /// Isometric from front-right-top: X and Y at 30° below and above the horizontal, Z up.
    Iso,
}

impl View {
    /// The camera of this view, looking at the origin.
    pub fn camera(self) -> Isometry3<f64> {
        let (eye, up) = match self {
            View::Top => (Vector3::z(), Vector3::y()),
            View::Front => (-Vector3::y(), Vector3::z()),
            View::Side => (Vector3::x(), Vector3::z()),
            View::Iso => (Vector3::new(1.0, -1.0, 1.0), Vector3::z()),
        };
        Isometry3::look_at_rh(&Point3::from(eye), &Point3::origin(), &up)
    }

    /// The machine axes along the picture's horizontal and vertical directions, when the
    /// view is orthographic along one axis (the grid is then labelled in those axes' mm).
    pub fn plane_axes(self) -> Option<(usize, usize)> {
        match self {
            View::Top => Some((0, 1)),
            View::Front => Some((0, 2)),
            View::Side => Some((1, 2)),
            View::Iso => None,
        }
    }

    /// Name for titles.
    pub fn name(self) -> &'static str {
        match self {
            View::Top => "top",
            View::Front => "front",
            View::Side => "side",
            View::Iso => "isometric",
        }
    }
}

/// Projects machine-frame points (mm) to the picture plane of a view.
#[derive(Debug, Clone, Copy)]
pub struct Projector {
    camera: Isometry3<f64>,
}

impl Projector {
    /// The projector of `view`.
    pub fn new(view: View) -> Self {
        Projector {
            camera: view.camera(),
        }
    }

    /// Picture-plane coordinates (u right, v up), mm.
    pub fn uv(&self, p: [f64; 3]) -> (f64, f64) {
        let c = self.camera.transform_point(&Point3::new(p[0], p[1], p[2]));
        (c.x, c.y)
    }
}
