//! Intervals against their truth: how often the nominal 95 % intervals of small jobs (summary,
//! after-run queries, Sobol' indices), small exceedance probabilities, calibration fits and
//! rare-event estimates cover a truth known exactly or from a much larger job, and how wide they are.

use super::speed::run;
use crate::progress::Progress;
use bouncewear_model::montecarlo::{Job, Metric, OperationMetric, Silent};
use bouncewear_model::stats::Accumulator;
use serde::{Deserialize, Serialize};
use serde_json::json;
use std::time::Instant;

/// How often the nominal 95 % intervals of a small job cover the truth, and how wide they are: one
/// design of scatter, one statistic.
#[derive(Debug, Serialize, Deserialize)]
pub struct Coverage {
    pub design: String,
    /// Devices per job.
    pub devices: u64,
    pub statistic: String,
    /// Jobs (seeds) run.
    pub seeds: u32,
    /// Of those, the jobs whose data could bound the statistic (a quantile level too extreme for
    /// a job answers no interval, only the reason): the share is over these.
    pub answered: u32,
    pub coverage: f64,
    /// The mean of the intervals' half-widths relative to the truth.
    pub mean_relative_half_width: f64,
}

/// The seeds (jobs) of each coverage figure when `--coverage-seeds` is not given.
pub(super) fn default_coverage_seeds(quick: bool) -> u32 {
    if quick { 20 } else { 400 }
}

/// The designs: which of the parameters scatter, and how (radius and hardness per
/// device, closing velocity per operation).
pub(super) const COVERAGE_DESIGNS: [(&str, &[&str]); 3] = [
    ("device-scattered", &["device"]),
    ("operation-scattered", &["operation"]),
    ("both", &["device", "operation"]),
];

/// The job sizes each design runs at: 512, the smallest job the intervals are built for (where the
/// p99 asked after the run has the five devices beyond it that docs/contract.md's rule asks for,
/// `0.01 x 512 = 5.12`), and 64, to show what falls short below it.
pub(super) const COVERAGE_DEVICES: [u64; 2] = [64, 512];

/// A design's job at 48 V / 15 A: `devices` x 20 operations in one bin, with Sobol' indices
/// when the design scatters per device, counting the values of total bounce time `above` a
/// threshold as it runs when one is given.
fn coverage_job(levels: &[&str], devices: u64, seed: u64, above: Option<f64>) -> Job {
    let mut scatter = Vec::new();
    if levels.contains(&"device") {
        scatter.push(json!({"parameter": "contact_radius_m", "per": "device",
            "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 1e-3, "min": 1e-3}}));
        scatter.push(
            json!({"parameter": "dynamic_yield_pressure_pa", "per": "device",
            "distribution": {"kind": "lognormal", "median": 2e8, "sigma": 0.1}}),
        );
    }
    if levels.contains(&"operation") {
        scatter.push(
            json!({"parameter": "impact_velocity_m_s", "per": "operation",
            "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.03, "min": 0.05}}),
        );
    }
    let mut job = json!({
        "devices": devices, "operations": 20, "bin_operations": 20, "seed": seed,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "metrics": ["total_bounce_s"], "scatter": scatter,
        "sensitivity": {"method": "sobol"},
    });
    if let Some(x) = above {
        job["limits"] = json!({"total_bounce_s": [{"above": x}]});
    }
    Job::from_json(&job.to_string(), || 0).expect("the coverage jobs are valid")
}

/// The quantile statistics of [`coverage_estimates`] and their levels.
const COVERAGE_QUANTILES: [(&str, f64); 3] =
    [("p50", 0.5), ("p95", 0.95), ("p99 after the run", 0.99)];

/// One statistic's estimate and its 95 % interval; no interval for a quantile level the job's
/// data cannot bound (its `reason`).
type Estimate = (&'static str, f64, Option<[f64; 2]>);

/// The truth for [`coverage_estimates`]: the same statistics of one large job, each quantile
/// interpolated within its bucket
/// ([`bouncewear_model::stats::Sketch::interpolated_quantile`]). The reported quantiles are
/// bucket midpoints, so judged against a truth on the same grid, an interval would count as
/// covering whenever the truth merely shares a bucket with an end: up to a bucket (0.39 %) wider
/// than it is, which at 512 devices is a quarter of a p50 interval and covered 98 %.
fn coverage_truth(large: &Job, exceedance_above: f64) -> Vec<Estimate> {
    let (mut truth, all) = coverage_run(large, exceedance_above);
    for (statistic, value, _) in &mut truth {
        if let Some(&(_, level)) = COVERAGE_QUANTILES
            .iter()
            .find(|(name, _)| name == statistic)
        {
            *value = all.sketch().interpolated_quantile(level);
        }
    }
    truth
}

/// One run's estimates, each with its 95 % interval, by statistic: the summary's mean, p50 and
/// p95, a quantile asked after the run, the exceedance of a threshold counted as it ran, and the
/// Sobol' indices.
fn coverage_estimates(job: &Job, exceedance_above: f64) -> Vec<Estimate> {
    coverage_run(job, exceedance_above).0
}

/// [`coverage_estimates`], with every value of the bin merged.
fn coverage_run(job: &Job, exceedance_above: f64) -> (Vec<Estimate>, Accumulator) {
    use bouncewear_model::montecarlo::{RunGroups, engine, query_metric, summarize_job};
    use bouncewear_model::stats::Threshold;
    let tally = engine::run(job, &Silent, |_| false).expect("nothing cancels a benchmark");
    let result = summarize_job(job, &tally, 1.0);
    let bin = &result.operations["total_bounce_s"][0].summary;
    let groups = RunGroups::new(job, tally)
        .of("total_bounce_s", 0)
        .expect("the job has the metric");
    let metric = Metric::Operation(OperationMetric::TotalBounce);
    let answer = query_metric(
        metric,
        job.bin_range(0),
        &groups,
        &[0.99],
        &[Threshold::Above(exceedance_above)],
    );
    let quantile = |key: &str| {
        let q = &bin.quantiles[key];
        (q.value, q.reason.is_none().then_some(q.ci95))
    };
    let p99 = &answer.quantiles["0.99"];
    let mut estimates = vec![
        ("mean", bin.mean, Some(bin.mean_ci95)),
        ("p50", quantile("p50").0, quantile("p50").1),
        ("p95", quantile("p95").0, quantile("p95").1),
        ("p99 after the run", p99.value.unwrap_or(f64::NAN), p99.ci95),
        (
            "P(above the true p90), counted as it ran",
            answer.exceedance[0].probability,
            Some(answer.exceedance[0].ci95),
        ),
    ];
    let sensitivity = &result.sensitivity.as_ref().expect("asked for")["total_bounce_s"][0];
    for (parameter, statistic) in [
        (
            "dynamic_yield_pressure_pa",
            ["pressure: first-order index", "pressure: total index"],
        ),
        (
            "impact_velocity_m_s",
            ["velocity: first-order index", "velocity: total index"],
        ),
    ] {
        if let Some(indices) = sensitivity.indices.get(parameter) {
            for (index, name) in [indices.first, indices.total].into_iter().zip(statistic) {
                if let Some(index) = index {
                    estimates.push((name, index.value, Some(index.ci95)));
                }
            }
        }
    }
    let mut all = groups
        .first()
        .map_or_else(|| Accumulator::new(None), Accumulator::empty_like);
    groups.iter().for_each(|group| all.merge(group));
    (estimates, all)
}

/// Coverage of every statistic in every design at every size of [`COVERAGE_DEVICES`], over `seeds`
/// jobs (400; quick: 20), the truth from one job of 64 000 devices (quick: 1280), at least 125
/// (quick: 2.5) times the largest: its own error then widens the spread an interval must cover by
/// under 0.4 %.
pub(super) fn coverage(quick: bool, seeds: u32, progress: &Progress) -> Vec<Coverage> {
    let truth_devices = if quick { 1280 } else { 64_000 };
    let mut rows = Vec::new();
    for (design, levels) in COVERAGE_DESIGNS {
        // The exceedance threshold is the truth's p90, so the true probability is about 0.1; the
        // truth's own answer for it, counted as it ran, is the reference.
        let p90 = {
            let result = run(&coverage_job(levels, truth_devices, 1_000_000, None));
            result.operations["total_bounce_s"][0].summary.quantiles["p90"].value
        };
        let large = coverage_job(levels, truth_devices, 1_000_000, Some(p90));
        let truth = coverage_truth(&large, p90);
        for devices in COVERAGE_DEVICES {
            progress.measure(
                format!("interval coverage: {design}, {devices} devices"),
                || {
                    // Per statistic: intervals that covered, intervals given, half-widths.
                    let mut hits = vec![(0_u32, 0_u32, 0.0); truth.len()];
                    for seed in 0..seeds {
                        let job = coverage_job(levels, devices, u64::from(seed), Some(p90));
                        let estimates = coverage_estimates(&job, p90);
                        for ((hit, given, width), ((_, _, ci95), (_, true_value, _))) in
                            hits.iter_mut().zip(estimates.iter().zip(&truth))
                        {
                            let Some([lo, hi]) = ci95 else { continue };
                            *hit += u32::from(lo <= true_value && true_value <= hi);
                            *given += 1;
                            *width += 0.5 * (hi - lo) / true_value.abs().max(f64::MIN_POSITIVE);
                        }
                    }
                    for ((statistic, _, _), (hit, given, width)) in truth.iter().zip(hits) {
                        let given_f = f64::from(given.max(1));
                        rows.push(Coverage {
                            design: design.into(),
                            devices,
                            statistic: statistic.to_string(),
                            seeds,
                            answered: given,
                            coverage: f64::from(hit) / given_f,
                            mean_relative_half_width: width / given_f,
                        });
                    }
                },
            );
        }
    }
    rows
}

/// How often the exceedance intervals of one kind cover an exact tail probability.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TailCoverage {
    pub statistic: String,
    /// Values per job.
    pub values: u64,
    /// The exact probability beyond the threshold.
    pub probability: f64,
    pub seeds: u32,
    /// Seeds whose answer was exact (`"resolution": "exact"`), not bucket-limited.
    pub exact: u32,
    pub coverage: f64,
    /// The mean of the intervals' half-widths relative to the exact probability.
    pub mean_relative_half_width: f64,
}

/// The closing velocity of [`tail_coverage`]'s jobs: N(0.224, 0.02) m/s, drawn per operation.
const TAIL_VELOCITY: (f64, f64) = (0.224, 0.02);

/// Exceedance intervals at P = 1e-4 in jobs of 1e7 values (quick: P = 1e-3, 1e6 values), over 200
/// seeds (quick: 20), against the exact probability: the metric is the closing velocity itself,
/// drawn N(0.224, 0.02) m/s per operation, so the share beyond any threshold is a normal tail (the
/// truncation at 0.05 m/s moves it by 1e-18). One threshold is named in the job's `limits` and
/// counted as it runs; another, just below it, is asked after the run and counted from the
/// values the groups keep at their ends.
pub(super) fn tail_coverage(quick: bool, progress: &Progress) -> Vec<TailCoverage> {
    use bouncewear_model::montecarlo::distribution::standard_normal_cdf;
    use bouncewear_model::montecarlo::{RunGroups, engine, query_metric};
    use bouncewear_model::stats::{Resolution, Threshold};
    let (seeds, devices, z) = if quick {
        (20_u32, 1000_u64, 3.090_232_306_167_813)
    } else {
        (200, 10_000, 3.719_016_485_455_709)
    };
    let (mean, sd) = TAIL_VELOCITY;
    let counted = mean + sd * z;
    let asked = mean + sd * (z - 0.01);
    let truth = |x: f64| standard_normal_cdf(-(x - mean) / sd);
    progress.measure("exceedance coverage in the tail", || {
        let mut hits = [(0_u32, 0_u32, 0.0); 2];
        for seed in 0..seeds {
            let job = json!({
                "devices": devices, "operations": 1000, "bin_operations": 1000, "seed": seed,
                "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
                "metrics": ["impact_velocity_m_s"],
                "limits": {"impact_velocity_m_s": [{"above": counted}]},
                "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                    "distribution": {"kind": "normal", "mean": mean, "sd": sd, "min": 0.05}}],
            });
            let job = Job::from_json(&job.to_string(), || 0).expect("the tail jobs are valid");
            let tally = engine::run(&job, &Silent, |_| false).expect("nothing cancels a benchmark");
            let groups = RunGroups::new(&job, tally)
                .of("impact_velocity_m_s", 0)
                .expect("the job has the metric");
            let metric = Metric::Operation(OperationMetric::ImpactVelocity);
            let thresholds = [Threshold::Above(counted), Threshold::Above(asked)];
            let answer = query_metric(metric, job.bin_range(0), &groups, &[], &thresholds);
            for ((hit, exact, width), e) in hits.iter_mut().zip(&answer.exceedance) {
                let p = truth(e.threshold.value());
                let [lo, hi] = e.ci95;
                *hit += u32::from(lo <= p && p <= hi);
                *exact += u32::from(e.resolution == Resolution::Exact);
                *width += 0.5 * (hi - lo) / p;
            }
        }
        let names = [
            "P(above), counted as the job ran",
            "P(above), asked after the run (kept tails)",
        ];
        names
            .into_iter()
            .zip(hits)
            .zip([counted, asked])
            .map(|((statistic, (hit, exact, width)), x)| TailCoverage {
                statistic: statistic.into(),
                values: devices * 1000,
                probability: truth(x),
                seeds,
                exact,
                coverage: f64::from(hit) / f64::from(seeds),
                mean_relative_half_width: width / f64::from(seeds),
            })
            .collect()
    })
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CalibrationCoverage {
    pub case: String,
    pub parameter: String,
    pub truth: f64,
    /// The first of the noise draws' seeds, each fitted once.
    pub first_seed: u64,
    /// Noise draws (seeds `first_seed` onwards).
    pub draws: u64,
    pub coverage: f64,
    /// The share of the same draws on which the exact interval of the model linearised at the
    /// truth holds it: 0.95 in expectation, so its departure is the draws' own luck.
    pub linear_reference: f64,
}

/// The calibration studies of the model (issue 29's two cases): each disjoint block of 200 noise
/// draws from seed 1000 on, five blocks, then the 1000 together (quick: one block of 20). The
/// blocks show how far a 200-draw coverage strays from the 1000-draw one by chance alone (its
/// binomial standard deviation at a true 0.95 is 0.015), and the exact linearised interval on
/// the same draws how much of that is the draws.
pub(super) fn calibration_coverage(quick: bool, progress: &Progress) -> Vec<CalibrationCoverage> {
    use bouncewear_model::calibration::study::{CASES, coverage_by_block};
    let (size, count) = if quick { (20, 1) } else { (200, 5) };
    let mut rows = Vec::new();
    for case in &CASES {
        progress.measure(format!("calibration coverage: {}", case.name), || {
            let study = coverage_by_block(case, 1000, size, count);
            let whole = (count > 1).then(|| (1000..1000 + size * count, study.all));
            for (seeds, coverage) in study.blocks.into_iter().chain(whole) {
                let shares = coverage.profile.into_iter().zip(coverage.linear_reference);
                rows.extend(case.truths.iter().zip(shares).map(
                    |(&(parameter, truth), (coverage, linear_reference))| CalibrationCoverage {
                        case: case.name.into(),
                        parameter: parameter.into(),
                        truth,
                        first_seed: seeds.start,
                        draws: seeds.end - seeds.start,
                        coverage,
                        linear_reference,
                    },
                ));
            }
        });
    }
    rows
}

/// The rare-event studies [`rare_event_coverage`] measures.
pub(super) const RARE_EVENT_STUDIES: usize = 7;

/// How one rare-event method fares at one probability: its intervals against the exact tail, its
/// precision and its cost.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RareEventCoverage {
    pub method: String,
    /// The exact probability beyond the threshold.
    pub probability: f64,
    pub target_cov: f64,
    pub seeds: u32,
    pub coverage: f64,
    /// The mean of the estimates' own coefficients of variation.
    pub mean_cov: f64,
    /// The spread of the estimates over the seeds, relative to the truth: the realised cov.
    pub observed_cov: f64,
    pub mean_evaluations: f64,
    /// Devices crude Monte Carlo needs for the same coefficient of variation, `(1 - P) / (P cov^2)`.
    pub crude_evaluations: f64,
    /// Mean wall seconds per estimate on this machine's threads.
    pub mean_wall_s: f64,
}

/// The rare-event studies: P(total bounce time of one operation above t) with the closing velocity
/// drawn N(0.224, 0.02) m/s per operation at 48 V / 15 A. The bounce time rises with the velocity
/// (checked over +-6 sd by the model's tests), so the event is the velocity's normal tail beyond
/// the velocity that gives `t`: exact. Each method over 200 seeds (quick: 5) at P = 1e-3, 1e-6
/// and 1e-9; crude Monte Carlo at 1e-3 only (1e-6 would need 1e8 devices per estimate).
pub(super) fn rare_event_coverage(quick: bool, progress: &Progress) -> Vec<RareEventCoverage> {
    use bouncewear_model::montecarlo::distribution::standard_normal_cdf;
    use bouncewear_model::montecarlo::rare::estimate;
    const Z: [f64; 3] = [
        3.090_232_306_167_813,
        4.753_424_308_817_09,
        5.997_807_015_007_688,
    ];
    let seeds: u32 = if quick { 5 } else { 200 };
    let (mean, sd) = TAIL_VELOCITY;
    let bounce_at = |v: f64| {
        let job = json!({
            "devices": 1, "operations": 1, "seed": 1,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                         "distribution": {"kind": "fixed", "value": v}}],
            "metrics": ["total_bounce_s"]
        });
        let job = Job::from_json(&job.to_string(), || 0).expect("a valid job");
        run(&job).operations["total_bounce_s"][0].summary.mean
    };
    let mut rows = Vec::new();
    for z in Z {
        let threshold = bounce_at(mean + sd * z);
        let truth = standard_normal_cdf(-z);
        let methods: &[(&'static str, f64)] = if z < 4.0 {
            &[("subset", 0.25), ("importance", 0.1), ("crude", 0.1)]
        } else {
            &[("subset", 0.25), ("importance", 0.1)]
        };
        for &(method, target_cov) in methods {
            progress.measure(format!("rare event: {method} at {truth:.0e}"), || {
                let (mut covered, mut cov, mut evaluations, mut squares) = (0, 0.0, 0.0, 0.0);
                let started = Instant::now();
                for seed in 0..seeds {
                    let job = json!({
                        "devices": 1, "operations": 1, "seed": seed,
                        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
                        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                            "distribution": {"kind": "normal", "mean": mean, "sd": sd, "min": 0.01}}],
                        "metrics": ["total_bounce_s"],
                        "rare_event": {"metric": "total_bounce_s", "above": threshold,
                                       "method": method, "target_cov": target_cov,
                                       "max_evaluations": 10_000_000}
                    });
                    let job = Job::from_json(&job.to_string(), || 0).expect("a valid job");
                    let found = estimate(&job, &Silent)
                        .expect("the studies reach their thresholds")
                        .expect("the job asks a rare event");
                    covered += u32::from(found.ci95[0] <= truth && truth <= found.ci95[1]);
                    cov += found.cov.unwrap_or(f64::NAN);
                    evaluations += found.evaluations as f64;
                    squares += (found.probability / truth - 1.0).powi(2);
                }
                let n = f64::from(seeds);
                rows.push(RareEventCoverage {
                    method: method.into(),
                    probability: truth,
                    target_cov,
                    seeds,
                    coverage: f64::from(covered) / n,
                    mean_cov: cov / n,
                    observed_cov: (squares / n).sqrt(),
                    mean_evaluations: evaluations / n,
                    crude_evaluations: (1.0 - truth) / (truth * (cov / n).powi(2)),
                    mean_wall_s: started.elapsed().as_secs_f64() / n,
                });
            });
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_design_scatters_what_it_names_and_runs_the_size_asked() {
        for (name, levels) in COVERAGE_DESIGNS {
            for devices in COVERAGE_DEVICES {
                let job = coverage_job(levels, devices, 7, Some(0.012));
                let spec = job.spec();
                assert_eq!(
                    (spec.devices, spec.operations, spec.seed),
                    (devices, 20, Some(7))
                );
                let per: Vec<String> = spec
                    .scatter
                    .iter()
                    .map(|s| format!("{:?}", s.per).to_lowercase())
                    .collect();
                assert_eq!(
                    per.iter().any(|p| p == "device"),
                    levels.contains(&"device"),
                    "{name}"
                );
                assert_eq!(
                    per.iter().any(|p| p == "operation"),
                    levels.contains(&"operation"),
                    "{name}"
                );
            }
        }
    }
}
