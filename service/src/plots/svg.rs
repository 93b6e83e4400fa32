//! The SVG writer every chart draws with: colours, text styles, elements, escaping and the
//! formatting of numbers for the page.

use std::fmt::Write as _;

pub(super) const FONT: &str =
    "system-ui, -apple-system, 'Segoe UI', Roboto, 'Helvetica Neue', Arial, sans-serif";
pub(super) const INK: &str = "#111827";
pub(super) const MUTED: &str = "#4b5563";
pub(super) const GRID: &str = "#e5e7eb";
pub(super) const GRID_MINOR: &str = "#f3f4f6";
pub(super) const AXIS: &str = "#9ca3af";
pub(super) const BLUE: &str = "#2563eb";
pub(super) const BAND: &str = "#bfdbfe";
pub(super) const BAR: &str = "#60a5fa";
pub(super) const RED: &str = "#dc2626";
/// Colours for the lines of one chart, in order; blue first, as everywhere else.
pub(super) const SERIES: [&str; 4] = [BLUE, "#d97706", "#059669", "#7c3aed"];

/// `floor(log10(v))`, robust to `log10(1000) = 2.9999...`.
pub(super) fn log10_floor(v: f64) -> f64 {
    (v.log10() + 1e-12).floor()
}

/// A pixel coordinate: at most two decimals, trailing zeros dropped; 0 if not finite.
pub(super) fn num(v: f64) -> String {
    if !v.is_finite() {
        return "0".to_owned();
    }
    let s = format!("{v:.2}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" || s.is_empty() {
        "0".to_owned()
    } else {
        s.to_owned()
    }
}

/// `digits` significant digits, fixed between 1e-3 and 1e6, exponent form outside.
pub(super) fn fmt_sig(v: f64, digits: usize) -> String {
    if !v.is_finite() {
        return "\u{2013}".to_owned();
    }
    if v == 0.0 {
        return "0".to_owned();
    }
    let e = log10_floor(v.abs());
    if (-3.0..6.0).contains(&e) {
        let decimals = (digits as f64 - 1.0 - e).max(0.0) as usize;
        format!("{v:.decimals$}")
    } else {
        let decimals = digits.saturating_sub(1);
        trim_exponent(&format!("{v:.decimals$e}"))
    }
}

/// Drops a zero exponent (`2.5e0` is `2.5`); `2.50e-4` stays.
pub(super) fn trim_exponent(s: &str) -> String {
    match s.strip_suffix("e0") {
        Some(mantissa) => mantissa.to_owned(),
        None => s.to_owned(),
    }
}

pub(super) fn fmt_percent(pc: f64) -> String {
    if pc >= 1.0 && pc.fract() == 0.0 {
        format!("{pc:.0}")
    } else {
        let s = format!("{pc:.2}");
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    }
}

/// An estimate of the width of `s` in the sans-serif font at `size` px.
pub(super) fn text_width(s: &str, size: f64) -> f64 {
    s.chars().count() as f64 * size * 0.56
}

pub(super) fn truncate(s: &str, max: usize) -> String {
    if s.chars().count() <= max {
        s.to_owned()
    } else {
        let mut t: String = s.chars().take(max.saturating_sub(1)).collect();
        t.push('\u{2026}');
        t
    }
}

/// Greedy word wrap to lines of at most `width` characters (long words are cut).
pub(super) fn wrap(s: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in s.split_whitespace() {
        let word = truncate(word, width);
        if !line.is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(&word);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines.truncate(4);
    lines
}

/// Characters a plot leaves out of its text: controls, the two non-characters XML forbids (a
/// name holding U+FFFF made a plot no parser reads, found from outside), and bidirectional
/// embeddings, overrides and isolates (a schedule named with U+202E drew its trend's title
/// backwards, found from outside).
fn unwritten(c: char) -> bool {
    c.is_control()
        || matches!(c, '\u{fffe}' | '\u{ffff}')
        || matches!(c, '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}')
}

/// Escapes text and attribute values.
pub(super) fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c if unwritten(c) => {}
            c => out.push(c),
        }
    }
    out
}

#[derive(Clone, Copy)]
pub(super) struct Style {
    pub(super) size: f64,
    pub(super) anchor: &'static str,
    pub(super) bold: bool,
    pub(super) fill: &'static str,
    pub(super) rotate: f64,
}

pub(super) const LABEL: Style = Style {
    size: 12.0,
    anchor: "middle",
    bold: false,
    fill: INK,
    rotate: 0.0,
};
pub(super) const SMALL: Style = Style {
    size: 11.0,
    fill: MUTED,
    ..LABEL
};
pub(super) const MUTED_SMALL: Style = Style {
    anchor: "start",
    ..SMALL
};

pub(super) struct Svg {
    pub(super) out: String,
    width: f64,
}

impl Svg {
    pub(super) fn new(width: f64, height: f64, title: &str) -> Self {
        let mut out = String::with_capacity(16 * 1024);
        let (w, h) = (num(width), num(height));
        let _ = writeln!(
            out,
            r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" height="{h}" font-family="{FONT}" font-size="12" role="img" aria-label="{}">"#,
            esc(title)
        );
        let _ = writeln!(out, "<title>{}</title>", esc(title));
        let _ = writeln!(
            out,
            r##"<rect x="0" y="0" width="{w}" height="{h}" fill="#ffffff"/>"##
        );
        Svg { out, width }
    }

    /// The plot's title, cut with an ellipsis to the plot's width (a schedule's name of 200
    /// characters ran off its trend); the whole title is the document's `<title>`.
    pub(super) fn title(&mut self, text: &str, x: f64, y: f64) {
        const SIZE: f64 = 13.0;
        let room = ((self.width - x - 8.0) / text_width("m", SIZE)).max(1.0) as usize;
        self.text(
            x,
            y,
            &truncate(text, room),
            Style {
                size: SIZE,
                anchor: "start",
                bold: true,
                ..LABEL
            },
        );
    }

    /// A y axis's title, written upwards, centred on (`x`, `y`).
    pub(super) fn y_label(&mut self, x: f64, y: f64, text: &str) {
        self.text(
            x,
            y,
            text,
            Style {
                rotate: -90.0,
                ..LABEL
            },
        );
    }

    pub(super) fn text(&mut self, x: f64, y: f64, text: &str, style: Style) {
        let weight = if style.bold {
            r#" font-weight="600""#
        } else {
            ""
        };
        let transform = if style.rotate != 0.0 {
            format!(
                r#" transform="rotate({} {} {})""#,
                num(style.rotate),
                num(x),
                num(y)
            )
        } else {
            String::new()
        };
        let _ = writeln!(
            self.out,
            r#"<text x="{}" y="{}" font-size="{}" text-anchor="{}" fill="{}"{weight}{transform}>{}</text>"#,
            num(x),
            num(y),
            num(style.size),
            style.anchor,
            style.fill,
            esc(text)
        );
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn line(
        &mut self,
        x1: f64,
        y1: f64,
        x2: f64,
        y2: f64,
        color: &str,
        w: f64,
        dash: Option<&str>,
    ) {
        let dash = dash
            .map(|d| format!(r#" stroke-dasharray="{d}""#))
            .unwrap_or_default();
        let _ = writeln!(
            self.out,
            r#"<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="{color}" stroke-width="{}"{dash}/>"#,
            num(x1),
            num(y1),
            num(x2),
            num(y2),
            num(w)
        );
    }

    pub(super) fn rect(
        &mut self,
        x: f64,
        y: f64,
        w: f64,
        h: f64,
        fill: &str,
        stroke: Option<&str>,
    ) {
        let stroke = stroke
            .map(|s| format!(r#" stroke="{s}""#))
            .unwrap_or_default();
        let _ = writeln!(
            self.out,
            r#"<rect x="{}" y="{}" width="{}" height="{}" fill="{fill}"{stroke}/>"#,
            num(x),
            num(y),
            num(w.max(0.0)),
            num(h.max(0.0))
        );
    }

    pub(super) fn circle(&mut self, x: f64, y: f64, r: f64, fill: &str, stroke: &str, w: f64) {
        let _ = writeln!(
            self.out,
            r#"<circle cx="{}" cy="{}" r="{}" fill="{fill}" stroke="{stroke}" stroke-width="{}"/>"#,
            num(x),
            num(y),
            num(r),
            num(w)
        );
    }

    pub(super) fn polyline(&mut self, pts: &[(f64, f64)], color: &str, w: f64, dash: Option<&str>) {
        if pts.len() < 2 {
            return;
        }
        let dash = dash
            .map(|d| format!(r#" stroke-dasharray="{d}""#))
            .unwrap_or_default();
        let _ = writeln!(
            self.out,
            r#"<polyline points="{}" fill="none" stroke="{color}" stroke-width="{}" stroke-linejoin="round"{dash}/>"#,
            points(pts),
            num(w)
        );
    }

    pub(super) fn raw(&mut self, s: &str) {
        self.out.push_str(s);
        self.out.push('\n');
    }

    pub(super) fn open_g(&mut self, attrs: &str) {
        let _ = writeln!(self.out, "<g {attrs}>");
    }

    pub(super) fn close_g(&mut self) {
        self.out.push_str("</g>\n");
    }

    pub(super) fn finish(mut self) -> String {
        self.out.push_str("</svg>\n");
        self.out
    }
}

pub(super) fn points(pts: &[(f64, f64)]) -> String {
    let mut s = String::with_capacity(pts.len() * 14);
    for (k, &(x, y)) in pts.iter().enumerate() {
        if k > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{},{}", num(x), num(y));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_short() {
        assert_eq!(fmt_sig(1234.5, 3), "1234");
        assert_eq!(fmt_sig(2.345, 3), "2.35");
        assert_eq!(num(-0.001), "0");
    }

    #[test]
    fn text_is_escaped_to_what_xml_allows() {
        assert_eq!(
            esc("a\u{ffff}b\u{fffe}<&>\"'\u{7}\u{fffd}"),
            "ab&lt;&amp;&gt;&quot;&#39;\u{fffd}"
        );
        assert_eq!(
            esc("Nightly \u{202e}RTL\u{2066}x\u{2069}\u{200f}"),
            "Nightly RTLx\u{200f}"
        );
    }
}
