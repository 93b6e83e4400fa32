//! The wear curve: an operation metric's quantile band, median and mean across the test.

use std::fmt::Write as _;

use bouncewear_model::montecarlo::Bin;

use super::axes::{Frame, Legend, LinearAxis, Scale, draw_frame_axes, draw_x_ticks, draw_y_grid};
use super::svg::{BAND, BLUE, INK, LABEL, RED, SERIES, SMALL, Style, Svg, fmt_sig, num, points};
use super::{extent, finite, limit_of, message_svg, pad, quantile, whole_valued};

/// One bin of operations as the curve draws it: at its midpoint.
struct Row {
    x: f64,
    p05: Option<f64>,
    p50: Option<f64>,
    p95: Option<f64>,
    mean: Option<f64>,
}

/// One design's bins of an operation metric, and its name in a comparison's legend.
pub struct Design<'a> {
    pub name: &'a str,
    pub bins: &'a [Bin],
}

/// The wear curve of `metric`: per bin of operations (at the bin's midpoint), a band from p05 to
/// p95, the median, the mean (dashed) and the limit when there is one, with a legend.
pub fn quantile_bands_svg(metric: &str, bins: &[Bin]) -> String {
    bands_svg(
        &format!("{metric}: wear curve over the test"),
        metric,
        &[Design { name: "", bins }],
    )
}

/// The wear curves of several designs on one plot, each in its colour: a translucent p05-p95
/// band, the median and the mean (dashed); the first design's limit when there is one.
pub fn compared_bands_svg(metric: &str, designs: &[Design]) -> String {
    bands_svg(&format!("{metric}: wear curves compared"), metric, designs)
}

/// What one design draws in: one design alone keeps the plain look (a pale band, a blue median,
/// a black mean); several take a colour each.
struct Look {
    band: &'static str,
    band_opacity: f64,
    median: &'static str,
    mean: &'static str,
}

fn look(index: usize, alone: bool) -> Look {
    if alone {
        return Look {
            band: BAND,
            band_opacity: 1.0,
            median: BLUE,
            mean: INK,
        };
    }
    let colour = SERIES[index % SERIES.len()];
    Look {
        band: colour,
        band_opacity: 0.14,
        median: colour,
        mean: colour,
    }
}

fn bands_svg(title: &str, metric: &str, designs: &[Design]) -> String {
    let rows: Vec<Vec<Row>> = designs.iter().map(|d| rows_of(d.bins)).collect();
    if rows.iter().all(Vec::is_empty) {
        return message_svg(title, "No operations to plot.");
    }
    let limit = designs
        .iter()
        .flat_map(|d| d.bins)
        .find_map(|b| limit_of(&b.summary));

    // Several designs: a legend row each, above the plot.
    let extra = if designs.len() == 1 {
        0.0
    } else {
        18.0 * designs.len() as f64
    };
    let (width, height) = (760.0, 420.0 + extra);
    let frame = Frame::inset(0.0, 0.0, width, height, [78.0, 70.0 + extra, 24.0, 56.0]);
    let bins = designs.iter().flat_map(|d| d.bins);
    let x_lo = bins
        .clone()
        .map(|b| b.op_start as f64)
        .fold(f64::INFINITY, f64::min);
    let x_hi = bins
        .map(|b| b.op_end as f64)
        .fold(f64::NEG_INFINITY, f64::max);
    let x_axis = LinearAxis::new(x_lo, x_hi, 8, true);
    let ys_values = rows
        .iter()
        .flatten()
        .flat_map(|r| [r.p05, r.p50, r.p95, r.mean])
        .chain([limit])
        .flatten();
    let (y_lo, y_hi) = extent(ys_values);
    let (y_lo, y_hi) = pad(y_lo, y_hi, 0.05);
    let y_axis = LinearAxis::new(y_lo, y_hi, 6, whole_valued(metric));
    let xs = Scale::new(x_axis.lo, x_axis.hi, frame.left, frame.right());
    let ys = Scale::new(y_axis.lo, y_axis.hi, frame.bottom(), frame.top);

    let mut svg = Svg::new(width, height, title);
    svg.title(title, 16.0, 24.0);
    draw_y_grid(&mut svg, &frame, &y_axis, &ys);
    draw_x_ticks(&mut svg, &frame, &x_axis, &xs, false);
    let alone = designs.len() == 1;
    for (i, rows) in rows.iter().enumerate() {
        draw_band(&mut svg, rows, &xs, &ys, &look(i, alone));
    }
    if let Some(limit) = limit {
        draw_limit(&mut svg, &frame, ys.map(limit), limit);
    }
    for (i, rows) in rows.iter().enumerate() {
        let look = look(i, alone);
        let median: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| Some((xs.map(r.x), ys.map(r.p50?))))
            .collect();
        let mean: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| Some((xs.map(r.x), ys.map(r.mean?))))
            .collect();
        svg.polyline(&mean, look.mean, 1.5, Some("6 4"));
        svg.polyline(&median, look.median, 2.2, None);
        if median.len() <= 40 {
            for &(x, y) in &median {
                svg.circle(x, y, 3.0, look.median, "#ffffff", 1.2);
            }
        }
    }
    draw_frame_axes(&mut svg, &frame);
    svg.text(
        frame.left + frame.width / 2.0,
        height - 14.0,
        "operation",
        LABEL,
    );
    svg.y_label(18.0, frame.top + frame.height / 2.0, metric);

    let mut legend = Legend::new(frame.left, 48.0);
    if alone {
        legend.swatch(&mut svg, BAND, "p05\u{2013}p95 (90 % of operations)");
        legend.line(&mut svg, BLUE, None, "median (p50)");
        legend.line(&mut svg, INK, Some("6 4"), "mean");
    } else {
        legend.line(&mut svg, INK, None, "median (p50)");
        legend.line(&mut svg, INK, Some("6 4"), "mean; bands p05\u{2013}p95");
    }
    if limit.is_some() {
        legend.line(&mut svg, RED, Some("6 4"), "limit");
    }
    if !alone {
        for (i, design) in designs.iter().enumerate() {
            let mut row = Legend::new(frame.left, 48.0 + 18.0 * (i + 1) as f64);
            row.swatch(&mut svg, SERIES[i % SERIES.len()], design.name);
        }
    }
    svg.finish()
}

/// Each bin with operations, at its midpoint.
fn rows_of(bins: &[Bin]) -> Vec<Row> {
    bins.iter()
        .filter(|b| b.summary.n > 0)
        .map(|b| Row {
            x: (b.op_start as f64 + b.op_end as f64) / 2.0,
            p05: quantile(&b.summary, "p05"),
            p50: quantile(&b.summary, "p50"),
            p95: quantile(&b.summary, "p95"),
            mean: finite(b.summary.mean),
        })
        .filter(|r| r.x.is_finite())
        .collect()
}

/// The band: p95 forwards, p05 backwards, over the bins that have both; one bin's is a bar.
fn draw_band(svg: &mut Svg, rows: &[Row], xs: &Scale, ys: &Scale, look: &Look) {
    let band: Vec<(f64, f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((xs.map(r.x), ys.map(r.p05?), ys.map(r.p95?))))
        .collect();
    let (fill, opacity) = (look.band, look.band_opacity);
    match band.len() {
        0 => {}
        1 => {
            let (x, y05, y95) = band[0];
            let _ = write!(
                svg.out,
                r#"<rect x="{}" y="{}" width="12" height="{}" fill="{fill}" fill-opacity="{opacity}"/>"#,
                num(x - 6.0),
                num(y95.min(y05)),
                num((y05 - y95).abs().max(1.0)),
            );
            svg.out.push('\n');
        }
        _ => {
            let mut pts: Vec<(f64, f64)> = band.iter().map(|&(x, _, y95)| (x, y95)).collect();
            pts.extend(band.iter().rev().map(|&(x, y05, _)| (x, y05)));
            let _ = write!(
                svg.out,
                r#"<polygon points="{}" fill="{fill}" fill-opacity="{opacity}" stroke="{fill}" stroke-opacity="{opacity}" stroke-width="1"/>"#,
                points(&pts)
            );
            svg.out.push('\n');
        }
    }
}

/// The limit across the frame at height `y`, labelled with its value.
fn draw_limit(svg: &mut Svg, frame: &Frame, y: f64, limit: f64) {
    svg.line(frame.left, y, frame.right(), y, RED, 1.5, Some("6 4"));
    svg.text(
        frame.right() - 4.0,
        y - 5.0,
        &format!("limit {}", fmt_sig(limit, 3)),
        Style {
            anchor: "end",
            fill: RED,
            ..SMALL
        },
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plots::fixtures::{bounce_count_bins, check, fractional_labels, summary, wear_bins};

    #[test]
    fn bands_of_a_wear_test() {
        let bins = wear_bins(10, 100, Some(0.0095));
        let svg = quantile_bands_svg("total_bounce_s", &bins);
        check(&svg);
        assert!(svg.contains("total_bounce_s: wear curve"));
        assert!(svg.contains("<polygon"));
        assert!(svg.contains("median (p50)"));
        assert!(svg.contains(">mean<"));
        assert!(svg.contains("limit 0.00950"));
        assert!(svg.contains(">operation<"));
        // The last bin's midpoint is inside the axis: 1000 is a tick.
        assert!(svg.contains(">1000<"));
    }

    #[test]
    fn a_whole_valued_metric_gets_whole_ticks() {
        let svg = quantile_bands_svg("bounce_count", &bounce_count_bins(6));
        check(&svg);
        assert_eq!(fractional_labels(&svg), Vec::<&str>::new());
    }

    #[test]
    fn bands_of_degenerate_bins() {
        check(&quantile_bands_svg("kappa", &[]));
        let one = wear_bins(1, 1, None);
        check(&quantile_bands_svg("kappa", &one));
        let flat: Vec<Bin> = (0..5)
            .map(|b| Bin {
                summary: summary(&[0.0; 4], None),
                op_start: b,
                op_end: b + 1,
            })
            .collect();
        check(&quantile_bands_svg("bounce_count", &flat));
        let big: Vec<Bin> = (0..5)
            .map(|b| Bin {
                summary: summary(&[1e300, -1e300], None),
                op_start: b * 1_000_000_000,
                op_end: (b + 1) * 1_000_000_000,
            })
            .collect();
        check(&quantile_bands_svg("peak_force_n", &big));
        let mut odd = wear_bins(3, 10, None);
        odd[1].summary.quantiles.clear();
        odd[2].summary.mean = f64::NAN;
        odd[0].summary.n = 0;
        check(&quantile_bands_svg("e1", &odd));
    }

    #[test]
    fn bands_of_two_designs_overlaid() {
        let (a, b) = (wear_bins(10, 100, None), wear_bins(5, 200, None));
        let designs = [
            Design {
                name: "a: strong",
                bins: &a,
            },
            Design {
                name: "b: weak",
                bins: &b,
            },
        ];
        let svg = compared_bands_svg("total_bounce_s", &designs);
        check(&svg);
        assert!(svg.contains("total_bounce_s: wear curves compared"));
        assert_eq!(svg.matches("<polygon").count(), 2);
        assert!(svg.contains(">a: strong<") && svg.contains(">b: weak<"));
        assert!(svg.contains(SERIES[0]) && svg.contains(SERIES[1]));
        // An empty design beside a full one still draws the other.
        let empty = [
            Design {
                name: "a",
                bins: &[],
            },
            Design {
                name: "b",
                bins: &b,
            },
        ];
        let svg = compared_bands_svg("e1", &empty);
        check(&svg);
        assert_eq!(svg.matches("<polygon").count(), 1);
    }
}
