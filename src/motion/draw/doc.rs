//! SVG document writing: the elements the pictures are made of, in pixel coordinates.

use std::fmt::Write;

/// An SVG document being written.
pub struct Doc {
    out: String,
}

impl Doc {
    /// A document `w` × `h` pixels with a white background and `title`.
    pub fn new(w: f64, h: f64, title: &str) -> Doc {
        let mut out = String::new();
        let _ = writeln!(
            out,
            r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w:.0} {h:.0}" width="{w:.0}" height="{h:.0}" font-family="DejaVu Sans, Arial, sans-serif">"#
        );
        let _ = writeln!(out, "<title>{}</title>", escape(title));
        let _ = writeln!(
            out,
            r#"<rect width="{w:.0}" height="{h:.0}" fill="white"/>"#
        );
        Doc { out }
    }

    /// Appends raw markup.
    pub fn raw(&mut self, s: &str) {
        self.out.push_str(s);
        self.out.push('\n');
    }

    /// Opens a group with these attributes (`id="grid"`, ...).
    pub fn open(&mut self, attrs: &str) {
        let _ = writeln!(self.out, "<g {attrs}>");
    }

    /// Closes the group opened last.
    pub fn close(&mut self) {
        self.out.push_str("</g>\n");
    }

    /// A polyline through `pts` (pixels) with `style` attributes.
    pub fn polyline(&mut self, pts: &[(f64, f64)], style: &str) {
        let _ = write!(self.out, r#"<polyline fill="none" {style} points=""#);
        for (i, (x, y)) in pts.iter().enumerate() {
            let sep = if i == 0 { "" } else { " " };
            let _ = write!(self.out, "{sep}{x:.2},{y:.2}");
        }
        self.out.push_str("\"/>\n");
    }

    /// A straight line.
    pub fn line(&mut self, a: (f64, f64), b: (f64, f64), style: &str) {
        let _ = writeln!(
            self.out,
            r#"<line x1="{:.2}" y1="{:.2}" x2="{:.2}" y2="{:.2}" {style}/>"#,
            a.0, a.1, b.0, b.1
        );
    }

    /// A rectangle.
    pub fn rect(&mut self, x: f64, y: f64, w: f64, h: f64, style: &str) {
        let _ = writeln!(
            self.out,
            r#"<rect x="{x:.2}" y="{y:.2}" width="{w:.2}" height="{h:.2}" {style}/>"#
        );
    }

    /// A circle.
    pub fn circle(&mut self, c: (f64, f64), r: f64, style: &str) {
        let _ = writeln!(
            self.out,
            r#"<circle cx="{:.2}" cy="{:.2}" r="{r:.2}" {style}/>"#,
            c.0, c.1
        );
    }

    /// Text at (x, y) (baseline), `anchor` start, middle or end.
    pub fn text(&mut self, at: (f64, f64), size: f64, anchor: &str, class: &str, text: &str) {
        let _ = writeln!(
            self.out,
            r#"<text class="{class}" x="{:.2}" y="{:.2}" font-size="{size:.1}" text-anchor="{anchor}">{}</text>"#,
            at.0,
            at.1,
            escape(text)
        );
    }

    /// The finished document.
    pub fn finish(mut self) -> String {
        self.out.push_str("</svg>\n");
        self.out
    }
}

/// Escapes text for XML.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}
