//! PNG output: the SVG rasterised by resvg (pure Rust: usvg parses, tiny-skia paints), so
//! `hytask plot -o part.png` needs no system library. Text uses the system's font files
//! when there are any (fontdb reads them itself); without fonts the labels are left out
//! and the lines, marks and colours are still drawn.

/// Why a picture could not be rasterised.
#[derive(Debug, thiserror::Error)]
pub enum PngError {
    /// The SVG did not parse (a bug in the drawing code).
    #[error("the picture's SVG does not parse: {0}")]
    Svg(String),
    /// The size is zero or too large for a pixmap.
    #[error("cannot rasterise a {0} x {1} px picture")]
    Size(u32, u32),
    /// PNG encoding failed.
    #[error("PNG encoding: {0}")]
    Encode(String),
}

/// Rasterises `svg` at its own pixel size; returns the PNG file's bytes.
pub fn render(svg: &str) -> Result<Vec<u8>, PngError> {
    let mut opt = resvg::usvg::Options::default();
    opt.fontdb_mut().load_system_fonts();
    let tree = resvg::usvg::Tree::from_str(svg, &opt).map_err(|e| PngError::Svg(e.to_string()))?;
    let size = tree.size().to_int_size();
    let (w, h) = (size.width(), size.height());
    let mut pixmap = resvg::tiny_skia::Pixmap::new(w, h).ok_or(PngError::Size(w, h))?;
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::identity(),
        &mut pixmap.as_mut(),
    );
    pixmap
        .encode_png()
        .map_err(|e| PngError::Encode(e.to_string()))
}
