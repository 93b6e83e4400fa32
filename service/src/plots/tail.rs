//! A rare event's tail curve: `P(metric beyond t)` against `t` on a log probability axis, the
//! estimate at the asked threshold with its 95 % interval.

use super::axes::{
    Frame, Legend, LinearAxis, LogAxis, Scale, draw_frame_axes, draw_log_y_grid, draw_x_ticks,
};
use super::svg::{BLUE, LABEL, MUTED, RED, Svg};
use super::{extent, message_svg, pad};
use bouncewear_model::montecarlo::RareEventReport;

/// The tail curve of `report` for `metric` (`beyond`: "above" or "below").
pub fn tail_svg(metric: &str, beyond: &str, report: &RareEventReport) -> String {
    let title = format!(
        "P({metric} {beyond} t): {} by {}",
        super::svg::fmt_sig(report.probability, 3),
        report.method
    );
    let points: Vec<(f64, f64)> = report
        .tail
        .iter()
        .map(|p| (p.threshold, p.probability))
        .filter(|(t, p)| t.is_finite() && p.is_finite() && *p > 0.0)
        .collect();
    if points.is_empty() {
        return message_svg(
            &title,
            "No sample reached the threshold: the tail has no point.",
        );
    }
    // The estimate at the threshold asked, the tail's last point: 0 where nothing was beyond it.
    let (t, p) = report
        .tail
        .last()
        .map(|last| (last.threshold, report.probability))
        .filter(|(t, p)| t.is_finite() && p.is_finite())
        .unwrap_or(*points.last().expect("not empty"));
    let (width, height) = (760.0, 380.0);
    let frame = Frame::inset(0.0, 0.0, width, height, [78.0, 62.0, 24.0, 58.0]);
    let (lo, hi) = pad_x(extent(points.iter().map(|p| p.0).chain([t])));
    let x_axis = LinearAxis::new(lo, hi, 6, false);
    let xs = Scale::new(x_axis.lo, x_axis.hi, frame.left, frame.right());
    let [ci_lo, ci_hi] = report.ci95;
    let probabilities = points
        .iter()
        .map(|p| p.1)
        .chain([ci_lo, ci_hi].into_iter().filter(|p| *p > 0.0));
    let (p_lo, p_hi) = extent(probabilities);
    // An estimate of 0 sits on the floor a decade below everything drawn, so that its interval
    // reaches up from it to its upper bound (its floor was that bound, the bar of no length).
    let p_lo = if p > 0.0 { p_lo } else { p_lo / 10.0 };
    let y_axis = LogAxis::whole(p_lo, p_hi.max(p_lo * 10.0));
    let ys = y_axis.scale(frame.bottom(), frame.top);

    let mut svg = Svg::new(width, height, &title);
    svg.title(&title, 16.0, 24.0);
    draw_log_y_grid(&mut svg, &frame, &y_axis, &ys);
    draw_x_ticks(&mut svg, &frame, &x_axis, &xs, true);
    let line: Vec<(f64, f64)> = points
        .iter()
        .map(|&(t, p)| (xs.map(t), ys.map(p.log10())))
        .collect();
    svg.polyline(&line, BLUE, 1.8, None);
    for &(x, y) in &line {
        svg.circle(x, y, 3.5, BLUE, "#ffffff", 1.0);
    }
    // The estimate with its interval; an estimate of 0 sits on the axis's floor, its interval
    // reaching up from there to its upper bound.
    let x = xs.map(t);
    let y_of = |p: f64| match p > 0.0 {
        true => ys.map(p.log10()),
        false => frame.bottom(),
    };
    if ci_hi > 0.0 && ci_hi.is_finite() {
        let (ya, yb) = (y_of(ci_lo), y_of(ci_hi));
        svg.line(x, ya, x, yb, RED, 1.4, None);
        if ci_lo > 0.0 {
            svg.line(x - 5.0, ya, x + 5.0, ya, RED, 1.4, None);
        }
        svg.line(x - 5.0, yb, x + 5.0, yb, RED, 1.4, None);
    }
    svg.circle(x, y_of(p), 4.5, RED, "#ffffff", 1.0);
    draw_frame_axes(&mut svg, &frame);
    svg.text(
        frame.left + frame.width / 2.0,
        height - 10.0,
        &format!("threshold t of {metric}"),
        LABEL,
    );
    svg.y_label(
        18.0,
        frame.top + frame.height / 2.0,
        "probability per device",
    );
    let mut legend = Legend::new(frame.left, 46.0);
    legend.dot(&mut svg, BLUE, "levels");
    legend.line(&mut svg, RED, None, "estimate, 95 % interval");
    legend.line(
        &mut svg,
        MUTED,
        None,
        &format!("{} evaluations", report.evaluations),
    );
    svg.finish()
}

/// The x range padded, and widened around a single threshold.
fn pad_x((lo, hi): (f64, f64)) -> (f64, f64) {
    if hi > lo {
        return pad(lo, hi, 0.05);
    }
    let half = (lo.abs() * 0.05).max(f64::MIN_POSITIVE);
    (lo - half, hi + half)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plots::fixtures::check;
    use bouncewear_model::montecarlo::rare::TailPoint;
    use std::collections::BTreeMap;

    fn report(tail: &[(f64, f64)], ci95: [f64; 2]) -> RareEventReport {
        RareEventReport {
            probability: tail.last().map_or(0.0, |p| p.1),
            ci95,
            cov: Some(0.1),
            evaluations: 5400,
            method: "subset".into(),
            beta: Some(3.7),
            design_point: BTreeMap::new(),
            tail: tail
                .iter()
                .map(|&(threshold, probability)| TailPoint {
                    threshold,
                    probability,
                })
                .collect(),
        }
    }

    #[test]
    fn a_tail_of_levels_down_to_1e_minus_6() {
        let tail: Vec<(f64, f64)> = (1..=6)
            .map(|k| (0.0125 + 0.0004 * k as f64, 10f64.powi(-k)))
            .collect();
        let svg = tail_svg("total_bounce_s", "above", &report(&tail, [6e-7, 1.6e-6]));
        check(&svg);
        assert!(svg.contains("P(total_bounce_s above t)"));
        assert!(svg.contains("5400 evaluations"));
    }

    /// The number an SVG element's line gives its attribute `name`.
    fn number(line: &str, name: &str) -> f64 {
        let start = line.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
        line[start..].split('"').next().unwrap().parse().unwrap()
    }

    /// An estimate of 0 (a crude run with nothing beyond the threshold) sits at the threshold
    /// asked, beyond the last level, on the axis's floor under its upper bound; it sat on the
    /// last level with a positive share, and the axis stopped short of the threshold (a probe).
    #[test]
    fn an_estimate_of_zero_sits_at_the_threshold_asked() {
        let tail = [(0.0121, 0.1), (0.0131, 0.01), (0.0137, 1e-3), (0.0218, 0.0)];
        let svg = tail_svg("total_bounce_s", "above", &report(&tail, [0.0, 3.688e-4]));
        check(&svg);
        let circles: Vec<(f64, f64, f64)> = svg
            .lines()
            .filter(|line| line.starts_with("<circle"))
            .map(|line| (number(line, "cx"), number(line, "cy"), number(line, "r")))
            .collect();
        // The levels' points (r 3.5), the estimate (r 4.5), below the legend's row (y 46).
        let drawn = |r: f64| -> Vec<&(f64, f64, f64)> {
            circles.iter().filter(|c| c.2 == r && c.1 > 50.0).collect()
        };
        let (levels, estimate) = (drawn(3.5), drawn(4.5));
        assert_eq!((levels.len(), estimate.len()), (3, 1), "{svg}");
        let last_level = levels.iter().map(|c| c.0).fold(f64::MIN, f64::max);
        let lowest_level = levels.iter().map(|c| c.1).fold(f64::MIN, f64::max);
        assert!(estimate[0].0 > last_level + 100.0, "{circles:?}");
        assert!(estimate[0].1 > lowest_level, "{circles:?}");
        // Its interval a red line up from it, of some length (it was none: a re-probe).
        let bar = svg
            .lines()
            .filter(|line| line.starts_with("<line") && line.contains(RED))
            .map(|line| (number(line, "x1"), number(line, "y1"), number(line, "y2")))
            .find(|&(x, ..)| (x - estimate[0].0).abs() < 1e-9)
            .expect("the interval's line");
        assert!(bar.1 - bar.2 > 20.0, "{bar:?}");
    }

    #[test]
    fn degenerate_tails_still_draw() {
        check(&tail_svg("x", "below", &report(&[], [0.0, 3e-5])));
        check(&tail_svg(
            "x",
            "above",
            &report(&[(1.0, 1e-3)], [8e-4, 1.2e-3]),
        ));
        check(&tail_svg("x", "above", &report(&[(0.0, 0.0)], [0.0, 1e-4])));
        check(&tail_svg(
            "x",
            "above",
            &report(&[(f64::NAN, 1e-3), (2.0, 1e-4)], [0.0, 1.0]),
        ));
    }
}
