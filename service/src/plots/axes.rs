//! From data to pixels: scales, linear and log axes with their ticks, the plotting frame, and the
//! drawing of grids, axis lines and legends.

use super::svg::{
    AXIS, GRID, GRID_MINOR, LABEL, MUTED, SMALL, Style, Svg, log10_floor, text_width, trim_exponent,
};

/// A linear map from a data domain to pixels; a zero-width domain maps to the range's middle.
#[derive(Clone, Copy)]
pub(super) struct Scale {
    d0: f64,
    d1: f64,
    r0: f64,
    r1: f64,
}

impl Scale {
    pub(super) fn new(d0: f64, d1: f64, r0: f64, r1: f64) -> Self {
        Scale { d0, d1, r0, r1 }
    }

    pub(super) fn map(&self, v: f64) -> f64 {
        let span = self.d1 - self.d0;
        if !(span.is_finite() && span != 0.0 && v.is_finite()) {
            return (self.r0 + self.r1) / 2.0;
        }
        let px = self.r0 + (v - self.d0) / span * (self.r1 - self.r0);
        if px.is_finite() {
            px
        } else {
            (self.r0 + self.r1) / 2.0
        }
    }
}

/// A linear axis with "nice" ticks (steps of 1, 2 or 5 times a power of ten) that cover the data.
pub(super) struct LinearAxis {
    pub(super) lo: f64,
    pub(super) hi: f64,
    pub(super) ticks: Vec<f64>,
    pub(super) labels: Vec<String>,
}

impl LinearAxis {
    /// About `target` ticks over `[lo, hi]`; `integer` keeps steps whole (counts, operations).
    pub(super) fn new(lo: f64, hi: f64, target: usize, integer: bool) -> Self {
        let (mut lo, mut hi) = if lo.is_finite() && hi.is_finite() {
            (lo.min(hi), lo.max(hi))
        } else {
            (0.0, 1.0)
        };
        let scale = lo.abs().max(hi.abs());
        if hi - lo <= scale * 1e-9 {
            // All values equal: a window around them (from 0 up when they are all 0).
            let pad = if scale > 0.0 { scale * 0.1 } else { 1.0 };
            if scale == 0.0 && integer {
                hi += pad;
            } else {
                lo -= pad;
                hi += pad;
            }
        }
        let raw = (hi - lo) / target.max(1) as f64;
        let magnitude = 10f64.powf(log10_floor(raw));
        let norm = raw / magnitude;
        let mut step = magnitude
            * if norm < 1.5 {
                1.0
            } else if norm < 3.0 {
                2.0
            } else if norm < 7.0 {
                5.0
            } else {
                10.0
            };
        if integer {
            step = step.max(1.0).round();
        }
        if !(step.is_finite() && step > 0.0) {
            step = 1.0;
        }
        let first = (lo / step).floor();
        let last = (hi / step).ceil();
        let count = ((last - first).max(1.0) as usize).min(60);
        let ticks: Vec<f64> = (0..=count).map(|i| (first + i as f64) * step).collect();
        let labels = linear_labels(&ticks, step);
        let (nlo, nhi) = (ticks[0], ticks[ticks.len() - 1]);
        LinearAxis {
            lo: nlo,
            hi: nhi,
            ticks,
            labels,
        }
    }
}

/// Tick labels with as many decimals as the step needs, in exponent form when the numbers are very
/// small or large.
fn linear_labels(ticks: &[f64], step: f64) -> Vec<String> {
    let max_abs = ticks.iter().fold(0.0f64, |m, t| m.max(t.abs()));
    let step_exp = log10_floor(step);
    let exponent_form = max_abs >= 1e6 || (max_abs > 0.0 && max_abs < 1e-3);
    ticks
        .iter()
        .map(|&t| {
            if t.abs() < step * 1e-6 {
                return "0".to_owned();
            }
            if exponent_form {
                let e = log10_floor(t.abs());
                let decimals = (e - step_exp).clamp(0.0, 6.0) as usize;
                trim_exponent(&format!("{t:.decimals$e}"))
            } else {
                let decimals = (-step_exp).clamp(0.0, 12.0) as usize;
                format!("{t:.decimals$}")
            }
        })
        .collect()
}

/// A base-10 log axis: labelled ticks at decades (and at 2 and 5, or every integer multiple, when
/// the range is short), light grid lines at the multiples in between.
pub(super) struct LogAxis {
    pub(super) lo: f64,
    pub(super) hi: f64,
    pub(super) labelled: Vec<f64>,
    /// `(value, major)`.
    pub(super) grid: Vec<(f64, bool)>,
}

impl LogAxis {
    /// At most 8 decades, centred on the geometric middle: beyond that a few outliers would
    /// squeeze the values that matter into a corner.
    pub(super) fn new(lo: f64, hi: f64) -> Self {
        let (mut lo, mut hi) = positive_range(lo, hi);
        if hi / lo > 1e8 {
            let mid = (lo.log10() + hi.log10()) / 2.0;
            lo = 10f64.powf(mid - 4.0);
            hi = 10f64.powf(mid + 4.0);
        }
        Self::ticked(lo, hi)
    }

    /// Every decade of `[lo, hi]`, for plots whose point is how many decades apart the values are.
    pub(super) fn whole(lo: f64, hi: f64) -> Self {
        let (lo, hi) = positive_range(lo, hi);
        Self::ticked(lo, hi)
    }

    /// A scale of `log10` values: a log axis is linear in the exponent.
    pub(super) fn scale(&self, r0: f64, r1: f64) -> Scale {
        Scale::new(self.lo.log10(), self.hi.log10(), r0, r1)
    }

    /// The ticks of `[lo, hi]`, first widened to a factor of 1.2 when it is narrower: a log axis
    /// needs some ratio to show.
    fn ticked(mut lo: f64, mut hi: f64) -> Self {
        if hi / lo < 1.2 {
            let mid = (lo * hi).sqrt();
            lo = mid / 1.1;
            hi = mid * 1.1;
        }
        let span = hi.log10() - lo.log10();
        if span < 0.6 {
            // Less than a factor of 4: a log axis has almost no decade ticks, so use linear ones.
            let linear = LinearAxis::new(lo, hi, 6, false);
            let ticks: Vec<f64> = linear
                .ticks
                .into_iter()
                .filter(|&t| t >= lo && t <= hi && t > 0.0)
                .collect();
            return LogAxis {
                lo,
                hi,
                grid: ticks.iter().map(|&t| (t, true)).collect(),
                labelled: ticks,
            };
        }
        let labelled_multiples: &[f64] = if span < 1.0 {
            &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
        } else if span < 2.5 {
            &[1.0, 2.0, 5.0]
        } else {
            &[1.0]
        };
        let decade_step = (span / 7.0).ceil().max(1.0) as i32;
        let (e0, e1) = (log10_floor(lo) as i32, hi.log10().ceil() as i32);
        let mut labelled = Vec::new();
        let mut grid = Vec::new();
        for e in e0..=e1 {
            let base = 10f64.powi(e);
            for m in 1..=9 {
                let v = base * f64::from(m);
                if v < lo || v > hi {
                    continue;
                }
                let is_labelled = labelled_multiples.contains(&f64::from(m))
                    && (m != 1 || (e - e0).rem_euclid(decade_step) == 0);
                if is_labelled {
                    labelled.push(v);
                }
                if m == 1 || span <= 4.0 {
                    grid.push((v, m == 1 || is_labelled));
                }
            }
        }
        LogAxis {
            lo,
            hi,
            labelled,
            grid,
        }
    }
}

/// `[lo, hi]` with both ends usable on a log axis: a decade from 1 when nothing is.
fn positive_range(lo: f64, hi: f64) -> (f64, f64) {
    let lo = if lo.is_finite() && lo > 0.0 { lo } else { 1.0 };
    let hi = if hi.is_finite() && hi > lo {
        hi
    } else {
        lo * 10.0
    };
    (lo, hi)
}

/// `[lo, hi]` widened by a factor that grows with its ratio, so the points at either end stay
/// clear of the frame on a log axis.
pub(super) fn widen_log(lo: f64, hi: f64) -> (f64, f64) {
    let margin = (hi / lo).powf(0.06).max(1.04);
    (lo / margin, hi * margin)
}

/// A log-axis tick, at most 6 significant digits with nothing trailing: plain between 1e-3 and
/// 1e6, else in exponent form (`2e7`).
pub(super) fn fmt_tick(v: f64) -> String {
    if !v.is_finite() {
        return "\u{2013}".to_owned();
    }
    if v == 0.0 {
        return "0".to_owned();
    }
    let rounded: f64 = format!("{v:.5e}").parse().unwrap_or(v);
    let e = log10_floor(rounded.abs());
    if (-3.0..6.0).contains(&e) {
        format!("{rounded}")
    } else {
        format!("{rounded:e}")
    }
}

/// The plotting area.
#[derive(Clone, Copy)]
pub(super) struct Frame {
    pub(super) left: f64,
    pub(super) top: f64,
    pub(super) width: f64,
    pub(super) height: f64,
}

impl Frame {
    /// The area of a `width` x `height` box at (`x`, `y`) inside margins `[left, top, right,
    /// bottom]` (room for the labels around the plot).
    pub(super) fn inset(x: f64, y: f64, width: f64, height: f64, margins: [f64; 4]) -> Self {
        let [left, top, right, bottom] = margins;
        Self {
            left: x + left,
            top: y + top,
            width: width - left - right,
            height: height - top - bottom,
        }
    }

    pub(super) fn right(&self) -> f64 {
        self.left + self.width
    }
    pub(super) fn bottom(&self) -> f64 {
        self.top + self.height
    }
}

/// Horizontal grid lines and labels of a y axis.
pub(super) fn draw_y_grid(svg: &mut Svg, frame: &Frame, axis: &LinearAxis, ys: &Scale) {
    for (t, label) in axis.ticks.iter().zip(&axis.labels) {
        let y = ys.map(*t);
        svg.line(frame.left, y, frame.right(), y, GRID, 1.0, None);
        svg.text(
            frame.left - 6.0,
            y + 4.0,
            label,
            Style {
                anchor: "end",
                ..SMALL
            },
        );
    }
}

/// Tick marks and labels of an x axis (labels thinned when they would overlap).
pub(super) fn draw_x_ticks(
    svg: &mut Svg,
    frame: &Frame,
    axis: &LinearAxis,
    xs: &Scale,
    grid: bool,
) {
    let widest = axis
        .labels
        .iter()
        .map(|l| text_width(l, 11.0))
        .fold(0.0, f64::max);
    let spacing = frame.width / (axis.ticks.len().max(2) - 1) as f64;
    let every = ((widest + 8.0) / spacing.max(1e-9)).ceil().max(1.0) as usize;
    for (k, (t, label)) in axis.ticks.iter().zip(&axis.labels).enumerate() {
        let x = xs.map(*t);
        if grid {
            svg.line(x, frame.top, x, frame.bottom(), GRID, 1.0, None);
        }
        svg.line(x, frame.bottom(), x, frame.bottom() + 4.0, AXIS, 1.0, None);
        if k.is_multiple_of(every) {
            svg.text(x, frame.bottom() + 16.0, label, SMALL);
        }
    }
}

/// Vertical grid lines of a log x axis (fainter between labelled values), with tick marks and
/// labels at the labelled values.
pub(super) fn draw_log_x_axis(svg: &mut Svg, frame: &Frame, axis: &LogAxis, xs: &Scale) {
    for &(t, major) in &axis.grid {
        let x = xs.map(t.log10());
        let colour = if major { GRID } else { GRID_MINOR };
        svg.line(x, frame.top, x, frame.bottom(), colour, 1.0, None);
    }
    for &t in &axis.labelled {
        let x = xs.map(t.log10());
        svg.line(x, frame.bottom(), x, frame.bottom() + 5.0, AXIS, 1.0, None);
        svg.text(x, frame.bottom() + 18.0, &fmt_tick(t), SMALL);
    }
}

/// Horizontal grid lines of a log y axis (fainter between labelled values), with labels at the
/// labelled values.
pub(super) fn draw_log_y_grid(svg: &mut Svg, frame: &Frame, axis: &LogAxis, ys: &Scale) {
    for &(t, major) in &axis.grid {
        let y = ys.map(t.log10());
        let colour = if major { GRID } else { GRID_MINOR };
        svg.line(frame.left, y, frame.right(), y, colour, 1.0, None);
    }
    for &t in &axis.labelled {
        let y = ys.map(t.log10());
        svg.text(
            frame.left - 6.0,
            y + 4.0,
            &fmt_tick(t),
            Style {
                anchor: "end",
                ..SMALL
            },
        );
    }
}

/// The left and bottom axis lines.
pub(super) fn draw_frame_axes(svg: &mut Svg, frame: &Frame) {
    svg.line(
        frame.left,
        frame.top,
        frame.left,
        frame.bottom(),
        AXIS,
        1.0,
        None,
    );
    svg.line(
        frame.left,
        frame.bottom(),
        frame.right(),
        frame.bottom(),
        AXIS,
        1.0,
        None,
    );
}

/// A message in the middle of an empty frame, so a plot without points says why.
pub(super) fn draw_no_data(svg: &mut Svg, frame: &Frame, message: &str) {
    svg.text(
        frame.left + frame.width / 2.0,
        frame.top + frame.height / 2.0,
        message,
        Style {
            size: 13.0,
            fill: MUTED,
            ..LABEL
        },
    );
}

/// A one-row legend, items left to right.
pub(super) struct Legend {
    x: f64,
    y: f64,
}

impl Legend {
    pub(super) fn new(x: f64, y: f64) -> Self {
        Legend { x, y }
    }

    fn label(&mut self, svg: &mut Svg, offset: f64, text: &str) {
        svg.text(
            self.x + offset,
            self.y + 4.0,
            text,
            Style {
                anchor: "start",
                ..LABEL
            },
        );
        self.x += offset + text_width(text, 12.0) + 18.0;
    }

    pub(super) fn swatch(&mut self, svg: &mut Svg, fill: &str, text: &str) {
        svg.rect(self.x, self.y - 6.0, 22.0, 12.0, fill, None);
        self.label(svg, 28.0, text);
    }

    pub(super) fn line(&mut self, svg: &mut Svg, color: &str, dash: Option<&str>, text: &str) {
        svg.line(self.x, self.y, self.x + 22.0, self.y, color, 2.0, dash);
        self.label(svg, 28.0, text);
    }

    pub(super) fn dot(&mut self, svg: &mut Svg, color: &str, text: &str) {
        svg.circle(self.x + 5.0, self.y, 3.5, color, "#ffffff", 1.0);
        self.label(svg, 14.0, text);
    }

    pub(super) fn ring(&mut self, svg: &mut Svg, color: &str, text: &str) {
        svg.circle(self.x + 8.0, self.y, 7.0, "none", color, 1.8);
        svg.circle(self.x + 8.0, self.y, 3.5, color, "#ffffff", 1.0);
        self.label(svg, 20.0, text);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_are_nice() {
        let a = LinearAxis::new(0.0081, 0.0112, 6, false);
        assert!(a.lo <= 0.0081 && a.hi >= 0.0112);
        assert!(
            a.labels.contains(&"0.0090".to_owned()) || a.labels.contains(&"0.009".to_owned()),
            "{:?}",
            a.labels
        );
        let a = LinearAxis::new(2.5e-5, 3.5e-5, 5, false);
        assert!(
            a.labels.iter().all(|l| l.contains('e') || l == "0"),
            "{:?}",
            a.labels
        );
        let a = LinearAxis::new(5.0, 5.0, 5, false);
        assert!(a.lo < 5.0 && a.hi > 5.0);
        let a = LinearAxis::new(0.0, 0.0, 5, true);
        assert_eq!(a.lo, 0.0);
        assert!(a.hi >= 1.0);
        let a = LinearAxis::new(0.0, 1000.0, 8, true);
        assert_eq!(a.labels.first().map(String::as_str), Some("0"));
        assert_eq!(a.labels.last().map(String::as_str), Some("1000"));
        let a = LinearAxis::new(f64::NAN, f64::INFINITY, 5, false);
        assert!(a.lo.is_finite() && a.hi.is_finite());
        let l = LogAxis::new(90.0, 1100.0);
        assert!(l.labelled.contains(&100.0) && l.labelled.contains(&1000.0));
        let l = LogAxis::new(1e-3, 1e12);
        assert!(l.labelled.len() <= 10);
        assert_eq!(fmt_tick(1e7), "1e7");
        assert_eq!(fmt_tick(2.5e-5), "2.5e-5");
        assert_eq!(fmt_tick(0.01), "0.01");
        assert_eq!(fmt_tick(850.0000000001), "850");
        assert_eq!(fmt_tick(0.85), "0.85");
        let l = LogAxis::new(860.0, 1000.0);
        assert!(l.labelled.len() >= 3, "{:?}", l.labelled);
    }
}
