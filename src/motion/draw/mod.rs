//! Pictures of a plan: the toolpath in a top, front, side or isometric view, fitted to the
//! cutting moves, on a labelled millimetre grid, with start/end, plunge and drill marks
//! and a legend inside the picture; SVG, and PNG through a pure-Rust renderer.
//!
//! One job per submodule, so that other pictures (the feed-along-path plot of `--velocity`)
//! reuse the same pieces: [`frame`] maps data coordinates to pixels and lays out the page,
//! [`grid`] draws labelled grids, [`doc`] writes SVG elements, [`legend`] the key, [`png`]
//! rasterises. The toolpath itself: [`path`] samples the plan into coloured runs and finds
//! the marks, [`view`] projects 3-D points with nalgebra, [`toolpath`] puts it together.
//! [`feed`] is the feed-along-the-path chart of `hytask plot --velocity`.

pub mod doc;
pub mod feed;
pub mod frame;
pub mod grid;
pub mod legend;
pub mod path;
pub mod png;
pub mod toolpath;
pub mod view;

pub use toolpath::render;
pub use view::View;

/// What to draw and how large.
#[derive(Debug, Clone)]
pub struct Options {
    /// Title shown at the top (the file name).
    pub title: String,
    /// Which way the toolpath is looked at.
    pub view: View,
    /// Picture width in pixels (the height follows the drawing's shape).
    pub width_px: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            title: String::new(),
            view: View::Top,
            width_px: 1000.0,
        }
    }
}
