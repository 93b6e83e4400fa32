//! Standalone SVG plots for the dashboard: a job's per-bin histograms and wear curve, a Weibull
//! probability plot of a life analysis, and a schedule's night-by-night trend.
//!
//! Every function returns one complete SVG document (`<svg ...>` to `</svg>\n`) with a white
//! background, a `viewBox` and its own `width`/`height`, so it can be served as `image/svg+xml`
//! or injected into a page as it is. Text is escaped; non-finite inputs are skipped and every
//! division is guarded, so no `NaN` or `inf` reaches the output, whatever the input (empty slices,
//! all-equal values, zero counts). No `id` attributes are used, so several plots can share a page.

use std::fmt::Write as _;

use bouncewear_model::life::{KaplanMeierPoint, LifeAnalysis, weibull_scale};
use bouncewear_model::montecarlo::{Bin, JobResult};

const FONT: &str =
    "system-ui, -apple-system, 'Segoe UI', Roboto, 'Helvetica Neue', Arial, sans-serif";
const INK: &str = "#111827";
const MUTED: &str = "#4b5563";
const GRID: &str = "#e5e7eb";
const AXIS: &str = "#9ca3af";
const BLUE: &str = "#2563eb";
const BAND: &str = "#bfdbfe";
const BAR: &str = "#60a5fa";
const RED: &str = "#dc2626";

// ---------------------------------------------------------------------------------------------
// Public API
// ---------------------------------------------------------------------------------------------

/// Why a job has no plot of the kind asked for: the caller's choice of plot or metric, not a fault.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("the job has no operation metric `{0}`")]
    NoMetric(String),
    #[error("the job has no failure criteria, so no Weibull plot")]
    NoLifeAnalysis,
    #[error("no plot `{0}`: bands.svg, histograms.svg or weibull.svg")]
    NoSuchPlot(String),
}

/// The plot `kind` (`bands.svg`, `histograms.svg` or `weibull.svg`) of a job's result, by the
/// file name the dashboard and `bouncewear run --plots` both use.
pub fn job_plot(result: &JobResult, kind: &str, metric: &str) -> Result<String, PlotError> {
    let bins = || {
        result
            .operations
            .get(metric)
            .ok_or_else(|| PlotError::NoMetric(metric.to_owned()))
    };
    match kind {
        "bands.svg" => Ok(quantile_bands_svg(metric, bins()?)),
        "histograms.svg" => Ok(histograms_svg(metric, bins()?)),
        "weibull.svg" => match &result.life {
            Some(life) => Ok(weibull_svg(&life.analysis)),
            None => Err(PlotError::NoLifeAnalysis),
        },
        other => Err(PlotError::NoSuchPlot(other.to_owned())),
    }
}

/// Small multiples of the histogram of `metric` in each bin of operations (at most 12 panels,
/// evenly spaced over the bins when there are more, as the title says), on a shared x axis. Each
/// panel marks the median and, when the metric has a limit, the limit.
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

    let n = chosen.len();
    let cols = ((n as f64).sqrt().ceil() as usize).clamp(1, 4);
    let rows = n.div_ceil(cols);
    let (panel_w, panel_h) = (250.0, 178.0);
    let (outer_left, outer_top, outer_bottom, outer_right) = (34.0, 66.0, 44.0, 12.0);
    let width = outer_left + panel_w * cols as f64 + outer_right;
    let height = outer_top + panel_h * rows as f64 + outer_bottom;

    // A shared x axis, so the panels compare at a glance.
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &i in &chosen {
        let s = &bins[i].summary;
        for &e in s.histogram.edges.iter().chain(limit_of(s).iter()) {
            if e.is_finite() {
                lo = lo.min(e);
                hi = hi.max(e);
            }
        }
    }
    let (lo, hi) = pad(lo, hi, 0.04);
    let x_axis = LinearAxis::new(lo, hi, 4, false);
    let limit_shown = chosen.iter().any(|&i| limit_of(&bins[i].summary).is_some());

    let mut svg = Svg::new(width, height, &title);
    svg.title(&title, 12.0, 22.0);
    let mut subtitle =
        String::from("Bars: counts of operations in equal-width classes; dark line: median (p50)");
    if limit_shown {
        subtitle.push_str("; red dashed: limit");
    }
    svg.text(12.0, 42.0, &subtitle, MUTED_SMALL);

    for (k, &i) in chosen.iter().enumerate() {
        let bin = &bins[i];
        let s = &bin.summary;
        let (col, row) = (k % cols, k / cols);
        let px = outer_left + panel_w * col as f64;
        let py = outer_top + panel_h * row as f64;
        let frame = Frame {
            left: px + 44.0,
            top: py + 24.0,
            width: panel_w - 44.0 - 12.0,
            height: panel_h - 24.0 - 32.0,
        };
        svg.open_g(&format!(
            r#"class="panel" data-op-start="{}" data-op-end="{}""#,
            bin.op_start, bin.op_end
        ));
        svg.text(
            px + 8.0,
            py + 14.0,
            &format!("operations {}\u{2013}{}", bin.op_start, bin.op_end),
            Style {
                anchor: "start",
                bold: true,
                ..LABEL
            },
        );
        svg.text(
            frame.right(),
            py + 14.0,
            &format!("n = {}", s.n),
            Style {
                anchor: "end",
                ..MUTED_SMALL
            },
        );

        let count = |c: u64| c as f64;
        let bars = s
            .histogram
            .counts
            .len()
            .min(s.histogram.edges.len().saturating_sub(1));
        let max_count = s.histogram.counts[..bars]
            .iter()
            .copied()
            .max()
            .unwrap_or(0)
            .max(1);
        let y_axis = LinearAxis::new(0.0, count(max_count), 3, true);
        let xs = Scale::new(x_axis.lo, x_axis.hi, frame.left, frame.right());
        let ys = Scale::new(y_axis.lo, y_axis.hi, frame.bottom(), frame.top);
        draw_y_grid(&mut svg, &frame, &y_axis, &ys);
        draw_x_ticks(&mut svg, &frame, &x_axis, &xs, false);

        let mut bars_g = String::new();
        for b in 0..bars {
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
            let y = ys.map(count(c));
            let _ = write!(
                bars_g,
                r#"<rect x="{}" y="{}" width="{}" height="{}" fill="{BAR}" stroke="{BLUE}" stroke-width="0.5"/>"#,
                num(x0),
                num(y),
                num(x1 - x0),
                num(frame.bottom() - y)
            );
        }
        if !bars_g.is_empty() {
            svg.raw(&bars_g);
        }
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
        draw_frame_axes(&mut svg, &frame);
        svg.close_g();
    }

    // Shared axis labels.
    svg.text(
        outer_left + panel_w * cols as f64 / 2.0,
        height - 12.0,
        metric,
        LABEL,
    );
    svg.text(
        14.0,
        outer_top + panel_h * rows as f64 / 2.0,
        "count",
        Style {
            rotate: -90.0,
            ..LABEL
        },
    );
    svg.finish()
}

/// The wear curve of `metric`: per bin of operations (at the bin's midpoint), a band from p05 to
/// p95, the median, the mean (dashed) and the limit when there is one, with a legend.
pub fn quantile_bands_svg(metric: &str, bins: &[Bin]) -> String {
    let title = format!("{metric}: wear curve over the test");
    struct Row {
        x: f64,
        p05: Option<f64>,
        p50: Option<f64>,
        p95: Option<f64>,
        mean: Option<f64>,
    }
    let rows: Vec<Row> = bins
        .iter()
        .filter(|b| b.summary.n > 0)
        .map(|b| Row {
            x: (b.op_start as f64 + b.op_end as f64) / 2.0,
            p05: quantile(&b.summary, "p05"),
            p50: quantile(&b.summary, "p50"),
            p95: quantile(&b.summary, "p95"),
            mean: finite(b.summary.mean),
        })
        .filter(|r| r.x.is_finite())
        .collect();
    if rows.is_empty() {
        return message_svg(&title, "No operations to plot.");
    }
    let limit = bins.iter().find_map(|b| limit_of(&b.summary));

    let (width, height) = (760.0, 420.0);
    let frame = Frame {
        left: 78.0,
        top: 70.0,
        width: width - 78.0 - 24.0,
        height: height - 70.0 - 56.0,
    };
    let x_lo = bins
        .iter()
        .map(|b| b.op_start as f64)
        .fold(f64::INFINITY, f64::min);
    let x_hi = bins
        .iter()
        .map(|b| b.op_end as f64)
        .fold(f64::NEG_INFINITY, f64::max);
    let x_axis = LinearAxis::new(x_lo, x_hi, 8, true);
    let ys_values = rows
        .iter()
        .flat_map(|r| [r.p05, r.p50, r.p95, r.mean])
        .chain([limit])
        .flatten();
    let (y_lo, y_hi) = extent(ys_values);
    let (y_lo, y_hi) = pad(y_lo, y_hi, 0.05);
    let y_axis = LinearAxis::new(y_lo, y_hi, 6, false);
    let xs = Scale::new(x_axis.lo, x_axis.hi, frame.left, frame.right());
    let ys = Scale::new(y_axis.lo, y_axis.hi, frame.bottom(), frame.top);

    let mut svg = Svg::new(width, height, &title);
    svg.title(&title, 16.0, 24.0);
    draw_y_grid(&mut svg, &frame, &y_axis, &ys);
    draw_x_ticks(&mut svg, &frame, &x_axis, &xs, false);

    // The band: p95 forwards, p05 backwards, over the bins that have both.
    let band: Vec<(f64, f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((xs.map(r.x), ys.map(r.p05?), ys.map(r.p95?))))
        .collect();
    match band.len() {
        0 => {}
        1 => {
            let (x, y05, y95) = band[0];
            svg.rect(
                x - 6.0,
                y95.min(y05),
                12.0,
                (y05 - y95).abs().max(1.0),
                BAND,
                None,
            );
        }
        _ => {
            let mut pts: Vec<(f64, f64)> = band.iter().map(|&(x, _, y95)| (x, y95)).collect();
            pts.extend(band.iter().rev().map(|&(x, y05, _)| (x, y05)));
            let _ = write!(
                svg.out,
                r#"<polygon points="{}" fill="{BAND}" stroke="{BAND}" stroke-width="1"/>"#,
                points(&pts)
            );
            svg.out.push('\n');
        }
    }
    if let Some(limit) = limit {
        let y = ys.map(limit);
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
    let median: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((xs.map(r.x), ys.map(r.p50?))))
        .collect();
    let mean: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((xs.map(r.x), ys.map(r.mean?))))
        .collect();
    svg.polyline(&mean, INK, 1.5, Some("6 4"));
    svg.polyline(&median, BLUE, 2.2, None);
    if median.len() <= 40 {
        for &(x, y) in &median {
            svg.circle(x, y, 3.0, BLUE, "#ffffff", 1.2);
        }
    }
    draw_frame_axes(&mut svg, &frame);
    svg.text(
        frame.left + frame.width / 2.0,
        height - 14.0,
        "operation",
        LABEL,
    );
    svg.text(
        18.0,
        frame.top + frame.height / 2.0,
        metric,
        Style {
            rotate: -90.0,
            ..LABEL
        },
    );

    let mut legend = Legend::new(frame.left, 48.0);
    legend.swatch(&mut svg, BAND, "p05\u{2013}p95 (90 % of operations)");
    legend.line(&mut svg, BLUE, None, "median (p50)");
    legend.line(&mut svg, INK, Some("6 4"), "mean");
    if limit.is_some() {
        legend.line(&mut svg, RED, Some("6 4"), "limit");
    }
    svg.finish()
}

/// A Weibull probability plot of `life`: Kaplan-Meier unreliability `1 - R` at each failure time,
/// the maximum-likelihood line and its pointwise 95 % bounds on time (delta method on `ln t_p`
/// with `covariance_ln`), on log time against `ln(-ln(1 - F))` labelled in percent. Annotated
/// with beta, eta and B10. Without a fit, the points (if any) and `weibull_error`.
pub fn weibull_svg(life: &LifeAnalysis) -> String {
    let title = "Weibull probability plot: operations to failure";
    let (width, height) = (760.0, 480.0);
    let frame = Frame {
        left: 70.0,
        top: 70.0,
        width: width - 70.0 - 28.0,
        height: height - 70.0 - 58.0,
    };
    let fit = life
        .weibull
        .as_ref()
        .filter(|w| w.beta.is_finite() && w.beta > 0.0 && w.eta.is_finite() && w.eta > 0.0);

    // Kaplan-Meier points with 0 < F < 1: F = 1 (R = 0) has no place on the Weibull scale.
    let usable = |p: &&KaplanMeierPoint| {
        let f = 1.0 - p.reliability;
        p.time.is_finite() && p.time > 0.0 && f > 0.0 && f < 1.0
    };
    let usable_points: Vec<&KaplanMeierPoint> = life.kaplan_meier.iter().filter(usable).collect();
    let omitted = life.kaplan_meier.len() - usable_points.len();
    // One step per distinct failure time can mean tens of thousands: draw an even selection.
    const MAX_POINTS: usize = 1500;
    let points: Vec<&KaplanMeierPoint> = pick_evenly(usable_points.len(), MAX_POINTS)
        .into_iter()
        .map(|i| usable_points[i])
        .collect();

    // y range: 1 % to 99 % at least, widened to the points (within 0.01 % and 99.99 %).
    let (y_min_cap, y_max_cap) = (weibull_scale(1e-4), weibull_scale(1.0 - 1e-4));
    let mut y_lo = weibull_scale(0.01);
    let mut y_hi = weibull_scale(0.99);
    for p in &points {
        let y = weibull_scale(1.0 - p.reliability).clamp(y_min_cap, y_max_cap);
        y_lo = y_lo.min(y);
        y_hi = y_hi.max(y);
    }
    y_lo -= 0.15;
    y_hi += 0.15;

    // x range: the points, and the fit between B10 and eta; then clamped to 8 decades.
    let mut t_lo = f64::INFINITY;
    let mut t_hi = f64::NEG_INFINITY;
    for p in &points {
        t_lo = t_lo.min(p.time);
        t_hi = t_hi.max(p.time);
    }
    if let Some(w) = fit {
        let candidates = if points.is_empty() {
            [w.quantile(0.01), w.quantile(0.99)]
        } else {
            [w.quantile(0.10), Some(w.eta)]
        };
        for t in candidates.into_iter().flatten() {
            t_lo = t_lo.min(t);
            t_hi = t_hi.max(t);
        }
    }
    if !(t_lo.is_finite() && t_hi.is_finite() && t_lo > 0.0) {
        t_lo = 1.0;
        t_hi = 1000.0;
    }
    let margin = (t_hi / t_lo).powf(0.06).max(1.04);
    let x_axis = LogAxis::new(t_lo / margin, t_hi * margin);
    let xs = Scale::new(
        x_axis.lo.log10(),
        x_axis.hi.log10(),
        frame.left,
        frame.right(),
    );
    let ys = Scale::new(y_lo, y_hi, frame.bottom(), frame.top);
    let x_of_t = |t: f64| xs.map(t.log10());

    let mut svg = Svg::new(width, height, title);
    svg.title(title, 16.0, 24.0);

    // Grid: percent lines and log-time ticks.
    let percents = [
        0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 50.0, 63.2, 90.0, 99.0,
        99.9, 99.99,
    ];
    let mut last_label = f64::INFINITY;
    for &pc in &percents {
        let y = weibull_scale(pc / 100.0);
        if y < y_lo || y > y_hi {
            continue;
        }
        let py = ys.map(y);
        let dash = (pc == 63.2).then_some("2 3");
        svg.line(frame.left, py, frame.right(), py, GRID, 1.0, dash);
        if last_label - py < 13.0 {
            continue;
        }
        last_label = py;
        svg.text(
            frame.left - 8.0,
            py + 4.0,
            &format!("{} %", fmt_percent(pc)),
            Style {
                anchor: "end",
                ..SMALL
            },
        );
    }
    for &(t, major) in &x_axis.grid {
        let x = x_of_t(t);
        svg.line(
            x,
            frame.top,
            x,
            frame.bottom(),
            if major { GRID } else { "#f3f4f6" },
            1.0,
            None,
        );
    }
    for &t in &x_axis.labelled {
        let x = x_of_t(t);
        svg.line(x, frame.bottom(), x, frame.bottom() + 5.0, AXIS, 1.0, None);
        svg.text(x, frame.bottom() + 18.0, &fmt_tick(t), SMALL);
    }

    let (lx0, lx1) = (x_axis.lo.ln(), x_axis.hi.ln());
    let mut legend = Legend::new(frame.left, 48.0);
    legend.dot(&mut svg, INK, "Kaplan\u{2013}Meier 1 \u{2212} R");

    if let Some(w) = fit {
        let (ln_eta, beta) = (w.eta.ln(), w.beta);
        // Bounds first, under the line.
        let steps = 120;
        let mut lower = Vec::new();
        let mut upper = Vec::new();
        for k in 0..=steps {
            let y = y_lo + (y_hi - y_lo) * k as f64 / steps as f64;
            let inside = |lt: f64| (lt >= lx0 && lt <= lx1).then_some(lt);
            let to_px = |lt: f64| (xs.map(lt / std::f64::consts::LN_10), ys.map(y));
            let bounds = w
                .quantile_bounds_at_scale(y)
                .map(|[lo, hi]| (lo.ln(), hi.ln()));
            lower.push(bounds.and_then(|(lo, _)| inside(lo)).map(to_px));
            upper.push(bounds.and_then(|(_, hi)| inside(hi)).map(to_px));
        }
        let has_bounds = lower.iter().chain(&upper).any(Option::is_some);
        for curve in [&lower, &upper] {
            for segment in segments(curve) {
                svg.polyline(&segment, BLUE, 1.2, Some("5 4"));
            }
        }
        // The line ln(-ln(1-F)) = beta (ln t - ln eta), clipped to the frame.
        let a = lx0.max(ln_eta + y_lo / beta);
        let b = lx1.min(ln_eta + y_hi / beta);
        if a < b {
            let p0 = (
                xs.map(a / std::f64::consts::LN_10),
                ys.map(beta * (a - ln_eta)),
            );
            let p1 = (
                xs.map(b / std::f64::consts::LN_10),
                ys.map(beta * (b - ln_eta)),
            );
            svg.polyline(&[p0, p1], BLUE, 2.2, None);
        }
        legend.line(&mut svg, BLUE, None, "Weibull MLE");
        if has_bounds {
            legend.line(&mut svg, BLUE, Some("5 4"), "95 % bounds on time (Fisher)");
        }
    }

    // Points, with Greenwood bounds as thin bars when there are few.
    if points.len() <= 60 {
        for p in &points {
            if let Some([lo, hi]) = p.ci95 {
                let f_lo = (1.0 - hi).clamp(1e-4, 1.0 - 1e-4);
                let f_hi = (1.0 - lo).clamp(1e-4, 1.0 - 1e-4);
                let x = x_of_t(p.time);
                let y0 = ys.map(weibull_scale(f_lo).clamp(y_lo, y_hi));
                let y1 = ys.map(weibull_scale(f_hi).clamp(y_lo, y_hi));
                svg.line(x, y0, x, y1, AXIS, 1.0, None);
            }
        }
    }
    let r = if points.len() > 200 { 2.2 } else { 3.2 };
    let mut dots = String::new();
    for p in &points {
        let y = weibull_scale(1.0 - p.reliability).clamp(y_lo, y_hi);
        let _ = write!(
            dots,
            r#"<circle cx="{}" cy="{}" r="{r}" fill="{INK}" fill-opacity="0.85"/>"#,
            num(x_of_t(p.time)),
            num(ys.map(y))
        );
    }
    if !dots.is_empty() {
        svg.raw(&dots);
    }
    draw_frame_axes(&mut svg, &frame);

    // Annotation box, top left (where a rising line leaves room).
    let mut notes: Vec<String> = Vec::new();
    match fit {
        Some(w) => {
            notes.push(format!(
                "\u{3b2} = {} [{}, {}]",
                fmt_sig(w.beta, 3),
                fmt_sig(w.beta_ci95[0], 3),
                fmt_sig(w.beta_ci95[1], 3)
            ));
            notes.push(format!(
                "\u{3b7} = {} [{}, {}] operations",
                fmt_sig(w.eta, 4),
                fmt_sig(w.eta_ci95[0], 4),
                fmt_sig(w.eta_ci95[1], 4)
            ));
            match &life.b10 {
                Some(b) => notes.push(format!(
                    "B10 = {} [{}, {}] operations",
                    fmt_sig(b.value, 4),
                    fmt_sig(b.ci95[0], 4),
                    fmt_sig(b.ci95[1], 4)
                )),
                None => {
                    if let Some(t) = w.quantile(0.10) {
                        notes.push(format!("B10 = {} operations", fmt_sig(t, 4)));
                    }
                }
            }
        }
        None => {
            let reason = life
                .weibull_error
                .as_deref()
                .unwrap_or("the fit is not available");
            notes.push("No Weibull fit:".to_owned());
            notes.extend(wrap(reason, 52));
        }
    }
    let error_lines = if fit.is_none() { notes.len() } else { 0 };
    notes.push(format!(
        "{} failed, {} censored",
        life.failures, life.censored
    ));
    if omitted > 0 {
        notes.push(format!("{omitted} point(s) at F = 100 % not shown"));
    }
    if points.len() < usable_points.len() {
        notes.push(format!(
            "{} of {} Kaplan\u{2013}Meier points shown, evenly spaced",
            points.len(),
            usable_points.len()
        ));
    }
    let box_w = notes
        .iter()
        .map(|s| text_width(s, 12.0))
        .fold(0.0, f64::max)
        + 20.0;
    let box_h = notes.len() as f64 * 17.0 + 10.0;
    let (bx, by) = (frame.left + 10.0, frame.top + 10.0);
    let _ = write!(
        svg.out,
        r##"<rect x="{}" y="{}" width="{}" height="{}" rx="4" fill="#ffffff" fill-opacity="0.92" stroke="{GRID}"/>"##,
        num(bx),
        num(by),
        num(box_w),
        num(box_h)
    );
    svg.out.push('\n');
    for (k, line) in notes.iter().enumerate() {
        let style = if k < error_lines {
            Style {
                anchor: "start",
                fill: RED,
                ..LABEL
            }
        } else {
            Style {
                anchor: "start",
                ..LABEL
            }
        };
        svg.text(bx + 10.0, by + 20.0 + 17.0 * k as f64, line, style);
    }
    if fit.is_none() && points.is_empty() {
        svg.text(
            frame.left + frame.width / 2.0,
            frame.top + frame.height / 2.0,
            "No failures to plot",
            Style {
                size: 13.0,
                fill: MUTED,
                ..LABEL
            },
        );
    }

    svg.text(
        frame.left + frame.width / 2.0,
        height - 14.0,
        "operations to failure (log scale)",
        LABEL,
    );
    svg.text(
        16.0,
        frame.top + frame.height / 2.0,
        "unreliability F (Weibull scale)",
        Style {
            rotate: -90.0,
            ..LABEL
        },
    );
    svg.finish()
}

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
/// with a ring; x labels rotated and thinned when there are many.
pub fn trend_svg(title: &str, y_label: &str, points: &[TrendPoint]) -> String {
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
    let frame = Frame {
        left,
        top: 62.0,
        width: width - left - 24.0,
        height: height - 62.0 - bottom,
    };
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

    // x labels, thinned to about one per 22 px (rotated) or per label width (flat).
    let per_label = if rotate { 22.0 } else { longest + 10.0 };
    let every = ((per_label / slot.max(1e-9)).ceil() as usize).max(1);
    for (k, p) in points.iter().enumerate() {
        let x = x_of(k);
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

    // Error bars, the line, then the points.
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
    svg.text(frame.left + frame.width / 2.0, height - 10.0, "run", LABEL);
    svg.text(
        18.0,
        frame.top + frame.height / 2.0,
        y_label,
        Style {
            rotate: -90.0,
            ..LABEL
        },
    );
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

// ---------------------------------------------------------------------------------------------
// Data helpers
// ---------------------------------------------------------------------------------------------

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn quantile(s: &bouncewear_model::stats::Summary, key: &str) -> Option<f64> {
    s.quantiles.get(key).and_then(|q| finite(q.value))
}

fn limit_of(s: &bouncewear_model::stats::Summary) -> Option<f64> {
    s.exceedance.as_ref().and_then(|e| finite(e.limit))
}

/// At most `max` indices of `0..len`, evenly spaced, first and last included.
fn pick_evenly(len: usize, max: usize) -> Vec<usize> {
    if len <= max || max < 2 {
        return (0..len.min(max.max(1))).collect();
    }
    let mut out: Vec<usize> = (0..max)
        .map(|i| (i * (len - 1) + (max - 1) / 2) / (max - 1))
        .collect();
    out.dedup();
    out
}

/// `[lo, hi]` widened by `share` of its width on both sides (nothing when it is empty).
fn pad(lo: f64, hi: f64, share: f64) -> (f64, f64) {
    let width = hi - lo;
    if width.is_finite() && width > 0.0 {
        (lo - width * share, hi + width * share)
    } else {
        (lo, hi)
    }
}

/// Min and max of finite values; `(0, 1)` when there are none.
fn extent(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo <= hi { (lo, hi) } else { (0.0, 1.0) }
}

/// Runs of consecutive `Some` points, each with at least two points.
fn segments(points: &[Option<(f64, f64)>]) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut current = Vec::new();
    for p in points {
        match p {
            Some(p) => current.push(*p),
            None => {
                if current.len() >= 2 {
                    out.push(std::mem::take(&mut current));
                }
                current.clear();
            }
        }
    }
    if current.len() >= 2 {
        out.push(current);
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Scales and ticks
// ---------------------------------------------------------------------------------------------

/// A linear map from a data domain to pixels; a zero-width domain maps to the range's middle.
#[derive(Clone, Copy)]
struct Scale {
    d0: f64,
    d1: f64,
    r0: f64,
    r1: f64,
}

impl Scale {
    fn new(d0: f64, d1: f64, r0: f64, r1: f64) -> Self {
        Scale { d0, d1, r0, r1 }
    }

    fn map(&self, v: f64) -> f64 {
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
struct LinearAxis {
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
    labels: Vec<String>,
}

impl LinearAxis {
    /// About `target` ticks over `[lo, hi]`; `integer` keeps steps whole (counts, operations).
    fn new(lo: f64, hi: f64, target: usize, integer: bool) -> Self {
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

/// Drops a zero exponent (`2.5e0` is `2.5`); `2.50e-4` stays.
fn trim_exponent(s: &str) -> String {
    match s.strip_suffix("e0") {
        Some(mantissa) => mantissa.to_owned(),
        None => s.to_owned(),
    }
}

/// A base-10 log axis: labelled ticks at decades (and at 2 and 5, or every integer multiple, when
/// the range is short), light grid lines at the multiples in between.
struct LogAxis {
    lo: f64,
    hi: f64,
    labelled: Vec<f64>,
    /// `(value, major)`.
    grid: Vec<(f64, bool)>,
}

impl LogAxis {
    fn new(lo: f64, hi: f64) -> Self {
        let mut lo = if lo.is_finite() && lo > 0.0 { lo } else { 1.0 };
        let mut hi = if hi.is_finite() && hi > lo {
            hi
        } else {
            lo * 10.0
        };
        // At most 8 decades, centred on the geometric middle.
        if hi / lo > 1e8 {
            let mid = (lo.log10() + hi.log10()) / 2.0;
            lo = 10f64.powf(mid - 4.0);
            hi = 10f64.powf(mid + 4.0);
        }
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

// ---------------------------------------------------------------------------------------------
// Number and text formatting
// ---------------------------------------------------------------------------------------------

/// `floor(log10(v))`, robust to `log10(1000) = 2.9999...`.
fn log10_floor(v: f64) -> f64 {
    (v.log10() + 1e-12).floor()
}

/// A pixel coordinate: at most two decimals, trailing zeros dropped; 0 if not finite.
fn num(v: f64) -> String {
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
fn fmt_sig(v: f64, digits: usize) -> String {
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

fn fmt_percent(pc: f64) -> String {
    if pc >= 1.0 && pc.fract() == 0.0 {
        format!("{pc:.0}")
    } else {
        let s = format!("{pc:.2}");
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    }
}

/// A log-axis tick, at most 6 significant digits with nothing trailing: plain between 1e-3 and
/// 1e6, else in exponent form (`2e7`).
fn fmt_tick(v: f64) -> String {
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

/// An estimate of the width of `s` in the sans-serif font at `size` px.
fn text_width(s: &str, size: f64) -> f64 {
    s.chars().count() as f64 * size * 0.56
}

fn truncate(s: &str, max: usize) -> String {
    if s.chars().count() <= max {
        s.to_owned()
    } else {
        let mut t: String = s.chars().take(max.saturating_sub(1)).collect();
        t.push('\u{2026}');
        t
    }
}

/// Greedy word wrap to lines of at most `width` characters (long words are cut).
fn wrap(s: &str, width: usize) -> Vec<String> {
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

/// Escapes text and attribute values.
fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c if c.is_control() => {}
            c => out.push(c),
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// SVG writing
// ---------------------------------------------------------------------------------------------

#[derive(Clone, Copy)]
struct Style {
    size: f64,
    anchor: &'static str,
    bold: bool,
    fill: &'static str,
    rotate: f64,
}

const LABEL: Style = Style {
    size: 12.0,
    anchor: "middle",
    bold: false,
    fill: INK,
    rotate: 0.0,
};
const SMALL: Style = Style {
    size: 11.0,
    fill: MUTED,
    ..LABEL
};
const MUTED_SMALL: Style = Style {
    anchor: "start",
    ..SMALL
};

/// The plotting area.
#[derive(Clone, Copy)]
struct Frame {
    left: f64,
    top: f64,
    width: f64,
    height: f64,
}

impl Frame {
    fn right(&self) -> f64 {
        self.left + self.width
    }
    fn bottom(&self) -> f64 {
        self.top + self.height
    }
}

struct Svg {
    out: String,
}

impl Svg {
    fn new(width: f64, height: f64, title: &str) -> Self {
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
        Svg { out }
    }

    fn title(&mut self, text: &str, x: f64, y: f64) {
        self.text(
            x,
            y,
            text,
            Style {
                size: 13.0,
                anchor: "start",
                bold: true,
                ..LABEL
            },
        );
    }

    fn text(&mut self, x: f64, y: f64, text: &str, style: Style) {
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
    fn line(
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

    fn rect(&mut self, x: f64, y: f64, w: f64, h: f64, fill: &str, stroke: Option<&str>) {
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

    fn circle(&mut self, x: f64, y: f64, r: f64, fill: &str, stroke: &str, w: f64) {
        let _ = writeln!(
            self.out,
            r#"<circle cx="{}" cy="{}" r="{}" fill="{fill}" stroke="{stroke}" stroke-width="{}"/>"#,
            num(x),
            num(y),
            num(r),
            num(w)
        );
    }

    fn polyline(&mut self, pts: &[(f64, f64)], color: &str, w: f64, dash: Option<&str>) {
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

    fn raw(&mut self, s: &str) {
        self.out.push_str(s);
        self.out.push('\n');
    }

    fn open_g(&mut self, attrs: &str) {
        let _ = writeln!(self.out, "<g {attrs}>");
    }

    fn close_g(&mut self) {
        self.out.push_str("</g>\n");
    }

    fn finish(mut self) -> String {
        self.out.push_str("</svg>\n");
        self.out
    }
}

fn points(pts: &[(f64, f64)]) -> String {
    let mut s = String::with_capacity(pts.len() * 14);
    for (k, &(x, y)) in pts.iter().enumerate() {
        if k > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{},{}", num(x), num(y));
    }
    s
}

/// Horizontal grid lines and labels of a y axis.
fn draw_y_grid(svg: &mut Svg, frame: &Frame, axis: &LinearAxis, ys: &Scale) {
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
fn draw_x_ticks(svg: &mut Svg, frame: &Frame, axis: &LinearAxis, xs: &Scale, grid: bool) {
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

/// The left and bottom axis lines.
fn draw_frame_axes(svg: &mut Svg, frame: &Frame) {
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

/// A plot with only a title and a message (no data).
fn message_svg(title: &str, message: &str) -> String {
    let (width, height) = (760.0, 200.0);
    let mut svg = Svg::new(width, height, title);
    svg.title(title, 16.0, 24.0);
    svg.rect(
        16.5,
        40.5,
        width - 33.0,
        height - 57.0,
        "#f9fafb",
        Some(GRID),
    );
    svg.text(
        width / 2.0,
        height / 2.0 + 16.0,
        message,
        Style {
            size: 13.0,
            fill: MUTED,
            ..LABEL
        },
    );
    svg.finish()
}

/// A one-row legend, items left to right.
struct Legend {
    x: f64,
    y: f64,
}

impl Legend {
    fn new(x: f64, y: f64) -> Self {
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

    fn swatch(&mut self, svg: &mut Svg, fill: &str, text: &str) {
        svg.rect(self.x, self.y - 6.0, 22.0, 12.0, fill, None);
        self.label(svg, 28.0, text);
    }

    fn line(&mut self, svg: &mut Svg, color: &str, dash: Option<&str>, text: &str) {
        svg.line(self.x, self.y, self.x + 22.0, self.y, color, 2.0, dash);
        self.label(svg, 28.0, text);
    }

    fn dot(&mut self, svg: &mut Svg, color: &str, text: &str) {
        svg.circle(self.x + 5.0, self.y, 3.5, color, "#ffffff", 1.0);
        self.label(svg, 14.0, text);
    }

    fn ring(&mut self, svg: &mut Svg, color: &str, text: &str) {
        svg.circle(self.x + 8.0, self.y, 7.0, "none", color, 1.8);
        svg.circle(self.x + 8.0, self.y, 3.5, color, "#ffffff", 1.0);
        self.label(svg, 20.0, text);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bouncewear_model::life::{BLife, analyse};
    use bouncewear_model::stats::{Exceedance, Histogram, QuantileSummary, Summary};
    use std::collections::BTreeMap;

    fn summary(values: &[f64], limit: Option<f64>) -> Summary {
        let n = values.len();
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let (min, max) = if n == 0 {
            (0.0, 0.0)
        } else {
            (sorted[0], sorted[n - 1])
        };
        let q = |p: f64| {
            if n == 0 {
                0.0
            } else {
                sorted[((p * (n - 1) as f64).round() as usize).min(n - 1)]
            }
        };
        let quantiles: BTreeMap<String, QuantileSummary> = [
            ("p01", 0.01),
            ("p05", 0.05),
            ("p10", 0.1),
            ("p25", 0.25),
            ("p50", 0.5),
            ("p75", 0.75),
            ("p90", 0.9),
            ("p95", 0.95),
            ("p99", 0.99),
        ]
        .iter()
        .map(|&(k, p)| {
            let v = q(p);
            (
                k.to_owned(),
                QuantileSummary {
                    value: v,
                    ci95: [v, v],
                },
            )
        })
        .collect();
        let classes = if n == 0 || min == max { 1 } else { 20 };
        let edges: Vec<f64> = (0..=classes)
            .map(|i| min + (max - min) * i as f64 / classes as f64)
            .collect();
        let mut counts = vec![0u64; classes];
        for &v in values {
            let i = if max > min {
                (((v - min) / (max - min)) * classes as f64) as usize
            } else {
                0
            };
            counts[i.min(classes - 1)] += 1;
        }
        let mean = if n == 0 {
            0.0
        } else {
            values.iter().sum::<f64>() / n as f64
        };
        Summary {
            n: n as u64,
            mean,
            mean_ci95: [mean, mean],
            sd: 0.0,
            min,
            max,
            quantiles,
            histogram: Histogram { edges, counts },
            exceedance: limit.map(|limit| Exceedance {
                limit,
                probability: 0.1,
                ci95: [0.05, 0.15],
            }),
        }
    }

    /// A deterministic pseudo-random stream in [0, 1).
    fn uniform(seed: u64, k: u64) -> f64 {
        let mut z = seed.wrapping_add(k.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 * 2f64.powi(-53)
    }

    fn wear_bins(count: usize, per_bin: u64, limit: Option<f64>) -> Vec<Bin> {
        (0..count)
            .map(|b| {
                let values: Vec<f64> = (0..200)
                    .map(|k| {
                        0.008 + 0.00001 * b as f64 + 0.002 * uniform(b as u64, k) * uniform(7, k)
                    })
                    .collect();
                Bin {
                    summary: summary(&values, limit),
                    op_start: b as u64 * per_bin,
                    op_end: (b as u64 + 1) * per_bin,
                }
            })
            .collect()
    }

    fn life_of(data: &[(f64, bool)]) -> LifeAnalysis {
        analyse(data)
    }

    /// The checks every plot must pass.
    fn check(svg: &str) {
        assert!(svg.starts_with("<svg"), "{svg}");
        assert!(svg.ends_with("</svg>\n"), "{svg}");
        assert!(svg.contains("viewBox=\"0 0 "));
        assert!(svg.contains("fill=\"#ffffff\""));
        assert!(!svg.contains("NaN"), "NaN in {svg}");
        assert!(!svg.contains("inf"), "inf in {svg}");
        let open = svg.matches("<g ").count() + svg.matches("<g>").count();
        assert_eq!(open, svg.matches("</g>").count(), "unbalanced <g>");
        assert_eq!(svg.matches("<svg").count(), 1);
        assert_eq!(svg.matches("</svg>").count(), 1);
        // Every element is closed: opening tags of container elements match their closes.
        for tag in ["text", "title"] {
            assert_eq!(
                svg.matches(&format!("<{tag} ")).count() + svg.matches(&format!("<{tag}>")).count(),
                svg.matches(&format!("</{tag}>")).count(),
                "unbalanced <{tag}>"
            );
        }
        // No stray markup in text: every '<' starts a known tag.
        for (i, _) in svg.match_indices('<') {
            let rest = &svg[i + 1..];
            assert!(
                [
                    "svg", "/svg", "title", "/title", "rect", "text", "/text", "line", "polyline",
                    "polygon", "circle", "g ", "g>", "/g>"
                ]
                .iter()
                .any(|t| rest.starts_with(t)),
                "unexpected tag at {}",
                &svg[i..(i + 20).min(svg.len())]
            );
        }
    }

    #[test]
    fn histograms_of_a_wear_test() {
        let bins = wear_bins(10, 100, Some(0.0095));
        let svg = histograms_svg("total_bounce_s", &bins);
        check(&svg);
        assert!(svg.contains("total_bounce_s: distribution per bin of operations"));
        assert!(svg.contains("operations 0\u{2013}100"));
        assert!(svg.contains("operations 900\u{2013}1000"));
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
        assert!(svg.contains("operations 0\u{2013}25"));
        assert!(svg.contains("operations 975\u{2013}1000"));
        assert_eq!(pick_evenly(40, 12).len(), 12);
        let v = pick_evenly(13, 12);
        assert_eq!((v.len(), v[0], v[11]), (12, 0, 12));
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

    fn weibull_data(n: u64, beta: f64, eta: f64, censor_at: f64) -> Vec<(f64, bool)> {
        (0..n)
            .map(|k| {
                let u = uniform(11, k).max(1e-12);
                let t = eta * (-(1.0 - u).ln()).powf(1.0 / beta);
                if t > censor_at {
                    (censor_at, false)
                } else {
                    (t.ceil().max(1.0), true)
                }
            })
            .collect()
    }

    #[test]
    fn weibull_plot_of_a_fit() {
        let life = life_of(&weibull_data(300, 2.0, 800.0, 1000.0));
        assert!(life.weibull.is_some(), "{:?}", life.weibull_error);
        let svg = weibull_svg(&life);
        check(&svg);
        for label in [
            "1 %",
            "5 %",
            "10 %",
            "20 %",
            "50 %",
            "90 %",
            "99 %",
            "\u{3b2} = ",
            "\u{3b7} = ",
            "B10 = ",
            "Weibull MLE",
            "95 % bounds",
        ] {
            assert!(svg.contains(label), "{label} missing");
        }
        assert!(svg.contains(">1000<") || svg.contains(">100<"));
        assert!(svg.matches("<circle").count() > 20);
    }

    #[test]
    fn weibull_plot_all_failed_and_wide() {
        // Every device fails: the last Kaplan-Meier point has F = 1 and is left out.
        let life = life_of(&weibull_data(50, 0.4, 1e5, f64::INFINITY));
        let svg = weibull_svg(&life);
        check(&svg);
        assert!(svg.contains("at F = 100 % not shown"));
        let life = life_of(&weibull_data(80, 12.0, 500.0, 520.0));
        check(&weibull_svg(&life));
    }

    #[test]
    fn weibull_plot_thins_many_points() {
        let data: Vec<(f64, bool)> = (1..=5000).map(|t| (f64::from(t), t % 2 == 0)).collect();
        let life = life_of(&data);
        assert!(life.kaplan_meier.len() > 2000);
        let svg = weibull_svg(&life);
        check(&svg);
        assert!(svg.contains("1500 of "));
        assert!(svg.matches("<circle").count() < 1600);
    }

    #[test]
    fn weibull_plot_without_a_fit() {
        let none = life_of(&[(100.0, false), (100.0, false)]);
        assert!(none.weibull.is_none());
        let svg = weibull_svg(&none);
        check(&svg);
        assert!(svg.contains("No Weibull fit"));
        assert!(svg.contains("no failures"));
        assert!(svg.contains("No failures to plot"));

        let single = life_of(&[(50.0, true), (50.0, true), (100.0, false)]);
        let svg = weibull_svg(&single);
        check(&svg);
        assert!(svg.contains("No Weibull fit"));
        assert!(svg.contains("<circle"));

        check(&weibull_svg(&life_of(&[])));
    }

    #[test]
    fn weibull_plot_of_odd_numbers() {
        let mut life = life_of(&weibull_data(100, 1.5, 300.0, 400.0));
        // A covariance that is not positive definite gives no bounds, and no NaN.
        if let Some(w) = life.weibull.as_mut() {
            w.covariance_ln = [[-1.0, 0.0], [0.0, -1.0]];
        }
        life.b10 = Some(BLife {
            p: 0.1,
            value: f64::NAN,
            ci95: [f64::INFINITY, 0.0],
        });
        let svg = weibull_svg(&life);
        check(&svg);
        assert!(!svg.contains("95 % bounds"));
        // A broken fit is treated as none.
        if let Some(w) = life.weibull.as_mut() {
            w.beta = f64::NAN;
        }
        check(&weibull_svg(&life));
        life.kaplan_meier[0].time = f64::INFINITY;
        life.kaplan_meier[1].reliability = f64::NAN;
        check(&weibull_svg(&life));
    }

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
        let svg = trend_svg("Nightly <wear> & \"drift\"", "p95 total_bounce_s", &points);
        check(&svg);
        assert!(svg.contains("Nightly &lt;wear&gt; &amp; &quot;drift&quot;"));
        assert!(svg.contains("2026-03-01"));
        assert!(svg.contains("2026-03-05"));
        assert!(svg.contains(">flagged<"));
        assert!(svg.contains(&format!("stroke=\"{RED}\"")));
        assert!(!svg.contains("rotate(-45"));
    }

    #[test]
    fn trend_of_many_nights_rotates_and_thins() {
        let points: Vec<TrendPoint> = (0..120)
            .map(|k| night(k % 28, 1.0 + (k as f64 * 0.3).sin(), k % 17 == 0))
            .collect();
        let svg = trend_svg("Nightly", "mean e1", &points);
        check(&svg);
        assert!(svg.contains("rotate(-45"));
        let labels = svg.matches("rotate(-45").count();
        assert!(labels < 60, "{labels} labels");
    }

    #[test]
    fn trend_of_degenerate_points() {
        check(&trend_svg("Empty", "x", &[]));
        assert!(trend_svg("Empty", "x", &[]).contains("No run has a value yet"));
        let flat: Vec<TrendPoint> = (0..3)
            .map(|_| TrendPoint {
                label: String::new(),
                value: 0.0,
                ci95: None,
                flagged: false,
            })
            .collect();
        check(&trend_svg("Flat", "x", &flat));
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
        check(&trend_svg("Odd", "x", &odd));
        let one = vec![night(0, 3.0, false)];
        check(&trend_svg("One", "x", &one));
    }

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
        assert_eq!(fmt_sig(1234.5, 3), "1234");
        assert_eq!(fmt_sig(2.345, 3), "2.35");
        assert_eq!(num(-0.001), "0");
    }
}
