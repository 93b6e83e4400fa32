//! Small multiples: the distribution of an operation metric in each bin of operations.

use std::fmt::Write as _;

use bouncewear_model::montecarlo::Bin;
use bouncewear_model::stats::Summary;

use super::axes::{Frame, LinearAxis, Scale, draw_frame_axes, draw_x_ticks, draw_y_grid};
use super::svg::{BAR, BLUE, INK, LABEL, MUTED_SMALL, RED, Style, Svg, fmt_sig, num, text_width};
use super::{limit_of, message_svg, pad, pick_evenly, quantile, whole_valued};

/// Panels of a grid are this large.
const PANEL: (f64, f64) = (250.0, 178.0);
/// Margins around the grid: left, top, bottom, right.
const OUTER: [f64; 4] = [34.0, 66.0, 44.0, 12.0];

/// Small multiples of the histogram of `metric` in each bin of operations (at most 12 panels,
/// evenly spaced over the bins when there are more, as the title says), on a shared x axis. Each
/// panel marks the median and, when the metric has a limit, the limit. The panels share their y
/// scale too, so that a taller bar is a larger count in any panel.
pub fn histograms_svg(metric: &str, bins: &[Bin]) -> String {
    const MAX_PANELS: usize = 12;
    let chosen = pick_evenly(bins.len(), MAX_PANELS);
    let title = if chosen.len() < bins.len() {
        format!(
            "{metric}: distribution per bin of operations ({} of {} bins, evenly spaced)",
            chosen.len(),
            bins.len()
        )
    } else {
        format!("{metric}: distribution per bin of operations")
    };
    if chosen.is_empty() {
        return message_svg(&title, "No bins of operations to plot.");
    }
    let chosen: Vec<&Bin> = chosen.into_iter().map(|i| &bins[i]).collect();

    let n = chosen.len();
    let cols = ((n as f64).sqrt().ceil() as usize).clamp(1, 4);
    let rows = n.div_ceil(cols);
    let [outer_left, outer_top, outer_bottom, outer_right] = OUTER;
    let width = outer_left + PANEL.0 * cols as f64 + outer_right;
    let height = outer_top + PANEL.1 * rows as f64 + outer_bottom;
    let axes = shared_axes(metric, &chosen);

    let mut svg = Svg::new(width, height, &title);
    svg.title(&title, 12.0, 22.0);
    let mut subtitle =
        String::from("Bars: counts of operations in equal-width classes; dark line: median (p50)");
    if chosen.iter().any(|bin| limit_of(&bin.summary).is_some()) {
        subtitle.push_str("; red dashed: limit");
    }
    svg.text(12.0, 42.0, &subtitle, MUTED_SMALL);
    for (k, bin) in chosen.iter().enumerate() {
        let (col, row) = (k % cols, k / cols);
        let px = outer_left + PANEL.0 * col as f64;
        let py = outer_top + PANEL.1 * row as f64;
        draw_panel(&mut svg, &axes, (px, py), bin);
    }

    // Shared axis labels.
    svg.text(
        outer_left + PANEL.0 * cols as f64 / 2.0,
        height - 12.0,
        metric,
        LABEL,
    );
    svg.y_label(14.0, outer_top + PANEL.1 * rows as f64 / 2.0, "count");
    svg.finish()
}

/// The axes every panel shares: across, every class edge and limit; up, the largest count.
fn shared_axes(metric: &str, chosen: &[&Bin]) -> [LinearAxis; 2] {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for bin in chosen {
        let s = &bin.summary;
        for &e in s.histogram.edges.iter().chain(limit_of(s).iter()) {
            if e.is_finite() {
                lo = lo.min(e);
                hi = hi.max(e);
            }
        }
    }
    let (lo, hi) = pad(lo, hi, 0.04);
    let x_axis = LinearAxis::new(lo, hi, 4, whole_valued(metric));
    let max_count = chosen
        .iter()
        .flat_map(|bin| class_counts(&bin.summary).iter().copied())
        .max()
        .unwrap_or(0)
        .max(1);
    let y_axis = LinearAxis::new(0.0, max_count as f64, 3, true);
    [x_axis, y_axis]
}

/// One bin's panel with its top left corner at `(px, py)`: its heading and count, the bars, the
/// median and the limit.
/// A panel's heading and its count, shortened until both fit on one line of `room` pixels with a
/// gap between them: `operations a-b` then `ops a-b`, `n = 12345` then `n = 12.3k`.
fn panel_labels(bin: &Bin, room: f64) -> (String, String) {
    let heading = super::operation_range(bin.op_start, bin.op_end);
    let short = heading.replacen("operations", "ops", 1);
    let headings = [heading, short];
    let counts = [
        format!("n = {}", bin.summary.n),
        format!("n = {}", fmt_count(bin.summary.n)),
    ];
    // Bold text runs about 8 % wider than the estimate of `text_width`.
    let fits = |h: &str, c: &str| text_width(h, 12.0) * 1.08 + 10.0 + text_width(c, 11.0) <= room;
    for count in &counts {
        for heading in &headings {
            if fits(heading, count) {
                return (heading.clone(), count.clone());
            }
        }
    }
    (headings[1].clone(), counts[1].clone())
}

/// `n` in at most four significant digits with a k, M or G suffix from 10,000 up.
fn fmt_count(n: u64) -> String {
    let v = n as f64;
    match v {
        v if v < 1e4 => n.to_string(),
        v if v < 1e6 => format!("{}k", fmt_sig(v / 1e3, 3)),
        v if v < 1e9 => format!("{}M", fmt_sig(v / 1e6, 3)),
        v => format!("{}G", fmt_sig(v / 1e9, 3)),
    }
}

fn draw_panel(svg: &mut Svg, [x_axis, y_axis]: &[LinearAxis; 2], (px, py): (f64, f64), bin: &Bin) {
    let s = &bin.summary;
    let frame = Frame::inset(px, py, PANEL.0, PANEL.1, [44.0, 24.0, 12.0, 32.0]);
    svg.open_g(&format!(
        r#"class="panel" data-op-start="{}" data-op-end="{}""#,
        bin.op_start, bin.op_end
    ));
    let (heading, count) = panel_labels(bin, frame.right() - (px + 8.0));
    svg.text(
        px + 8.0,
        py + 14.0,
        &heading,
        Style {
            anchor: "start",
            bold: true,
            ..LABEL
        },
    );
    svg.text(
        frame.right(),
        py + 14.0,
        &count,
        Style {
            anchor: "end",
            ..MUTED_SMALL
        },
    );
    let xs = Scale::new(x_axis.lo, x_axis.hi, frame.left, frame.right());
    let ys = Scale::new(y_axis.lo, y_axis.hi, frame.bottom(), frame.top);
    draw_y_grid(svg, &frame, y_axis, &ys);
    draw_x_ticks(svg, &frame, x_axis, &xs, false);
    draw_bars(svg, &frame, (&xs, &ys), s);
    if s.n == 0 {
        svg.text(
            frame.left + frame.width / 2.0,
            frame.top + frame.height / 2.0,
            "no values",
            MUTED_SMALL,
        );
    }
    if s.n > 0
        && let Some(p50) = quantile(s, "p50")
    {
        let x = xs.map(p50);
        svg.line(x, frame.top, x, frame.bottom(), INK, 1.5, None);
    }
    if let Some(limit) = limit_of(s) {
        let x = xs.map(limit);
        svg.line(x, frame.top, x, frame.bottom(), RED, 1.5, Some("5 3"));
    }
    draw_frame_axes(svg, &frame);
    svg.close_g();
}

/// A bar for each class with values, one element group for all of them.
fn draw_bars(svg: &mut Svg, frame: &Frame, (xs, ys): (&Scale, &Scale), s: &Summary) {
    let mut bars = String::new();
    for b in 0..class_counts(s).len() {
        let c = s.histogram.counts[b];
        let (e0, e1) = (s.histogram.edges[b], s.histogram.edges[b + 1]);
        if c == 0 || !e0.is_finite() || !e1.is_finite() {
            continue;
        }
        let (mut x0, mut x1) = (xs.map(e0.min(e1)), xs.map(e0.max(e1)));
        if x1 - x0 < 3.0 {
            // A class of (almost) zero width, as when every value is equal: a narrow bar
            // centred on it.
            let mid = (x0 + x1) / 2.0;
            x0 = mid - 3.0;
            x1 = mid + 3.0;
        }
        let y = ys.map(c as f64);
        let _ = write!(
            bars,
            r#"<rect x="{}" y="{}" width="{}" height="{}" fill="{BAR}" stroke="{BLUE}" stroke-width="0.5"/>"#,
            num(x0),
            num(y),
            num(x1 - x0),
            num(frame.bottom() - y)
        );
    }
    if !bars.is_empty() {
        svg.raw(&bars);
    }
}

/// The counts of a histogram's classes: as many as it has edges for.
fn class_counts(s: &Summary) -> &[u64] {
    let h = &s.histogram;
    &h.counts[..h.counts.len().min(h.edges.len().saturating_sub(1))]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plots::fixtures::{
        bounce_count_bins, check, fractional_labels, summary, uniform, wear_bins,
    };
    use bouncewear_model::stats::Histogram;

    #[test]
    fn histograms_of_a_wear_test() {
        let bins = wear_bins(10, 100, Some(0.0095));
        let svg = histograms_svg("total_bounce_s", &bins);
        check(&svg);
        assert!(svg.contains("total_bounce_s: distribution per bin of operations"));
        assert!(svg.contains("operations 0\u{2013}99"));
        assert!(svg.contains("operations 900\u{2013}999"));
        assert_eq!(svg.matches("class=\"panel\"").count(), 10);
        assert!(svg.contains("limit"));
        assert!(svg.contains(">count<"));
    }

    #[test]
    fn histograms_pick_twelve_of_many_bins() {
        let bins = wear_bins(40, 25, None);
        let svg = histograms_svg("e1", &bins);
        check(&svg);
        assert_eq!(svg.matches("class=\"panel\"").count(), 12);
        assert!(svg.contains("12 of 40 bins, evenly spaced"));
        assert!(svg.contains("operations 0\u{2013}24"));
        assert!(svg.contains("operations 975\u{2013}999"));
        assert_eq!(pick_evenly(40, 12).len(), 12);
        let v = pick_evenly(13, 12);
        assert_eq!((v.len(), v[0], v[11]), (12, 0, 12));
    }

    fn bin(values: &[f64], op_start: u64) -> Bin {
        Bin {
            summary: summary(values, None),
            op_start,
            op_end: op_start + 1,
        }
    }

    /// The height of the tallest bar of each panel.
    fn tallest_bars(svg: &str) -> Vec<f64> {
        let bar = format!(r#"fill="{BAR}""#);
        svg.split(r#"<g class="panel""#)
            .skip(1)
            .map(|panel| {
                panel[..panel.find("</g>").unwrap()]
                    .split("<rect ")
                    .filter(|rect| rect.contains(&bar))
                    .map(|rect| {
                        let height = &rect[rect.find("height=\"").unwrap() + 8..];
                        height[..height.find('"').unwrap()].parse::<f64>().unwrap()
                    })
                    .fold(0.0, f64::max)
            })
            .collect()
    }

    #[test]
    fn histogram_panels_share_one_count_scale() {
        let few: Vec<f64> = (0..50).map(|k| uniform(3, k)).collect();
        let many: Vec<f64> = few.iter().cycle().take(200).copied().collect();
        let svg = histograms_svg("e1", &[bin(&few, 0), bin(&many, 1)]);
        check(&svg);
        let tallest = tallest_bars(&svg);
        // Four times the operations in the same classes: bars four times as tall.
        assert!((tallest[1] / tallest[0] - 4.0).abs() < 0.05, "{tallest:?}");
    }

    #[test]
    fn a_whole_valued_metric_gets_whole_ticks() {
        let svg = histograms_svg("bounce_count", &bounce_count_bins(4));
        check(&svg);
        assert!(svg.contains(">2</text>"));
        assert_eq!(fractional_labels(&svg), Vec::<&str>::new());
    }

    #[test]
    fn histograms_of_degenerate_bins() {
        check(&histograms_svg("kappa", &[]));
        assert!(histograms_svg("kappa", &[]).contains("No bins"));
        let equal = Bin {
            summary: summary(&[0.5; 10], None),
            op_start: 0,
            op_end: 1,
        };
        let empty = Bin {
            summary: summary(&[], None),
            op_start: 1,
            op_end: 2,
        };
        let zero = Bin {
            summary: summary(&[0.0; 3], Some(0.0)),
            op_start: 2,
            op_end: 3,
        };
        let mut broken = summary(&[1.0, 2.0], None);
        broken.histogram = Histogram {
            edges: vec![f64::NAN],
            counts: vec![3, 4],
        };
        broken.quantiles.clear();
        let broken = Bin {
            summary: broken,
            op_start: 3,
            op_end: 4,
        };
        for bins in [
            vec![equal.clone()],
            vec![empty.clone()],
            vec![zero.clone()],
            vec![broken.clone()],
            vec![equal, empty, zero, broken],
        ] {
            check(&histograms_svg("bounce_count", &bins));
        }
    }

    #[test]
    fn panel_labels_never_collide() {
        let bin = |start: u64, end: u64, n: u64| {
            let mut b = wear_bins(1, 1, None).remove(0);
            (b.op_start, b.op_end, b.summary.n) = (start, end, n);
            b
        };
        let room = PANEL.0 - 12.0 - 8.0;
        assert_eq!(
            panel_labels(&bin(0, 20, 2000), room),
            ("operations 0\u{2013}19".to_owned(), "n = 2000".to_owned())
        );
        let (heading, count) = panel_labels(&bin(100_000, 200_000, 2_000_000), room);
        assert!(heading.starts_with("ops "), "{heading}");
        assert!(
            text_width(&heading, 12.0) * 1.08 + 10.0 + text_width(&count, 11.0) <= room,
            "{heading} / {count}"
        );
        assert_eq!(fmt_count(12_345), "12.3k");
        assert_eq!(fmt_count(2_000_000), "2.00M");
    }
}
