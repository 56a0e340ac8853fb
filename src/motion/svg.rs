//! SVG of a plan's toolpath: the top view of [`super::draw`] (kept for callers that only
//! want the picture; `hytask plot` uses `draw` with its view and size options).

use super::draw::{self, Options};
use super::Plan;

/// Renders `plan` as an SVG document: top view, 1000 px wide.
pub fn render(plan: &Plan, title: &str) -> String {
    draw::render(
        plan,
        &Options {
            title: title.to_string(),
            ..Options::default()
        },
    )
}
