//! A calibration's fit: measured against simulated, one panel per measured quantity.

use super::axes::{
    Frame, LinearAxis, Scale, draw_frame_axes, draw_no_data, draw_x_ticks, draw_y_grid,
};
use super::svg::{BLUE, MUTED, SMALL, Svg};
use super::{extent, pad};
use bouncewear_model::calibration::{Calibration, CalibrationSpec};

/// One measured quantity of a calibration: `(measured, simulated)` per observation that
/// measured it.
#[derive(Debug, Clone, PartialEq)]
pub struct FitPanel {
    pub quantity: String,
    pub points: Vec<(f64, f64)>,
}

/// The panels of a calibration: for each quantity with residuals, each measurement against the
/// fitted model's simulation (`measured + residual`).
pub fn calibration_panels(spec: &CalibrationSpec, fit: &Calibration) -> Vec<FitPanel> {
    fit.residuals
        .iter()
        .map(|(quantity, residuals)| FitPanel {
            quantity: quantity.clone(),
            points: spec
                .observations
                .iter()
                .filter_map(|o| o.measured(quantity))
                .zip(&residuals.values)
                .map(|(measured, residual)| (measured, measured + residual))
                .collect(),
        })
        .collect()
}

/// Panels of simulated (y) against measured (x), three to a row, each with the line where the
/// two are equal (dashed): a point above it is a quantity the fitted model overestimates.
pub fn calibration_svg(panels: &[FitPanel]) -> String {
    let title = "Calibration: simulated against measured";
    let columns = panels.len().clamp(1, 3);
    let rows = panels.len().div_ceil(3).max(1);
    let (panel_w, panel_h) = (320.0, 300.0);
    let (width, height) = (panel_w * columns as f64, 40.0 + panel_h * rows as f64);
    let mut svg = Svg::new(width, height, title);
    svg.title(title, 16.0, 24.0);
    for (k, panel) in panels.iter().enumerate() {
        let (x0, y0) = (panel_w * (k % 3) as f64, 40.0 + panel_h * (k / 3) as f64);
        let frame = Frame::inset(x0, y0, panel_w, panel_h, [72.0, 24.0, 28.0, 48.0]);
        svg.text(x0 + panel_w / 2.0, y0 + 14.0, &panel.quantity, SMALL);
        let finite: Vec<(f64, f64)> = panel
            .points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        // One range for both axes, so that the equality line is the diagonal.
        let (lo, hi) = extent(finite.iter().flat_map(|&(x, y)| [x, y]));
        let (lo, hi) = pad(lo, hi, 0.05);
        let axis = LinearAxis::new(lo, hi, 5, false);
        let xs = Scale::new(axis.lo, axis.hi, frame.left, frame.right());
        let ys = Scale::new(axis.lo, axis.hi, frame.bottom(), frame.top);
        draw_y_grid(&mut svg, &frame, &axis, &ys);
        draw_x_ticks(&mut svg, &frame, &axis, &xs, false);
        draw_frame_axes(&mut svg, &frame);
        if finite.is_empty() {
            draw_no_data(&mut svg, &frame, "no measurements");
            continue;
        }
        svg.polyline(
            &[
                (xs.map(axis.lo), ys.map(axis.lo)),
                (xs.map(axis.hi), ys.map(axis.hi)),
            ],
            MUTED,
            1.0,
            Some("4 3"),
        );
        for &(x, y) in &finite {
            svg.circle(xs.map(x), ys.map(y), 3.5, BLUE, "white", 0.8);
        }
        svg.text(
            frame.left + frame.width / 2.0,
            frame.bottom() + 36.0,
            "measured",
            SMALL,
        );
        svg.y_label(x0 + 14.0, frame.top + frame.height / 2.0, "simulated");
    }
    svg.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_panel_is_drawn_and_no_number_is_lost() {
        let panels = [
            FitPanel {
                quantity: "first_bounce_s".into(),
                points: vec![(0.01, 0.0101), (0.008, 0.0079)],
            },
            FitPanel {
                quantity: "e1".into(),
                points: vec![(f64::NAN, 0.4)],
            },
        ];
        let svg = calibration_svg(&panels);
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert!(svg.contains("first_bounce_s") && svg.contains("no measurements"));
        assert_eq!(svg.matches("<circle").count(), 2);
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
    }
}
