//! Standalone SVG plots for the dashboard: a job's per-bin histograms and wear curve, a Weibull
//! probability plot of a life analysis, a sensitivity analysis's indices, a schedule's
//! night-by-night trend, a calibration's fit, and the benchmark's work-precision panels.
//!
//! Every function returns one complete SVG document (`<svg ...>` to `</svg>\n`) with a white
//! background, a `viewBox` and its own `width`/`height`, so it can be served as `image/svg+xml`
//! or injected into a page as it is. Text is escaped; non-finite inputs are skipped and every
//! division is guarded, so no `NaN` or `inf` reaches the output, whatever the input (empty slices,
//! all-equal values, zero counts). No `id` attributes are used, so several plots can share a page.
//!
//! `svg` writes the markup, `axes` maps data to pixels and draws the axes; each chart has its own
//! file and is re-exported here.

mod axes;
mod bands;
mod calibration;
mod histograms;
mod sensitivity;
mod svg;
mod tail;
mod trend;
mod weibull;
mod work_precision;

use bouncewear_model::montecarlo::{JobResult, JobSpec, Metric};
use bouncewear_model::stats::Summary;

pub use bands::{Design, compared_bands_svg, quantile_bands_svg};
pub use calibration::{FitPanel, calibration_panels, calibration_svg};
pub use histograms::histograms_svg;
pub use sensitivity::sensitivity_svg;
pub use tail::tail_svg;
pub use trend::{TrendPoint, trend_svg};
pub use weibull::{compared_weibull_svg, weibull_svg};
pub use work_precision::{Panel, Series, work_precision_svg};

use svg::{GRID, LABEL, MUTED, Style, Svg};

/// Why a job has no plot of the kind asked for: the caller's choice of plot or metric, not a fault.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("the job has no operation metric `{0}`")]
    NoMetric(String),
    #[error("the job has no failure criteria, so no Weibull plot")]
    NoLifeAnalysis,
    #[error("the job has no sensitivity analysis: submit it with `sensitivity`")]
    NoSensitivity,
    #[error("the job's sensitivity analysis has no metric `{0}`")]
    NoSensitivityMetric(String),
    #[error("the job asks no rare event, so no tail curve: submit it with `rare_event`")]
    NoRareEvent,
    #[error("no plot `{0}`: bands.svg, histograms.svg, weibull.svg, sensitivity.svg or tail.svg")]
    NoSuchPlot(String),
    #[error("no comparison plot `{0}`: bands.svg or weibull.svg")]
    NoSuchComparedPlot(String),
}

/// The plot `kind` (`bands.svg`, `histograms.svg`, `weibull.svg`, `sensitivity.svg` or
/// `tail.svg`) of a job's result, by the file name the dashboard and `bouncewear run --plots` both
/// use. `metric` is an operation metric for the first two, any metric of the sensitivity analysis
/// for the fourth; the tail curve is of the job's rare event.
pub fn job_plot(result: &JobResult, kind: &str, metric: &str) -> Result<String, PlotError> {
    job_has_plot(result.job.spec(), kind, metric)?;
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
        "sensitivity.svg" => {
            let sensitivity = result
                .sensitivity
                .as_ref()
                .ok_or(PlotError::NoSensitivity)?;
            let bins = sensitivity
                .get(metric)
                .ok_or_else(|| PlotError::NoSensitivityMetric(metric.to_owned()))?;
            Ok(sensitivity_svg(metric, bins))
        }
        "tail.svg" => {
            let (Some(report), Some(asked)) = (&result.rare_event, &result.job.spec().rare_event)
            else {
                return Err(PlotError::NoRareEvent);
            };
            let beyond = if asked.below.is_some() {
                "below"
            } else {
                "above"
            };
            Ok(tail_svg(&asked.metric, beyond, report))
        }
        other => Err(PlotError::NoSuchPlot(other.to_owned())),
    }
}

/// Whether `metric` has wear curves (`bands.svg`, `histograms.svg`): an operation metric, with
/// a value every operation; a device metric has one a device.
pub fn has_wear_curve(metric: &str) -> bool {
    matches!(Metric::parse(metric), Some(Metric::Operation(_)))
}

/// Whether a job of `spec` (as stored: its metrics filled in) has the plot `kind` of `metric`
/// once it succeeds: the rule [`job_plot`] applies, which the API applies whatever the job's
/// status, since a plot the job does not ask for never comes.
pub fn job_has_plot(spec: &JobSpec, kind: &str, metric: &str) -> Result<(), PlotError> {
    match kind {
        "bands.svg" | "histograms.svg" => {
            if has_wear_curve(metric) && spec.computes(metric) {
                Ok(())
            } else {
                Err(PlotError::NoMetric(metric.to_owned()))
            }
        }
        "weibull.svg" if spec.failure.is_empty() => Err(PlotError::NoLifeAnalysis),
        "sensitivity.svg" if spec.sensitivity.is_none() => Err(PlotError::NoSensitivity),
        "sensitivity.svg" if !spec.computes(metric) => {
            Err(PlotError::NoSensitivityMetric(metric.to_owned()))
        }
        "tail.svg" if spec.rare_event.is_none() => Err(PlotError::NoRareEvent),
        "weibull.svg" | "sensitivity.svg" | "tail.svg" => Ok(()),
        other => Err(PlotError::NoSuchPlot(other.to_owned())),
    }
}

/// The plot `kind` comparing two jobs' results (`bands.svg`: the wear curves of `metric`;
/// `weibull.svg`: the Weibull plots), each named in the legend.
pub fn compared_plot(
    designs: [(&str, &JobResult); 2],
    kind: &str,
    metric: &str,
) -> Result<String, PlotError> {
    match kind {
        "bands.svg" => {
            let mut drawn = Vec::new();
            for (name, result) in designs {
                let bins = result
                    .operations
                    .get(metric)
                    .ok_or_else(|| PlotError::NoMetric(metric.to_owned()))?;
                drawn.push(Design { name, bins });
            }
            Ok(compared_bands_svg(metric, &drawn))
        }
        "weibull.svg" => {
            let mut drawn = Vec::new();
            for (name, result) in designs {
                let life = result.life.as_ref().ok_or(PlotError::NoLifeAnalysis)?;
                drawn.push((name, &life.analysis));
            }
            Ok(compared_weibull_svg(&drawn))
        }
        other => Err(PlotError::NoSuchComparedPlot(other.to_owned())),
    }
}

/// Whether `metric` takes whole values only (`bounce_count`): its axes get whole ticks.
/// A bin's operations as every plot heads it, both ends included: `operations 90–99` for the
/// bin whose `op_start` is 90 and `op_end` (exclusive) 100, as the dashboard writes it too.
fn operation_range(start: u64, end: u64) -> String {
    format!(
        "operations {start}\u{2013}{}",
        end.saturating_sub(1).max(start)
    )
}

fn whole_valued(metric: &str) -> bool {
    matches!(Metric::parse(metric), Some(Metric::Operation(m)) if m.is_integer())
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn quantile(s: &Summary, key: &str) -> Option<f64> {
    s.quantiles.get(key).and_then(|q| finite(q.value))
}

fn limit_of(s: &Summary) -> Option<f64> {
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

/// What the chart tests share: summaries built from values, a wear test's bins, and the checks
/// every document must pass.
#[cfg(test)]
mod fixtures {
    use bouncewear_model::montecarlo::Bin;
    use bouncewear_model::stats::{Exceedance, Histogram, QuantileSummary, Summary};
    use std::collections::BTreeMap;

    pub(super) fn summary(values: &[f64], limit: Option<f64>) -> Summary {
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
                    reason: None,
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
            exceedances: Vec::new(),
        }
    }

    /// A deterministic pseudo-random stream in [0, 1).
    pub(super) fn uniform(seed: u64, k: u64) -> f64 {
        let mut z = seed.wrapping_add(k.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 * 2f64.powi(-53)
    }

    pub(super) fn wear_bins(count: usize, per_bin: u64, limit: Option<f64>) -> Vec<Bin> {
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

    /// The numbers among the texts of `svg` that are not whole: none on an axis of counts.
    pub(super) fn fractional_labels(svg: &str) -> Vec<&str> {
        svg.split("<text ")
            .skip(1)
            .map(|t| &t[t.find('>').unwrap() + 1..t.find("</text>").unwrap()])
            .filter(|label| label.parse::<f64>().is_ok_and(|v| v.fract() != 0.0))
            .collect()
    }

    /// Bins of a whole-valued metric, 1 to 3 bounces an operation.
    pub(super) fn bounce_count_bins(count: u64) -> Vec<Bin> {
        (0..count)
            .map(|b| {
                let values: Vec<f64> = (0..200)
                    .map(|k| (1.0 + 3.0 * uniform(b, k)).floor())
                    .collect();
                Bin {
                    summary: summary(&values, None),
                    op_start: b * 100,
                    op_end: (b + 1) * 100,
                }
            })
            .collect()
    }

    /// The checks every plot must pass.
    pub(super) fn check(svg: &str) {
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
}
