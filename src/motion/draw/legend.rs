//! The key, drawn in the legend band at the bottom of the picture (inside it): the feed
//! colour scale, the line styles and marks used, and a one-line summary.

use super::doc::Doc;
use super::frame::Frame;
use super::path::BUCKETS;

/// Colour of speed bucket `b`: hue 240 (blue, slow) to 0 (red, fast).
pub fn colour(b: usize) -> String {
    let h = 240.0 * (1.0 - b as f64 / (BUCKETS - 1) as f64);
    format!("hsl({h:.0},90%,45%)")
}

/// Draws one mark at a pixel position.
pub type Mark = fn(&mut Doc, (f64, f64));

/// Style of a rapid line.
pub const RAPID_STYLE: &str = r##"stroke="#999" stroke-width="1.2" stroke-dasharray="6 4""##;

/// The marks' styles (shared by the drawing and the key).
pub mod marks {
    use super::Doc;

    /// Start of the program: a green circle.
    pub fn start(doc: &mut Doc, at: (f64, f64)) {
        doc.circle(
            at,
            6.0,
            r##"class="mark start" fill="#2a2" stroke="black""##,
        );
    }

    /// End of the program: a red square.
    pub fn end(doc: &mut Doc, at: (f64, f64)) {
        doc.rect(
            at.0 - 5.0,
            at.1 - 5.0,
            10.0,
            10.0,
            r##"class="mark end" fill="#d22" stroke="black""##,
        );
    }

    /// A drilled hole: a black-filled circle with a white centre.
    pub fn drill(doc: &mut Doc, at: (f64, f64)) {
        doc.circle(at, 5.0, r#"class="mark drill" fill="black" stroke="black""#);
        doc.circle(at, 1.5, r#"fill="white""#);
    }

    /// A plunge: an open circle with a cross.
    pub fn plunge(doc: &mut Doc, at: (f64, f64)) {
        doc.circle(
            at,
            5.0,
            r##"class="mark plunge" fill="white" stroke="#222" stroke-width="1.5""##,
        );
        doc.line((at.0 - 3.5, at.1), (at.0 + 3.5, at.1), r##"stroke="#222""##);
        doc.line((at.0, at.1 - 3.5), (at.0, at.1 + 3.5), r##"stroke="#222""##);
    }
}

/// Draws the key of a toolpath picture: feed colours from 0 to `vmax` mm/s, then rapid,
/// start, end, plunge and drill, then `summary` on a second line.
pub fn toolpath(doc: &mut Doc, f: &Frame, vmax: f64, summary: &str) {
    let y = open_box(doc, f);
    let mut x = 16.0;
    for b in 0..BUCKETS {
        doc.rect(x, y - 10.0, 14.0, 12.0, &format!(r#"fill="{}""#, colour(b)));
        x += 14.0;
    }
    x += 6.0;
    doc.text(
        (x, y),
        12.0,
        "start",
        "legend-text",
        &format!("feed 0 … {vmax:.1} mm/s"),
    );
    x += 150.0;
    doc.line((x, y - 4.0), (x + 30.0, y - 4.0), RAPID_STYLE);
    doc.text((x + 36.0, y), 12.0, "start", "legend-text", "rapid");
    x += 90.0;
    let items: [(Mark, &str); 4] = [
        (marks::start, "start"),
        (marks::end, "end"),
        (marks::plunge, "plunge"),
        (marks::drill, "drill"),
    ];
    for (mark, name) in items {
        mark(doc, (x, y - 4.0));
        doc.text((x + 10.0, y), 12.0, "start", "legend-text", name);
        x += 70.0;
    }
    doc.text((16.0, y + 22.0), 12.0, "start", "legend-text", summary);
    doc.close();
}

/// Opens the legend group in the band under the picture framed by `f` and draws its box
/// (the toolpath's and the feed chart's keys look alike); returns the baseline of the first
/// line of text.
pub fn open_box(doc: &mut Doc, f: &Frame) -> f64 {
    let top = f.legend_top();
    doc.open(r#"id="legend""#);
    doc.rect(
        6.0,
        top + 2.0,
        f.width - 12.0,
        super::frame::LEGEND - 8.0,
        r##"class="legend-box" fill="#f7f7f7" stroke="#ccc""##,
    );
    top + 22.0
}
