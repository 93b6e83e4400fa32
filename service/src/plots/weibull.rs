//! The Weibull probability plot of a life analysis.

use std::fmt::Write as _;

use bouncewear_model::life::fits::Fit;
use bouncewear_model::life::{
    KaplanMeierPoint, LifeAnalysis, Weibull, median_ranks, weibull_scale,
};

use super::axes::{
    Frame, Legend, LogAxis, Scale, draw_frame_axes, draw_log_x_axis, draw_no_data, widen_log,
};
use super::svg::{
    AXIS, BLUE, GRID, INK, LABEL, RED, SERIES, SMALL, Style, Svg, fmt_percent, fmt_sig, num,
    text_width, wrap,
};
use super::{pick_evenly, segments};

/// At most this many failure times are drawn, evenly picked: one point per distinct failure time
/// can mean tens of thousands.
const MAX_POINTS: usize = 1500;
/// Greenwood bounds are drawn as bars up to this many points.
const MAX_BARS: usize = 60;
/// The colour of the best fit's curve when it is not the two-parameter Weibull.
const BEST: &str = SERIES[1];

/// A failure time at its median rank.
type Point<'a> = (&'a KaplanMeierPoint, f64);

/// Where the plot draws: log time across, `ln(-ln(1 - F))` up, and their pixel scales.
struct Plane {
    frame: Frame,
    x_axis: LogAxis,
    xs: Scale,
    ys: Scale,
    /// The `ln(-ln(1 - F))` range shown.
    y_lo: f64,
    y_hi: f64,
}

impl Plane {
    fn x_of_t(&self, t: f64) -> f64 {
        self.xs.map(t.log10())
    }

    /// Where a failure time `t` at unreliability `f` is drawn, in pixels (`f` held in the range).
    fn point_at(&self, t: f64, f: f64) -> (f64, f64) {
        let y = weibull_scale(f).clamp(self.y_lo, self.y_hi);
        (self.x_of_t(t), self.ys.map(y))
    }

    /// A point of `ln t` and `y`, in pixels.
    fn at_ln(&self, ln_t: f64, y: f64) -> (f64, f64) {
        (self.xs.map(ln_t / std::f64::consts::LN_10), self.ys.map(y))
    }
}

/// A Weibull probability plot of `life`: the median rank of each failure time (Bernard's
/// approximation on Johnson's adjusted ranks, as reliability tools plot censored data; the last
/// failure too, which Kaplan-Meier would put at `F = 1`, off the scale) with the Kaplan-Meier
/// Greenwood bounds as bars when there are few, the maximum-likelihood line and its pointwise 95 % bounds on time (delta method on `ln t_p`
/// with `covariance_ln`), on log time against `ln(-ln(1 - F))` labelled in percent. Annotated
/// with beta, eta and B10. Without a fit, the points (if any) and `weibull_error`.
pub fn weibull_svg(life: &LifeAnalysis) -> String {
    weibulls_svg(
        "Weibull probability plot: operations to failure",
        &[("", life)],
    )
}

/// The Weibull probability plots of several designs' lives on one plane, each in its colour,
/// annotated with each design's beta, eta and B10.
pub fn compared_weibull_svg(designs: &[(&str, &LifeAnalysis)]) -> String {
    weibulls_svg("Weibull probability plots compared", designs)
}

/// One design as the plot draws it: its usable fit, its points (thinned) and its colours.
struct Drawn<'a> {
    name: &'a str,
    life: &'a LifeAnalysis,
    fit: Option<&'a Weibull>,
    usable: usize,
    points: Vec<Point<'a>>,
    dots: &'static str,
    line: &'static str,
}

/// Each design's fit (if drawable), its usable points thinned to its share of [`MAX_POINTS`],
/// and its colours: ink and blue alone, a series colour each among several.
fn drawn_designs<'a>(designs: &[(&'a str, &'a LifeAnalysis)]) -> Vec<Drawn<'a>> {
    let alone = designs.len() == 1;
    designs
        .iter()
        .enumerate()
        .map(|(i, &(name, life))| {
            let usable = usable_points(life);
            let colour = SERIES[i % SERIES.len()];
            Drawn {
                name,
                life,
                fit: life.weibull.as_ref().filter(|w| {
                    w.beta.is_finite() && w.beta > 0.0 && w.eta.is_finite() && w.eta > 0.0
                }),
                usable: usable.len(),
                points: pick_evenly(usable.len(), MAX_POINTS / designs.len().max(1))
                    .into_iter()
                    .map(|k| usable[k])
                    .collect(),
                dots: if alone { INK } else { colour },
                line: if alone { BLUE } else { colour },
            }
        })
        .collect()
}

fn weibulls_svg(title: &str, designs: &[(&str, &LifeAnalysis)]) -> String {
    let alone = designs.len() == 1;
    let drawn = drawn_designs(designs);
    // One design's notes go in a box over the plot's empty corner; several designs' would hide
    // their points, so they go above the plot.
    let notes: Vec<(String, &'static str)> =
        drawn.iter().flat_map(|d| design_notes(d, alone)).collect();
    let above = if alone {
        0.0
    } else {
        notes.len() as f64 * 17.0 + 16.0
    };
    let (width, height) = (760.0, 480.0 + above);
    let frame = Frame::inset(0.0, 0.0, width, height, [70.0, 70.0 + above, 28.0, 58.0]);
    let plane = plane(frame, &drawn);

    let mut svg = Svg::new(width, height, title);
    svg.title(title, 16.0, 24.0);
    draw_percent_grid(&mut svg, &plane);
    draw_log_x_axis(&mut svg, &plane.frame, &plane.x_axis, &plane.xs);
    let mut legend = Legend::new(plane.frame.left, 48.0);
    legend.dot(&mut svg, INK, "median ranks (Bernard, Johnson-adjusted)");
    let mut bounds = false;
    for d in &drawn {
        if let Some(w) = d.fit {
            bounds |= draw_fit(&mut svg, &plane, w, d.line);
        }
    }
    if drawn.iter().any(|d| d.fit.is_some()) {
        legend.line(
            &mut svg,
            if alone { BLUE } else { INK },
            None,
            "Weibull MLE",
        );
    }
    // One design whose lives another distribution fits clearly better: that fit's curve too,
    // named in the notes in its colour.
    if alone
        && let [d] = drawn.as_slice()
        && let Some(best) = better_fit(d.life)
    {
        draw_cdf(&mut svg, &plane, best);
    }
    if bounds {
        let colour = if alone { BLUE } else { INK };
        legend.line(
            &mut svg,
            colour,
            Some("5 4"),
            "95 % bounds on time (Fisher)",
        );
    }
    for d in &drawn {
        draw_points(&mut svg, &plane, &d.points, d.dots);
    }
    draw_frame_axes(&mut svg, &plane.frame);
    if alone {
        let [bx, by] = empty_corner(&plane, &drawn, notes_size(&notes));
        draw_notes(&mut svg, bx, by, &notes);
    } else {
        draw_notes(&mut svg, frame.left, 62.0, &notes);
    }
    if drawn.iter().all(|d| d.fit.is_none() && d.points.is_empty()) {
        draw_no_data(&mut svg, &plane.frame, "No failures to plot");
    }

    svg.text(
        frame.left + frame.width / 2.0,
        height - 14.0,
        "operations to failure (log scale)",
        LABEL,
    );
    svg.y_label(
        16.0,
        frame.top + frame.height / 2.0,
        "unreliability F (Weibull scale)",
    );
    svg.finish()
}

/// A design's lines of the annotation, each with its colour: its name when there are several,
/// the fit or why there is none (red), the counts, and how many points are shown.
fn design_notes(d: &Drawn, alone: bool) -> Vec<(String, &'static str)> {
    let mut notes = Vec::new();
    if !alone {
        notes.push((d.name.to_owned(), d.line));
    }
    let fit_lines = fit_notes(d.life, d.fit);
    let colour = if d.fit.is_none() { RED } else { INK };
    notes.extend(fit_lines.into_iter().map(|line| (line, colour)));
    if d.fit.is_some()
        && let Some(best) = better_fit(d.life)
    {
        let (how, colour) = if alone {
            (" (dotted)", BEST)
        } else {
            ("", INK)
        };
        notes.push((
            format!(
                "Best fit by AICc: {}{how}, not this Weibull",
                best.distribution.name()
            ),
            colour,
        ));
    }
    notes.push((
        format!("{} failed, {} censored", d.life.failures, d.life.censored),
        INK,
    ));
    if d.points.len() < d.usable {
        notes.push((
            format!(
                "{} of {} failure times shown, evenly spaced",
                d.points.len(),
                d.usable
            ),
            INK,
        ));
    }
    notes
}

/// Each failure time at its median rank, always inside `0 < F < 1`.
fn usable_points(life: &LifeAnalysis) -> Vec<Point<'_>> {
    let ranks = median_ranks(&life.kaplan_meier, life.failures + life.censored);
    life.kaplan_meier
        .iter()
        .zip(ranks)
        .filter(|&(p, f)| p.time.is_finite() && p.time > 0.0 && f > 0.0 && f < 1.0)
        .collect()
}

/// The ranges: up, 1 % to 99 % at least, widened to the points (within 0.01 % and 99.99 %);
/// across, the points and the fits between B10 and eta, widened to whole decades.
fn plane(frame: Frame, designs: &[Drawn]) -> Plane {
    let (y_min_cap, y_max_cap) = (weibull_scale(1e-4), weibull_scale(1.0 - 1e-4));
    let mut y_lo = weibull_scale(0.01);
    let mut y_hi = weibull_scale(0.99);
    let mut t_lo = f64::INFINITY;
    let mut t_hi = f64::NEG_INFINITY;
    for d in designs {
        for &(p, f) in &d.points {
            let y = weibull_scale(f).clamp(y_min_cap, y_max_cap);
            y_lo = y_lo.min(y);
            y_hi = y_hi.max(y);
            t_lo = t_lo.min(p.time);
            t_hi = t_hi.max(p.time);
        }
        if let Some(w) = d.fit {
            let candidates = if d.points.is_empty() {
                [w.quantile(0.01), w.quantile(0.99)]
            } else {
                [w.quantile(0.10), Some(w.eta)]
            };
            for t in candidates.into_iter().flatten() {
                t_lo = t_lo.min(t);
                t_hi = t_hi.max(t);
            }
        }
    }
    y_lo -= 0.15;
    y_hi += 0.15;
    if !(t_lo.is_finite() && t_hi.is_finite() && t_lo > 0.0) {
        t_lo = 1.0;
        t_hi = 1000.0;
    }
    let (t_lo, t_hi) = widen_log(t_lo, t_hi);
    let x_axis = LogAxis::new(t_lo, t_hi);
    let xs = x_axis.scale(frame.left, frame.right());
    let ys = Scale::new(y_lo, y_hi, frame.bottom(), frame.top);
    Plane {
        frame,
        x_axis,
        xs,
        ys,
        y_lo,
        y_hi,
    }
}

/// Percent lines across, labelled where they are not crowded; 63.2 % (eta) dashed.
fn draw_percent_grid(svg: &mut Svg, plane: &Plane) {
    let frame = &plane.frame;
    let percents = [
        0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 50.0, 63.2, 90.0, 99.0,
        99.9, 99.99,
    ];
    let mut last_label = f64::INFINITY;
    for &pc in &percents {
        let y = weibull_scale(pc / 100.0);
        if y < plane.y_lo || y > plane.y_hi {
            continue;
        }
        let py = plane.ys.map(y);
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
}

/// The fitted line `ln(-ln(1 - F)) = beta (ln t - ln eta)` in `colour`, clipped to the frame,
/// over its bounds on time (drawn first, under it); whether there were bounds to draw.
fn draw_fit(svg: &mut Svg, plane: &Plane, w: &Weibull, colour: &str) -> bool {
    let (lx0, lx1) = (plane.x_axis.lo.ln(), plane.x_axis.hi.ln());
    let (y_lo, y_hi) = (plane.y_lo, plane.y_hi);
    let (ln_eta, beta) = (w.eta.ln(), w.beta);
    let steps = 120;
    let mut lower = Vec::new();
    let mut upper = Vec::new();
    for k in 0..=steps {
        let y = y_lo + (y_hi - y_lo) * k as f64 / steps as f64;
        let inside = |lt: f64| (lt >= lx0 && lt <= lx1).then_some(lt);
        let to_px = |lt: f64| plane.at_ln(lt, y);
        let bounds = w
            .quantile_bounds_at_scale(y)
            .map(|[lo, hi]| (lo.ln(), hi.ln()));
        lower.push(bounds.and_then(|(lo, _)| inside(lo)).map(to_px));
        upper.push(bounds.and_then(|(_, hi)| inside(hi)).map(to_px));
    }
    let has_bounds = lower.iter().chain(&upper).any(Option::is_some);
    for curve in [&lower, &upper] {
        for segment in segments(curve) {
            svg.polyline(&segment, colour, 1.2, Some("5 4"));
        }
    }
    let a = lx0.max(ln_eta + y_lo / beta);
    let b = lx1.min(ln_eta + y_hi / beta);
    if a < b {
        let p0 = plane.at_ln(a, beta * (a - ln_eta));
        let p1 = plane.at_ln(b, beta * (b - ln_eta));
        svg.polyline(&[p0, p1], colour, 2.2, None);
    }
    has_bounds
}

/// The distribution that fits the lives clearly better than the Weibull line (`fit_warning`'s).
fn better_fit(life: &LifeAnalysis) -> Option<&Fit> {
    bouncewear_model::life::fits::better_than_weibull(&life.fits).map(|(fit, _)| fit)
}

/// `fit`'s CDF as a curve on the Weibull scale, clipped to the frame.
fn draw_cdf(svg: &mut Svg, plane: &Plane, fit: &Fit) {
    let (lx0, lx1) = (plane.x_axis.lo.ln(), plane.x_axis.hi.ln());
    let steps = 240;
    let curve: Vec<Option<(f64, f64)>> = (0..=steps)
        .map(|k| {
            let ln_t = lx0 + (lx1 - lx0) * f64::from(k) / f64::from(steps);
            let y = (-(-fit.cdf(ln_t.exp())).ln_1p()).ln();
            (y.is_finite() && y >= plane.y_lo && y <= plane.y_hi).then(|| plane.at_ln(ln_t, y))
        })
        .collect();
    for segment in segments(&curve) {
        svg.polyline(&segment, BEST, 2.0, Some("2 3"));
    }
}

/// The points, with their Greenwood bounds as thin bars when there are few.
fn draw_points(svg: &mut Svg, plane: &Plane, points: &[Point], colour: &str) {
    let (y_lo, y_hi) = (plane.y_lo, plane.y_hi);
    if points.len() <= MAX_BARS {
        for (p, _) in points {
            if let Some([lo, hi]) = p.ci95 {
                let f_lo = (1.0 - hi).clamp(1e-4, 1.0 - 1e-4);
                let f_hi = (1.0 - lo).clamp(1e-4, 1.0 - 1e-4);
                let x = plane.x_of_t(p.time);
                let y0 = plane.ys.map(weibull_scale(f_lo).clamp(y_lo, y_hi));
                let y1 = plane.ys.map(weibull_scale(f_hi).clamp(y_lo, y_hi));
                svg.line(x, y0, x, y1, AXIS, 1.0, None);
            }
        }
    }
    let r = if points.len() > 200 { 2.2 } else { 3.2 };
    let mut dots = String::new();
    for &(p, f) in points {
        let (x, y) = plane.point_at(p.time, f);
        let _ = write!(
            dots,
            r#"<circle cx="{}" cy="{}" r="{r}" fill="{colour}" fill-opacity="0.85"/>"#,
            num(x),
            num(y)
        );
    }
    if !dots.is_empty() {
        svg.raw(&dots);
    }
}

/// What the annotation says of the fit: beta, eta and B10 with their intervals, or why there is
/// no fit.
fn fit_notes(life: &LifeAnalysis, fit: Option<&Weibull>) -> Vec<String> {
    let mut notes = Vec::new();
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
            // The bounds to judge by: the likelihood ratio's, honest with few failures (the
            // delta method's showed 906 [894, 918] for 5 failures of 200, the ratio's 898-931).
            match &life.b10 {
                Some(b) => notes.push(format!(
                    "B10 = {} [{}, {}] operations",
                    fmt_sig(b.value, 4),
                    fmt_sig(b.bounds()[0], 4),
                    fmt_sig(b.bounds()[1], 4)
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
    notes
}

/// The annotation box's width and height.
fn notes_size(notes: &[(String, &'static str)]) -> [f64; 2] {
    let box_w = notes
        .iter()
        .map(|(s, _)| text_width(s, 12.0))
        .fold(0.0, f64::max)
        + 20.0;
    [box_w, notes.len() as f64 * 17.0 + 10.0]
}

/// Where a box of `size` goes over the plot: its top left corner, where lives rise from the
/// bottom left; its bottom right where that would hide more of the points (all failures at one
/// time are one point in the middle of the top, which the note saying why there is no fit hid).
fn empty_corner(plane: &Plane, drawn: &[Drawn], [box_w, box_h]: [f64; 2]) -> [f64; 2] {
    let frame = &plane.frame;
    let top_left = [frame.left + 10.0, frame.top + 10.0];
    let bottom_right = [frame.right() - 10.0 - box_w, frame.bottom() - 10.0 - box_h];
    let hidden = |[bx, by]: [f64; 2]| {
        let points = drawn.iter().flat_map(|d| &d.points);
        points
            .filter(|&&(p, f)| {
                let (x, y) = plane.point_at(p.time, f);
                (bx..=bx + box_w).contains(&x) && (by..=by + box_h).contains(&y)
            })
            .count()
    };
    if hidden(bottom_right) < hidden(top_left) {
        bottom_right
    } else {
        top_left
    }
}

/// The annotation box with its top left at `(bx, by)`, each line in its colour.
fn draw_notes(svg: &mut Svg, bx: f64, by: f64, notes: &[(String, &'static str)]) {
    let [box_w, box_h] = notes_size(notes);
    let _ = write!(
        svg.out,
        r##"<rect x="{}" y="{}" width="{}" height="{}" rx="4" fill="#ffffff" fill-opacity="0.92" stroke="{GRID}"/>"##,
        num(bx),
        num(by),
        num(box_w),
        num(box_h)
    );
    svg.out.push('\n');
    for (k, (line, colour)) in notes.iter().enumerate() {
        let style = Style {
            anchor: "start",
            fill: colour,
            ..LABEL
        };
        svg.text(bx + 10.0, by + 20.0 + 17.0 * k as f64, line, style);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plots::fixtures::{check, uniform};
    use bouncewear_model::life::{BLife, analyse};

    fn life_of(data: &[(f64, bool)]) -> LifeAnalysis {
        analyse(data)
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
        // B10's bounds are the ones to judge by, the likelihood ratio's.
        let b10 = life.b10.as_ref().unwrap();
        let [lo, hi] = b10.lr_ci95.unwrap();
        let bounds = format!("[{}, {}] operations", fmt_sig(lo, 4), fmt_sig(hi, 4));
        assert!(svg.contains(&bounds), "{bounds} missing");
    }

    /// Lives with a failure-free 800 operations: the three-parameter Weibull fits them clearly
    /// better, and the plot draws its curve, dotted in its colour, named in the notes in that
    /// colour; the straight line stays the two-parameter Weibull's.
    #[test]
    fn weibull_plot_draws_a_clearly_better_fit() {
        let data: Vec<(f64, bool)> = weibull_data(300, 2.0, 300.0, 700.0)
            .into_iter()
            .map(|(t, failed)| (t + 800.0, failed))
            .collect();
        let life = life_of(&data);
        assert!(life.fit_warning.is_some(), "{:?}", life.fits);
        assert_eq!(life.fits[0].distribution.name(), "weibull_3p");
        let svg = weibull_svg(&life);
        check(&svg);
        assert!(svg.contains("Best fit by AICc: weibull_3p (dotted), not this Weibull"));
        assert!(
            svg.contains(&format!(r#"fill="{BEST}""#)),
            "the note in the curve's colour"
        );
        assert!(
            svg.matches(&format!(r#"stroke="{BEST}""#)).count() >= 1,
            "the curve"
        );
        // Without the warning, no curve.
        let plain = weibull_svg(&life_of(&weibull_data(300, 2.0, 800.0, 1000.0)));
        assert!(!plain.contains(BEST), "{plain}");
    }

    #[test]
    fn weibull_plot_shows_every_failure_time_of_a_complete_sample() {
        // Every device fails: Kaplan-Meier would put the last one at F = 1, off the scale; at its
        // median rank it is drawn with the others.
        let life = life_of(&weibull_data(50, 0.4, 1e5, f64::INFINITY));
        let svg = weibull_svg(&life);
        check(&svg);
        let legend_dots = 1;
        assert_eq!(
            svg.matches("<circle").count(),
            life.kaplan_meier.len() + legend_dots
        );
        assert!(svg.contains("median ranks (Bernard, Johnson-adjusted)"));
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

        // Every device failing at one time is one point in the middle of the top: the note
        // saying why there is no fit goes where it hides it not (it did: a probe).
        let all_at_once = life_of(&[(1.0, true); 30]);
        let svg = weibull_svg(&all_at_once);
        check(&svg);
        let attribute = |element: &str, name: &str| -> f64 {
            let after = &element[element.find(&format!(" {name}=\"")).unwrap() + name.len() + 3..];
            after[..after.find('"').unwrap()].parse().unwrap()
        };
        // The point, not the legend's dot.
        let dot_fill = svg.find(r#"fill-opacity="0.85""#).unwrap();
        let circle = &svg[svg[..dot_fill].rfind("<circle").unwrap()..];
        let (cx, cy) = (attribute(circle, "cx"), attribute(circle, "cy"));
        let box_fill = svg.find(r#"fill-opacity="0.92""#).unwrap();
        let note = &svg[svg[..box_fill].rfind("<rect").unwrap()..];
        let (x, y) = (attribute(note, "x"), attribute(note, "y"));
        let (w, h) = (attribute(note, "width"), attribute(note, "height"));
        assert!(
            !((x..=x + w).contains(&cx) && (y..=y + h).contains(&cy)),
            "the point ({cx}, {cy}) under the note {x} {y} {w} {h}"
        );
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
            lr_ci95: None,
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

    #[test]
    fn weibull_plots_of_two_designs_overlaid() {
        let a = life_of(&weibull_data(200, 2.0, 800.0, 1000.0));
        let b = life_of(&weibull_data(200, 4.0, 600.0, 1000.0));
        let svg = compared_weibull_svg(&[("a: long", &a), ("b: short", &b)]);
        check(&svg);
        assert!(svg.contains("Weibull probability plots compared"));
        assert!(svg.contains(">a: long<") && svg.contains(">b: short<"));
        assert_eq!(svg.matches("\u{3b2} = ").count(), 2);
        assert!(svg.contains(&format!(r#"fill="{}" fill-opacity="0.85""#, SERIES[1])));
        // A design without failures is named with its reason; the other is drawn.
        let none = life_of(&[(100.0, false), (100.0, false)]);
        let svg = compared_weibull_svg(&[("a", &a), ("b", &none)]);
        check(&svg);
        assert!(svg.contains("No Weibull fit"));
        assert!(!svg.contains("No failures to plot"));
    }
}
