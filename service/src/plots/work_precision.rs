//! Work-precision panels: what a result costs against how precise it is, both on log axes,
//! since the tiers and sample sizes they compare are decades apart.

use super::axes::{
    Frame, Legend, LogAxis, draw_frame_axes, draw_log_x_axis, draw_log_y_grid, draw_no_data,
    widen_log,
};
use super::message_svg;
use super::svg::{LABEL, SERIES, Style, Svg};

/// One line of a panel, drawn through its points in order.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Its name in the legend.
    pub name: String,
    /// `(x, y)`; points that a log axis cannot show (zero, negative, not finite) are left out.
    pub points: Vec<(f64, f64)>,
}

/// One panel of a work-precision plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
}

/// `panels` side by side under `title`, each with log axes over every decade its points span (a
/// tier that is exact to 1e-16 and one that is off by 1e-2 both stay on the plot) and a legend of
/// its series.
pub fn work_precision_svg(title: &str, panels: &[Panel]) -> String {
    if panels.is_empty() {
        return message_svg(title, "No measurements to plot.");
    }
    let (panel_w, height) = (480.0, 440.0);
    let width = panel_w * panels.len() as f64;
    let mut svg = Svg::new(width, height, title);
    svg.title(title, 16.0, 24.0);
    for (k, panel) in panels.iter().enumerate() {
        let px = panel_w * k as f64;
        let frame = Frame::inset(px, 0.0, panel_w, height, [78.0, 92.0, 24.0, 56.0]);
        svg.open_g(r#"class="panel""#);
        draw_panel(&mut svg, &frame, panel);
        svg.text(
            px + 16.0,
            52.0,
            &panel.title,
            Style {
                anchor: "start",
                bold: true,
                ..LABEL
            },
        );
        svg.text(
            frame.left + frame.width / 2.0,
            height - 14.0,
            &panel.x_label,
            LABEL,
        );
        svg.y_label(px + 18.0, frame.top + frame.height / 2.0, &panel.y_label);
        svg.close_g();
    }
    svg.finish()
}

fn draw_panel(svg: &mut Svg, frame: &Frame, panel: &Panel) {
    let shown = |&(x, y): &(f64, f64)| x.is_finite() && x > 0.0 && y.is_finite() && y > 0.0;
    let series: Vec<(&str, Vec<(f64, f64)>)> = panel
        .series
        .iter()
        .map(|s| {
            (
                s.name.as_str(),
                s.points.iter().copied().filter(shown).collect(),
            )
        })
        .collect();
    let all = || series.iter().flat_map(|(_, points)| points.iter().copied());
    let range = |values: Vec<f64>| {
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let (lo, hi) = if lo <= hi { (lo, hi) } else { (1.0, 10.0) };
        widen_log(lo, hi)
    };
    let (x_lo, x_hi) = range(all().map(|p| p.0).collect());
    let (y_lo, y_hi) = range(all().map(|p| p.1).collect());
    let x_axis = LogAxis::whole(x_lo, x_hi);
    let y_axis = LogAxis::whole(y_lo, y_hi);
    let xs = x_axis.scale(frame.left, frame.right());
    let ys = y_axis.scale(frame.bottom(), frame.top);
    draw_log_y_grid(svg, frame, &y_axis, &ys);
    draw_log_x_axis(svg, frame, &x_axis, &xs);

    let mut legend = Legend::new(frame.left, 74.0);
    for (k, (name, points)) in series.iter().enumerate() {
        let colour = SERIES[k % SERIES.len()];
        let px: Vec<(f64, f64)> = points
            .iter()
            .map(|&(x, y)| (xs.map(x.log10()), ys.map(y.log10())))
            .collect();
        svg.polyline(&px, colour, 2.0, None);
        for &(x, y) in &px {
            svg.circle(x, y, 3.5, colour, "#ffffff", 1.0);
        }
        legend.line(svg, colour, None, name);
    }
    if all().next().is_none() {
        draw_no_data(svg, frame, "No measurements to plot");
    }
    draw_frame_axes(svg, frame);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plots::fixtures::check;

    fn series(name: &str, points: &[(f64, f64)]) -> Series {
        Series {
            name: name.to_owned(),
            points: points.to_vec(),
        }
    }

    fn panel(title: &str, series: Vec<Series>) -> Panel {
        Panel {
            title: title.to_owned(),
            x_label: "relative error".to_owned(),
            y_label: "ns per operation".to_owned(),
            series,
        }
    }

    #[test]
    fn work_precision_of_tiers_and_samplers() {
        let tiers = panel(
            "Tiers",
            vec![
                series("exact", &[(1e-17, 900.0), (2e-16, 900.0)]),
                series("closed_form", &[(3e-3, 120.0), (2e-2, 120.0)]),
            ],
        );
        let sampling = panel(
            "Sampling",
            vec![
                series("random", &[(0.08, 0.01), (0.04, 0.03), (0.02, 0.1)]),
                series("lhs", &[(0.05, 0.01), (0.025, 0.03), (0.012, 0.1)]),
            ],
        );
        let svg = work_precision_svg("Speed against error", &[tiers, sampling]);
        check(&svg);
        assert_eq!(svg.matches("class=\"panel\"").count(), 2);
        for text in [
            ">Tiers<",
            ">Sampling<",
            ">exact<",
            ">closed_form<",
            ">random<",
            ">lhs<",
        ] {
            assert!(svg.contains(text), "{text} missing");
        }
        // Fifteen decades apart, the exact and the closed-form tier are both inside the first
        // frame (x from 78 to 456 px); the samplers inside the second (558 to 936 px).
        let xs: Vec<f64> = svg
            .split("<circle cx=\"")
            .skip(1)
            .map(|rest| rest[..rest.find('"').unwrap()].parse().unwrap())
            .collect();
        assert_eq!(xs.len(), 10);
        assert!(xs[..4].iter().all(|x| (78.0..=456.0).contains(x)), "{xs:?}");
        assert!(
            xs[4..].iter().all(|x| (558.0..=936.0).contains(x)),
            "{xs:?}"
        );
    }

    #[test]
    fn work_precision_of_degenerate_panels() {
        check(&work_precision_svg("Nothing", &[]));
        assert!(work_precision_svg("Nothing", &[]).contains("No measurements"));
        let unusable = panel(
            "Zeros",
            vec![series(
                "none",
                &[
                    (0.0, 1.0),
                    (-1.0, 2.0),
                    (f64::NAN, 3.0),
                    (1.0, f64::INFINITY),
                ],
            )],
        );
        let svg = work_precision_svg("Odd", &[unusable]);
        check(&svg);
        assert!(svg.contains("No measurements to plot"));
        let single = panel(
            "One",
            vec![series("one", &[(0.5, 0.5)]), series("empty", &[])],
        );
        check(&work_precision_svg("Single", &[single]));
    }
}
