//! A schedule's night-by-night trend of one value.

use super::axes::{Frame, Legend, LinearAxis, Scale, draw_frame_axes, draw_y_grid};
use super::svg::{AXIS, BLUE, LABEL, MUTED, RED, SMALL, Style, Svg, text_width, truncate};
use super::{extent, finite, message_svg, pad, segments};

/// One night of a schedule's trend.
#[derive(Debug, Clone, PartialEq)]
pub struct TrendPoint {
    /// The x label (a date or run name).
    pub label: String,
    pub value: f64,
    /// 95 % interval, drawn as an error bar.
    pub ci95: Option<[f64; 2]>,
    /// Drawn in red with a ring.
    pub flagged: bool,
}

/// A night-by-night trend: points with 95 % error bars joined by a line, flagged points in red
/// with a ring; x labels rotated and thinned when there are many, `x_label` under them.
pub fn trend_svg(title: &str, x_label: &str, y_label: &str, points: &[TrendPoint]) -> String {
    if points.is_empty() {
        return message_svg(title, "No run has a value yet.");
    }
    let n = points.len();
    let rotate = n > 8 || points.iter().any(|p| p.label.chars().count() > 12);
    let longest = points
        .iter()
        .map(|p| text_width(&truncate(&p.label, 24), 11.0))
        .fold(0.0, f64::max);
    let bottom = if rotate { 46.0 + longest * 0.71 } else { 58.0 };
    let (width, height) = (760.0, 300.0 + bottom);
    // Rotated labels hang down to the left of their point: room for the first one.
    let left = if rotate {
        let first_slot = (width - 78.0 - 24.0) / n as f64 / 2.0;
        (longest * 0.71 - first_slot + 8.0).clamp(78.0, 200.0)
    } else {
        78.0
    };
    let frame = Frame::inset(0.0, 0.0, width, height, [left, 62.0, 24.0, bottom]);
    let values = points.iter().flat_map(|p| {
        let [a, b] = p.ci95.unwrap_or([p.value, p.value]);
        [p.value, a, b]
    });
    let (lo, hi) = extent(values.filter(|v| v.is_finite()));
    let (lo, hi) = pad(lo, hi, 0.05);
    let y_axis = LinearAxis::new(lo, hi, 6, false);
    let ys = Scale::new(y_axis.lo, y_axis.hi, frame.bottom(), frame.top);
    // Categorical x: slot k at its centre.
    let slot = frame.width / n as f64;
    let x_of = |k: usize| frame.left + slot * (k as f64 + 0.5);

    let mut svg = Svg::new(width, height, title);
    svg.title(title, 16.0, 24.0);
    draw_y_grid(&mut svg, &frame, &y_axis, &ys);

    draw_x_labels(&mut svg, &frame, points, (slot, longest), rotate);
    draw_error_bars(&mut svg, points, &ys, slot, x_of);
    let line: Vec<Option<(f64, f64)>> = points
        .iter()
        .enumerate()
        .map(|(k, p)| finite(p.value).map(|v| (x_of(k), ys.map(v))))
        .collect();
    for segment in segments(&line) {
        svg.polyline(&segment, BLUE, 1.8, None);
    }
    for (k, p) in points.iter().enumerate() {
        let Some(v) = finite(p.value) else { continue };
        let (x, y) = (x_of(k), ys.map(v));
        if p.flagged {
            svg.circle(x, y, 8.0, "none", RED, 1.8);
            svg.circle(x, y, 4.0, RED, "#ffffff", 1.0);
        } else {
            svg.circle(x, y, 3.5, BLUE, "#ffffff", 1.0);
        }
    }
    draw_frame_axes(&mut svg, &frame);
    svg.text(
        frame.left + frame.width / 2.0,
        height - 10.0,
        x_label,
        LABEL,
    );
    svg.y_label(18.0, frame.top + frame.height / 2.0, y_label);
    let mut legend = Legend::new(frame.left, 46.0);
    legend.dot(&mut svg, BLUE, "value");
    if points.iter().any(|p| p.ci95.is_some()) {
        legend.line(&mut svg, MUTED, None, "95 % interval");
    }
    if points.iter().any(|p| p.flagged) {
        legend.ring(&mut svg, RED, "flagged");
    }
    svg.finish()
}

/// The nights' ticks and labels, thinned to about one per 22 px (rotated) or per label width
/// (flat), counted from the last night; `slot` is a night's width and `longest` the widest label.
fn draw_x_labels(
    svg: &mut Svg,
    frame: &Frame,
    points: &[TrendPoint],
    (slot, longest): (f64, f64),
    rotate: bool,
) {
    let n = points.len();
    let per_label = if rotate { 22.0 } else { longest + 10.0 };
    let every = ((per_label / slot.max(1e-9)).ceil() as usize).max(1);
    for (k, p) in points.iter().enumerate() {
        let x = frame.left + slot * (k as f64 + 0.5);
        svg.line(x, frame.bottom(), x, frame.bottom() + 4.0, AXIS, 1.0, None);
        if !(n - 1 - k).is_multiple_of(every) {
            continue;
        }
        let label = truncate(&p.label, 24);
        if rotate {
            svg.text(
                x + 3.0,
                frame.bottom() + 12.0,
                &label,
                Style {
                    anchor: "end",
                    rotate: -45.0,
                    ..SMALL
                },
            );
        } else {
            svg.text(x, frame.bottom() + 18.0, &label, SMALL);
        }
    }
}

/// Each night's 95 % interval as a capped bar, red when flagged.
fn draw_error_bars(
    svg: &mut Svg,
    points: &[TrendPoint],
    ys: &Scale,
    slot: f64,
    x_of: impl Fn(usize) -> f64,
) {
    let cap = (slot * 0.2).clamp(2.0, 6.0);
    for (k, p) in points.iter().enumerate() {
        if let Some([a, b]) = p.ci95
            && a.is_finite()
            && b.is_finite()
        {
            let x = x_of(k);
            let color = if p.flagged { RED } else { MUTED };
            let (ya, yb) = (ys.map(a), ys.map(b));
            svg.line(x, ya, x, yb, color, 1.2, None);
            svg.line(x - cap, ya, x + cap, ya, color, 1.2, None);
            svg.line(x - cap, yb, x + cap, yb, color, 1.2, None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plots::fixtures::check;

    fn night(k: usize, value: f64, flagged: bool) -> TrendPoint {
        TrendPoint {
            label: format!("2026-03-{:02}", k + 1),
            value,
            ci95: Some([value * 0.95, value * 1.05]),
            flagged,
        }
    }

    #[test]
    fn trend_of_a_few_nights() {
        let points: Vec<TrendPoint> = (0..5)
            .map(|k| night(k, 0.009 + 0.0001 * k as f64, k == 3))
            .collect();
        let svg = trend_svg(
            "Nightly <wear> & \"drift\"",
            "run",
            "p95 total_bounce_s",
            &points,
        );
        check(&svg);
        assert!(svg.contains("Nightly &lt;wear&gt; &amp; &quot;drift&quot;"));
        assert!(svg.contains("2026-03-01"));
        assert!(svg.contains("2026-03-05"));
        assert!(svg.contains(">flagged<"));
        assert!(svg.contains(&format!("stroke=\"{RED}\"")));
        assert!(!svg.contains("rotate(-45"));
    }

    /// A name of 200 characters without a space is cut to the plot's width, with an ellipsis;
    /// the document's `<title>` keeps it whole.
    #[test]
    fn a_long_title_is_cut_to_the_plots_width() {
        let name = "W".repeat(200);
        let svg = trend_svg(&name, "run", "p95 total_bounce_s", &[night(0, 0.01, false)]);
        check(&svg);
        assert!(svg.contains(&format!("<title>{name}</title>")));
        let shown = svg
            .split('>')
            .find_map(|part| part.strip_suffix("\u{2026}</text"))
            .expect("the title cut with an ellipsis");
        let width = svg
            .split("width=\"")
            .nth(1)
            .and_then(|rest| rest.split('"').next())
            .and_then(|w| w.parse::<f64>().ok())
            .expect("the plot's width");
        let room = crate::plots::svg::text_width(&format!("{shown}\u{2026}"), 13.0);
        assert!(
            shown.len() > 20 && room < width,
            "{} characters in {width} px",
            shown.len()
        );
    }

    #[test]
    fn trend_of_many_nights_rotates_and_thins() {
        let points: Vec<TrendPoint> = (0..120)
            .map(|k| night(k % 28, 1.0 + (k as f64 * 0.3).sin(), k % 17 == 0))
            .collect();
        let svg = trend_svg("Nightly", "run", "mean e1", &points);
        check(&svg);
        assert!(svg.contains("rotate(-45"));
        let labels = svg.matches("rotate(-45").count();
        assert!(labels < 60, "{labels} labels");
    }

    #[test]
    fn trend_of_degenerate_points() {
        check(&trend_svg("Empty", "run", "x", &[]));
        assert!(trend_svg("Empty", "run", "x", &[]).contains("No run has a value yet"));
        let flat: Vec<TrendPoint> = (0..3)
            .map(|_| TrendPoint {
                label: String::new(),
                value: 0.0,
                ci95: None,
                flagged: false,
            })
            .collect();
        check(&trend_svg("Flat", "run", "x", &flat));
        let odd = vec![
            TrendPoint {
                label: "a".into(),
                value: f64::NAN,
                ci95: Some([f64::NEG_INFINITY, 1.0]),
                flagged: true,
            },
            TrendPoint {
                label: "b".into(),
                value: 5.0,
                ci95: Some([5.0, 5.0]),
                flagged: false,
            },
            TrendPoint {
                label: "a very long label that goes on and on".into(),
                value: -1e-12,
                ci95: None,
                flagged: true,
            },
        ];
        check(&trend_svg("Odd", "run", "x", &odd));
        let one = vec![night(0, 3.0, false)];
        check(&trend_svg("One", "run", "x", &one));
    }
}
