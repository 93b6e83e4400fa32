//! Which scattered parameters drive a metric: its Sobol' indices (first-order and total, with
//! their 95 % intervals) or, for method `regression`, its standardised regression coefficients,
//! in the first and the last bin side by side.

use bouncewear_model::montecarlo::sensitivity::{ParameterSensitivity, SensitivityBin};
use bouncewear_model::stats::sobol::IndexEstimate;

use super::axes::{Frame, Legend, LinearAxis, Scale, draw_frame_axes, draw_x_ticks};
use super::finite;
use super::svg::{
    AXIS, BLUE, INK, LABEL, SERIES, SMALL, Style, Svg, fmt_sig, text_width, truncate,
};

/// Parameters drawn at most; the rest are named in a note.
const MAX_ROWS: usize = 24;
/// The axis is 0 to 1, widened to the intervals but never beyond these.
const AXIS_FLOOR: f64 = -0.5;
const AXIS_CEILING: f64 = 1.5;
const TOTAL: &str = SERIES[1];
const ROW_SHADE: &str = "#f9fafb";

/// Horizontal bars per parameter of `metric`'s sensitivity: the first-order and the total Sobol'
/// index side by side with their 95 % interval whiskers, for the first and the last of `bins`
/// (one panel each, labelled with its operations; a device metric has one), parameters ordered
/// by their total index in the last bin. Without Sobol' indices (method `regression`), the
/// absolute standardised regression coefficient, its sign written at the bar, and the R².
pub fn sensitivity_svg(metric: &str, bins: &[SensitivityBin]) -> String {
    let sobol = bins
        .iter()
        .flat_map(|b| b.indices.values())
        .any(|p| p.first.is_some() || p.total.is_some());
    let title = if sobol {
        format!("Sensitivity of {metric}: Sobol' indices")
    } else {
        format!("Sensitivity of {metric}: standardised regression coefficients")
    };
    let panels: Vec<&SensitivityBin> = match bins {
        [] => Vec::new(),
        [only] => vec![only],
        [first, .., last] => vec![first, last],
    };
    if panels.is_empty() {
        return super::message_svg(&title, "no sensitivity indices for this metric");
    }
    let (names, hidden) = ranked_names(&panels, sobol);
    if names.is_empty() {
        return super::message_svg(&title, "no scattered parameters in this analysis");
    }
    let layout = Layout::new(&panels, &names, hidden, sobol);

    let mut svg = Svg::new(layout.width, layout.height, &title);
    svg.title(&title, 16.0, 24.0);
    let mut legend = Legend::new(16.0, 50.0);
    if sobol {
        legend.swatch(&mut svg, BLUE, "first-order index");
        legend.swatch(&mut svg, TOTAL, "total index");
        legend.line(&mut svg, INK, None, "95 % interval");
    } else {
        legend.swatch(
            &mut svg,
            BLUE,
            "|standardised regression coefficient| (sign at the bar)",
        );
    }
    draw_rows(&mut svg, &layout, &names);
    for (k, bin) in panels.iter().enumerate() {
        let heading = match (k, panels.len()) {
            (_, 1) => operations(bin),
            (0, _) => format!("{} (first bin)", operations(bin)),
            _ => format!("{} (last bin)", operations(bin)),
        };
        draw_panel(&mut svg, &layout, k, &heading, bin, &names);
    }
    if hidden > 0 {
        svg.text(
            16.0,
            layout.height - 10.0,
            &format!("{hidden} more parameters with smaller indices are not shown"),
            MUTED_START,
        );
    }
    svg.finish()
}

/// Every parameter of the panels, the most influential in the last first (by its total index,
/// or its coefficient's size), cut to [`MAX_ROWS`]; and how many were cut.
fn ranked_names<'a>(panels: &[&'a SensitivityBin], sobol: bool) -> (Vec<&'a str>, usize) {
    let mut names: Vec<&str> = Vec::new();
    for bin in panels {
        for name in bin.indices.keys() {
            if !names.contains(&name.as_str()) {
                names.push(name);
            }
        }
    }
    let last = panels[panels.len() - 1];
    let weight = |name: &str| {
        last.indices
            .get(name)
            .and_then(|p| {
                if sobol {
                    p.total.and_then(|t| finite(t.value))
                } else {
                    p.src.and_then(finite).map(f64::abs)
                }
            })
            .unwrap_or(f64::NEG_INFINITY)
    };
    names.sort_by(|a, b| weight(b).total_cmp(&weight(a)));
    let hidden = names.len().saturating_sub(MAX_ROWS);
    names.truncate(MAX_ROWS);
    (names, hidden)
}

/// Where the rows and panels go, and the axis they share.
struct Layout {
    sobol: bool,
    axis: LinearAxis,
    label_width: f64,
    row_h: f64,
    panel_w: f64,
    gap: f64,
    top: f64,
    width: f64,
    height: f64,
}

impl Layout {
    fn new(panels: &[&SensitivityBin], names: &[&str], hidden: usize, sobol: bool) -> Self {
        // The axis: 0 to 1, widened (within limits) to every value and interval drawn.
        let mut lo: f64 = 0.0;
        let mut hi: f64 = 1.0;
        for bin in panels {
            for name in names {
                let Some(p) = bin.indices.get(*name) else {
                    continue;
                };
                for v in drawn_values(p, sobol) {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
        }
        let axis = index_axis(lo.max(AXIS_FLOOR), hi.min(AXIS_CEILING));
        let label_width = names
            .iter()
            .map(|n| text_width(&truncate(n, 34), 12.0))
            .fold(0.0, f64::max)
            .clamp(90.0, 220.0)
            + 24.0;
        let row_h = if sobol { 30.0 } else { 24.0 };
        let panel_w = if panels.len() == 1 { 460.0 } else { 300.0 };
        let gap = 28.0;
        let (top, bottom) = (96.0, 58.0);
        let plots_w = panel_w * panels.len() as f64 + gap * (panels.len() - 1) as f64;
        let width = (label_width + plots_w + 24.0).max(560.0);
        let rows_h = row_h * names.len() as f64;
        let height = top + rows_h + bottom + if hidden > 0 { 16.0 } else { 0.0 };
        Self {
            sobol,
            axis,
            label_width,
            row_h,
            panel_w,
            gap,
            top,
            width,
            height,
        }
    }

    /// The top of row `r`.
    fn row(&self, r: usize) -> f64 {
        self.top + self.row_h * r as f64
    }
}

/// The rows' shading and the parameters' names.
fn draw_rows(svg: &mut Svg, layout: &Layout, names: &[&str]) {
    for (r, name) in names.iter().enumerate() {
        let y = layout.row(r);
        if r % 2 == 1 {
            svg.rect(16.0, y, layout.width - 32.0, layout.row_h, ROW_SHADE, None);
        }
        svg.text(
            layout.label_width - 12.0,
            y + layout.row_h / 2.0 + 4.0,
            &truncate(name, 34),
            Style {
                anchor: "end",
                ..LABEL
            },
        );
    }
}

/// Panel `k`: its heading, the R² of a regression, the axis, and each parameter's bars.
fn draw_panel(
    svg: &mut Svg,
    layout: &Layout,
    k: usize,
    heading: &str,
    bin: &SensitivityBin,
    names: &[&str],
) {
    let (top, axis, sobol) = (layout.top, &layout.axis, layout.sobol);
    let frame = Frame {
        left: layout.label_width + (layout.panel_w + layout.gap) * k as f64,
        top,
        width: layout.panel_w,
        height: layout.row_h * names.len() as f64,
    };
    let xs = Scale::new(axis.lo, axis.hi, frame.left, frame.right());
    svg.text(
        frame.left + frame.width / 2.0,
        top - 22.0,
        heading,
        Style {
            bold: true,
            ..LABEL
        },
    );
    if let Some(r2) = bin.r_squared.and_then(finite).filter(|_| !sobol) {
        let note = format!("R\u{b2} = {}", fmt_sig(r2, 3));
        svg.text(frame.left + frame.width / 2.0, top - 8.0, &note, SMALL);
    }
    draw_x_ticks(svg, &frame, axis, &xs, true);
    draw_frame_axes(svg, &frame);
    // 0 and 1 stand out from the grid: no influence and all of the variance.
    let x0 = xs.map(0.0);
    svg.line(x0, frame.top, x0, frame.bottom(), AXIS, 1.0, None);
    if sobol && axis.lo <= 1.0 && 1.0 <= axis.hi {
        let x1 = xs.map(1.0);
        svg.line(x1, frame.top, x1, frame.bottom(), AXIS, 1.0, Some("4 3"));
    }
    for (r, name) in names.iter().enumerate() {
        let y = layout.row(r);
        let Some(p) = bin.indices.get(*name) else {
            svg.text(
                x0 + 4.0,
                y + layout.row_h / 2.0 + 4.0,
                "\u{2013}",
                MUTED_START,
            );
            continue;
        };
        if sobol {
            let bars = [(p.first, BLUE, 5.0), (p.total, TOTAL, 15.0)];
            for (estimate, colour, offset) in bars {
                draw_index(svg, &xs, axis, estimate, colour, y + offset, 8.0);
            }
        } else {
            draw_src(svg, &xs, axis, p.src, y + 6.0, 12.0);
        }
    }
    let caption = if sobol {
        "Sobol' index (share of the variance)"
    } else {
        "|standardised regression coefficient|"
    };
    svg.text(
        frame.left + frame.width / 2.0,
        frame.bottom() + 36.0,
        caption,
        SMALL,
    );
}

const MUTED_START: Style = Style {
    anchor: "start",
    ..SMALL
};

/// Ticks of `[lo, hi]` (which holds 0 to 1), the axis only a little wider than the values: an
/// interval that ends at -0.01 widens it to -0.04, not to the next tick at -0.2.
fn index_axis(lo: f64, hi: f64) -> LinearAxis {
    const MARGIN: f64 = 0.03;
    let mut axis = LinearAxis::new(lo, hi, 5, false);
    axis.lo = axis.lo.max(lo - MARGIN);
    axis.hi = axis.hi.min(hi + MARGIN);
    let (ticks, labels) = axis
        .ticks
        .iter()
        .zip(&axis.labels)
        .filter(|(t, _)| (axis.lo - 1e-9..=axis.hi + 1e-9).contains(*t))
        .map(|(t, l)| (*t, l.clone()))
        .unzip();
    axis.ticks = ticks;
    axis.labels = labels;
    axis
}

/// "operations 0–99" for a bin of operations 0 to 99 (its end is exclusive); a device metric's
/// single entry is over the devices at the end of the test.
fn operations(bin: &SensitivityBin) -> String {
    match (bin.op_start, bin.op_end) {
        (Some(start), Some(end)) => super::operation_range(start, end),
        (Some(start), None) => format!("operations from {start}"),
        _ => "devices at the end of the test".to_owned(),
    }
}

/// The finite numbers a parameter's bars and whiskers reach.
fn drawn_values(p: &ParameterSensitivity, sobol: bool) -> Vec<f64> {
    if sobol {
        [p.first, p.total]
            .into_iter()
            .flatten()
            .flat_map(|e| [e.value, e.ci95[0], e.ci95[1]])
            .filter(|v| v.is_finite())
            .collect()
    } else {
        p.src.and_then(finite).map(f64::abs).into_iter().collect()
    }
}

/// A bar from 0 to `value`, clipped to the axis.
fn bar(svg: &mut Svg, xs: &Scale, axis: &LinearAxis, value: f64, colour: &str, y: f64, h: f64) {
    let v = value.clamp(axis.lo, axis.hi);
    let (a, b) = (xs.map(v.min(0.0)), xs.map(v.max(0.0)));
    // A value of 0 still shows as a hairline.
    svg.rect(a, y, (b - a).max(1.0), h, colour, None);
}

/// One Sobol' index: its bar and, when it has one, its 95 % interval as a whisker with caps (none
/// at an end clipped by the axis).
fn draw_index(
    svg: &mut Svg,
    xs: &Scale,
    axis: &LinearAxis,
    estimate: Option<IndexEstimate>,
    colour: &str,
    y: f64,
    h: f64,
) {
    let Some(e) = estimate else {
        return;
    };
    let Some(value) = finite(e.value) else {
        return;
    };
    bar(svg, xs, axis, value, colour, y, h);
    let [lo, hi] = e.ci95;
    if !(lo.is_finite() && hi.is_finite()) || lo > hi {
        return;
    }
    let mid = y + h / 2.0;
    let (xl, xh) = (
        xs.map(lo.clamp(axis.lo, axis.hi)),
        xs.map(hi.clamp(axis.lo, axis.hi)),
    );
    svg.line(xl, mid, xh, mid, INK, 1.2, None);
    for (x, inside) in [(xl, lo >= axis.lo), (xh, hi <= axis.hi)] {
        if inside {
            svg.line(x, mid - 4.0, x, mid + 4.0, INK, 1.2, None);
        }
    }
}

/// A standardised regression coefficient: a bar of its absolute value, its signed value beside.
fn draw_src(svg: &mut Svg, xs: &Scale, axis: &LinearAxis, src: Option<f64>, y: f64, h: f64) {
    let Some(src) = src.and_then(finite) else {
        svg.text(
            xs.map(0.0) + 4.0,
            y + h / 2.0 + 4.0,
            "no coefficient",
            MUTED_START,
        );
        return;
    };
    bar(svg, xs, axis, src.abs(), BLUE, y, h);
    let sign = if src < 0.0 { "\u{2212}" } else { "+" };
    let end = xs.map(src.abs().clamp(axis.lo, axis.hi));
    let label = format!("{sign}{}", fmt_sig(src.abs(), 2));
    // Inside the frame: after the bar, or over it when the bar fills the panel.
    let (x, style) = if end + 6.0 + text_width(&label, 11.0) <= xs.map(axis.hi) {
        (end + 4.0, MUTED_START)
    } else {
        (
            end - 4.0,
            Style {
                anchor: "end",
                fill: "#ffffff",
                ..SMALL
            },
        )
    };
    svg.text(x, y + h / 2.0 + 4.0, &label, style);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plots::fixtures::check;
    use bouncewear_model::montecarlo::job::Per;
    use std::collections::BTreeMap;

    fn estimate(value: f64, half: f64) -> Option<IndexEstimate> {
        Some(IndexEstimate {
            value,
            ci95: [value - half, value + half],
        })
    }

    fn sobol_bin(start: u64, end: u64, params: &[(&str, f64, f64)]) -> SensitivityBin {
        SensitivityBin {
            op_start: Some(start),
            op_end: Some(end),
            indices: params
                .iter()
                .map(|&(name, first, total)| {
                    (
                        name.to_owned(),
                        ParameterSensitivity {
                            first: estimate(first, 0.05),
                            total: estimate(total, 0.08),
                            src: Some(first.sqrt()),
                            per: Per::Device,
                        },
                    )
                })
                .collect(),
            r_squared: Some(0.9),
            reason: None,
        }
    }

    fn regression_bin(start: u64, end: u64, params: &[(&str, Option<f64>)]) -> SensitivityBin {
        SensitivityBin {
            op_start: Some(start),
            op_end: Some(end),
            indices: params
                .iter()
                .map(|&(name, src)| {
                    (
                        name.to_owned(),
                        ParameterSensitivity {
                            first: None,
                            total: None,
                            src,
                            per: Per::Operation,
                        },
                    )
                })
                .collect(),
            r_squared: Some(0.81),
            reason: None,
        }
    }

    fn strict(svg: &str) {
        check(svg);
        assert!(!svg.contains(" id="), "an id attribute in {svg}");
    }

    #[test]
    fn sobol_indices_of_the_first_and_last_bin_with_their_operations() {
        let bins = [
            sobol_bin(
                0,
                100,
                &[
                    ("contact_radius_m", 0.2, 0.3),
                    ("impact_velocity_m_s", 0.6, 0.7),
                ],
            ),
            sobol_bin(100, 200, &[("contact_radius_m", 0.4, 0.5)]),
            sobol_bin(
                900,
                1000,
                &[
                    ("contact_radius_m", 0.7, 0.8),
                    ("impact_velocity_m_s", 0.1, 0.2),
                ],
            ),
        ];
        let svg = sensitivity_svg("total_bounce_s", &bins);
        strict(&svg);
        assert!(svg.contains("operations 0\u{2013}99 (first bin)"), "{svg}");
        assert!(svg.contains("operations 900\u{2013}999 (last bin)"));
        assert!(!svg.contains("operations 100\u{2013}199"));
        assert!(svg.contains("first-order index") && svg.contains("total index"));
        // Two panels, two parameters, two bars each.
        assert_eq!(svg.matches(&format!("fill=\"{TOTAL}\"")).count(), 4 + 1);
        // Ordered by the last bin's total index: the radius first.
        assert!(
            svg.find(">contact_radius_m<").unwrap() < svg.find(">impact_velocity_m_s<").unwrap()
        );
        // Within 0..1: the axis is 0 to 1.
        assert!(svg.contains(">0<") && svg.contains(">1.0<"), "{svg}");
        assert!(!svg.contains(">-0.2<"));
    }

    #[test]
    fn intervals_across_0_or_1_widen_the_axis_a_little_and_no_further() {
        let mut bin = sobol_bin(0, 50, &[("contact_radius_m", -0.02, 0.98)]);
        let p = bin.indices.get_mut("contact_radius_m").unwrap();
        p.first = Some(IndexEstimate {
            value: -0.02,
            ci95: [-0.1, 0.06],
        });
        p.total = Some(IndexEstimate {
            value: 0.98,
            ci95: [0.9, 1.07],
        });
        let svg = sensitivity_svg("arc_energy_j", &[bin]);
        strict(&svg);
        // Widened to the intervals, not to the next ticks.
        let axis = index_axis(-0.1, 1.07);
        assert!((axis.lo + 0.13).abs() < 1e-9 && (axis.hi - 1.1).abs() < 1e-9);
        assert_eq!(axis.labels.first().map(String::as_str), Some("0"));
        assert!(!svg.contains(">-0.2<") && !svg.contains(">1.2<"), "{svg}");
        assert!(svg.contains(">0<") && svg.contains(">1.0<"));
        let mut wild = sobol_bin(0, 50, &[("x", 0.5, 0.5)]);
        wild.indices.get_mut("x").unwrap().total = Some(IndexEstimate {
            value: 0.5,
            ci95: [-40.0, 90.0],
        });
        let svg = sensitivity_svg("arc_energy_j", &[wild]);
        strict(&svg);
        assert!(!svg.contains(">-40") && !svg.contains(">90<"), "{svg}");
        let axis = index_axis(AXIS_FLOOR, AXIS_CEILING);
        assert!(axis.lo >= AXIS_FLOOR - 0.03 && axis.hi <= AXIS_CEILING + 0.03);
    }

    #[test]
    fn a_device_metric_has_one_panel_over_the_devices() {
        let mut bin = sobol_bin(0, 0, &[("contact_radius_m", 0.9, 0.95)]);
        bin.op_start = None;
        bin.op_end = None;
        let svg = sensitivity_svg("final_radius_m", &[bin]);
        strict(&svg);
        assert!(svg.contains("devices at the end of the test"));
        assert!(!svg.contains("(first bin)"));
    }

    #[test]
    fn regression_draws_the_absolute_coefficient_with_its_sign() {
        let bins = [
            regression_bin(0, 10, &[("a", Some(-0.8)), ("b", Some(0.3)), ("c", None)]),
            regression_bin(10, 20, &[("a", Some(-0.5)), ("b", Some(1.2)), ("c", None)]),
        ];
        let svg = sensitivity_svg("total_bounce_s", &bins);
        strict(&svg);
        assert!(svg.contains("standardised regression coefficient"));
        assert!(!svg.contains("first-order"));
        assert!(
            svg.contains("\u{2212}0.80") && svg.contains("+1.2"),
            "{svg}"
        );
        assert!(svg.contains("R\u{b2} = 0.810"));
        assert!(svg.contains("no coefficient"));
        assert!(svg.contains("operations 10\u{2013}19 (last bin)"));
    }

    #[test]
    fn empty_and_degenerate_input_still_make_a_document() {
        let svg = sensitivity_svg("total_bounce_s", &[]);
        strict(&svg);
        assert!(svg.contains("no sensitivity indices"));
        let svg = sensitivity_svg(
            "m",
            &[SensitivityBin {
                op_start: Some(0),
                op_end: Some(0),
                indices: BTreeMap::new(),
                r_squared: None,
                reason: None,
            }],
        );
        strict(&svg);
        let mut bin = sobol_bin(5, 5, &[("<b>&\"x\"", f64::NAN, f64::INFINITY)]);
        bin.indices.get_mut("<b>&\"x\"").unwrap().first = Some(IndexEstimate {
            value: 0.3,
            ci95: [f64::NAN, f64::NEG_INFINITY],
        });
        bin.r_squared = Some(f64::NAN);
        let svg = sensitivity_svg("<m>", &[bin.clone(), bin]);
        strict(&svg);
        assert!(svg.contains("&lt;b&gt;&amp;&quot;x&quot;"));
        assert!(svg.contains("operations 5\u{2013}5"));
    }

    #[test]
    fn many_parameters_are_capped_with_a_note() {
        let names: Vec<String> = (0..30).map(|k| format!("parameter_{k:02}")).collect();
        let params: Vec<(&str, f64, f64)> = names
            .iter()
            .enumerate()
            .map(|(k, n)| (n.as_str(), k as f64 / 100.0, k as f64 / 50.0))
            .collect();
        let svg = sensitivity_svg("m", &[sobol_bin(0, 10, &params)]);
        strict(&svg);
        assert!(svg.contains("6 more parameters"));
        assert!(svg.contains(">parameter_29<") && !svg.contains(">parameter_00<"));
    }
}
