//! Monte Carlo endurance tests (docs/contract.md "Job" and "Result"): `N` devices with scattered
//! parameters through `M` make operations each, the surface of each wearing with its cumulative arc
//! energy (docs/model.md section 6), summarised per bin of operations with honest confidence
//! intervals.

pub mod compare;
pub mod correlation;
pub mod diagnostics;
pub mod distribution;
pub mod engine;
pub mod job;
pub mod kernel;
pub mod lives;
pub mod metric;
pub mod rare;
pub mod scatter;
pub mod sensitivity;

pub use engine::{Cancelled, Observer, Silent, Tally, Watch};
pub use job::{Job, JobSpec, LimitSpec};
pub use kernel::{FLOOR_CHAINS, Isa, Kernel};
pub use lives::{DeviceLife, GroupLives};
pub use metric::{DeviceMetric, Metric, OperationMetric, needs_polarity};
pub use rare::{RareEventReport, RareEventSpec};

use crate::stats::summary::MIN_TAIL_UNITS;
use crate::stats::{
    Accumulator, QueryAnswer, Sketch, Summary, Threshold, quantile_keyed, query, summarize,
};
use job::Statistic;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::time::Instant;

/// The generator every draw comes from, recorded in each result.
pub const GENERATOR: &str = "ChaCha8Rng (rand_chacha) seeded by seed_from_u64(seed); device d draws from stream d, LHS batch b permutes on stream 2^63 + b";

/// Versions of the crates that fix the random numbers, recorded in each result (checked against
/// Cargo.lock by a test).
pub const RANDOM_CRATES: [(&str, &str); 3] = [
    ("rand", "0.10.3"),
    ("rand_chacha", "0.10.0"),
    ("rand_distr", "0.6.0"),
];

/// One bin of operations: its summary and the operations it covers (`op_end` exclusive).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Bin {
    #[serde(flatten)]
    pub summary: Summary,
    /// First operation of the bin (0-based).
    pub op_start: u64,
    /// End of the bin, exclusive.
    pub op_end: u64,
}

/// Whether the precision target was met, and with how many devices.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PrecisionReport {
    /// The operation metric of the target.
    pub metric: String,
    /// The statistic of the target.
    pub statistic: String,
    /// The half-width asked for, relative to the value.
    pub target_relative_half_width: f64,
    /// The half-width reached, relative to the value.
    pub achieved_relative_half_width: f64,
    /// Whether the target was met within `max_devices`: never while the data cannot bound the
    /// statistic (a quantile level with a `reason`), whatever its interval's width.
    pub met: bool,
    /// Why the target counts as not met though the half-width reached is within it: the
    /// quantile's own `reason` (its level beyond what the data bound), or too few devices yet
    /// for a target on that level (5 devices' share beyond it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Devices that ran.
    pub devices: u64,
}

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Wall-clock time the run took, s.
    pub wall_s: f64,
    /// Operations simulated per second of wall-clock time.
    pub operations_per_s: f64,
}

/// The Result of docs/contract.md "Result".
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobResult {
    /// The job with every default filled in, its seed, the generator and crate versions.
    pub job: ResolvedJob,
    /// Per operation metric, its bins in operation order.
    pub operations: BTreeMap<String, Vec<Bin>>,
    /// Per device metric, its summary over devices at the end of the test.
    pub devices: BTreeMap<String, Summary>,
    /// With a precision target: whether it was met.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub precision: Option<PrecisionReport>,
    /// With failure criteria: the life analysis of the devices' operations to failure.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub life: Option<LifeReport>,
    /// With a sensitivity analysis: per metric, its bins in operation order (a device metric:
    /// one entry), each with the indices of every parameter that drives it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity: Option<BTreeMap<String, Vec<sensitivity::SensitivityBin>>>,
    /// With a rare event: its probability, interval, design point and tail curve.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rare_event: Option<rare::RareEventReport>,
    /// What the run met that bears on its numbers, counted over every operation.
    pub counts: diagnostics::Counts,
    /// Warnings about how far to trust the numbers (e.g. eq. 16 far from its calibration current,
    /// bounce sequences cut at `max_bounces`, inputs outside the paper's measurements).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub diagnostics: Vec<diagnostics::Diagnostic>,
    /// How long the run took.
    pub timing: Timing,
}

/// The job as it ran: everything needed to rerun it and get the same bits.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct ResolvedJob {
    /// The JobSpec with every default filled in: its seed, `bin_operations`, the whole scenario and
    /// the list of metrics. A plain object here: JobSpec's schema admits no other members, and
    /// the served document declares them (`api::openapi`).
    #[serde(flatten)]
    #[cfg_attr(feature = "openapi", schema(value_type = Object))]
    spec: JobSpec,
    /// Devices that ran: `devices`, or more with a precision target.
    devices_run: u64,
    /// The random number generator and how it is seeded.
    generator: String,
    /// Versions of the crates that fix the random numbers, and of the model.
    versions: BTreeMap<String, String>,
}

impl ResolvedJob {
    fn new(job: &Job, devices_run: u64) -> Self {
        let mut spec = job.spec().clone();
        spec.scenario = job.scenario().spec().clone();
        spec.metrics = Some(job.metric_names());
        // The operation a rare event reads an operation metric at (1 unless asked).
        if let (Some(asked), Some(rare)) = (spec.rare_event.as_mut(), job.rare_event())
            && matches!(rare.reading, rare::Reading::Metric(Metric::Operation(_)))
        {
            asked.operation = Some(rare.operations);
        }
        Self {
            spec,
            devices_run,
            generator: GENERATOR.to_owned(),
            versions: RANDOM_CRATES
                .iter()
                .copied()
                .chain([("bouncewear-model", env!("CARGO_PKG_VERSION"))])
                .map(|(name, version)| (name.to_owned(), version.to_owned()))
                .collect(),
        }
    }

    pub fn spec(&self) -> &JobSpec {
        &self.spec
    }

    pub fn devices_run(&self) -> u64 {
        self.devices_run
    }

    pub fn generator(&self) -> &str {
        &self.generator
    }

    pub fn versions(&self) -> &BTreeMap<String, String> {
        &self.versions
    }
}

impl Serialize for ResolvedJob {
    /// Through one serde_json map, which keeps its keys sorted: every key at every depth comes out
    /// in alphabetical order, as when the job was an untyped map, so Results stay byte-identical.
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::Error;
        let mut value = serde_json::to_value(&self.spec).map_err(S::Error::custom)?;
        let object = value.as_object_mut().expect("a job spec is an object");
        object.insert("devices_run".into(), self.devices_run.into());
        object.insert("generator".into(), self.generator.clone().into());
        object.insert(
            "versions".into(),
            serde_json::to_value(&self.versions).map_err(S::Error::custom)?,
        );
        value.serialize(serializer)
    }
}

/// Life analysis of a job with failure criteria (docs/model.md has no failure model: the user's
/// criteria define failure, and each device's first failing operation is its life).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LifeReport {
    /// The failure criteria, by metric.
    pub criteria: BTreeMap<String, job::CriterionSpec>,
    /// Devices that failed within the test.
    pub failures: u64,
    /// Devices that survived every operation (right-censored).
    pub censored: u64,
    /// Weibull fit (maximum likelihood with censoring, Fisher-matrix bounds), B1 and B10 life, Kaplan-Meier reliability.
    #[cfg_attr(feature = "openapi", schema(value_type = Object))]
    pub analysis: crate::life::LifeAnalysis,
    /// A Weibayes demonstration (`eta` and B-lives with the shape taken as known), where asked for
    /// (`GET /v1/jobs/{id}/life?weibayes_beta=`); never in the Result.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(value_type = Option<Object>))]
    pub weibayes: Option<crate::life::weibayes::Weibayes>,
    /// Each device's life, in device order, as far as the groups kept them listed (all of them
    /// unless trimmed with [`GroupLives::keep_listed_below`]); not part of the Result JSON: the
    /// service serves it as CSV.
    #[serde(skip)]
    pub devices: Vec<DeviceLife>,
}

impl LifeReport {
    /// The lives it summarises, grouped by time: each Kaplan-Meier step's failures at its
    /// operation, and the censored devices at `operations`, the end of the test every survivor
    /// reached.
    pub fn lives(&self, operations: u64) -> crate::life::Lives {
        let mut counts: Vec<(u64, u64, u64)> = self
            .analysis
            .kaplan_meier
            .iter()
            .map(|step| (step.time as u64, step.failures as u64, 0))
            .collect();
        match counts.last_mut() {
            Some(last) if last.0 == operations => last.2 += self.censored,
            _ => counts.push((operations, 0, self.censored)),
        }
        crate::life::Lives::from_counts(counts)
    }

    /// The report with its candidate fits compared, where a Result stored by an older build has
    /// none (`fits` came later, and such a Result reads as if no fit could be made): from the
    /// lives it summarises ([`LifeReport::lives`], exact), as the job's own run compares them,
    /// beside the stored Weibull. A report that has them, or has no failure to fit, is as it was.
    pub fn with_fits(mut self, operations: u64) -> Self {
        if self.analysis.fits.is_empty() && self.failures > 0 {
            let lives = self.lives(operations);
            let analysis = &mut self.analysis;
            analysis.fits = crate::life::fits::fits(&lives, analysis.weibull.as_ref());
            analysis.fit_warning = crate::life::fits::weibull_warning(&analysis.fits);
        }
        self
    }
}

/// Why a run gave no Result.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
    #[error(transparent)]
    RareEvent(#[from] rare::RareEventError),
    #[error(transparent)]
    OutOfRange(#[from] OutOfRange),
}

/// A summary the run cannot state: a metric's values, or their spread, beyond f64's range. The
/// magnitudes a scenario admits keep every input within 1e-30 to 1e30, but their products can
/// still combine past 1.8e308 (forces of 1e30 N, lengths and pressures of 1e-30, an arc of 1e30 V and
/// 1e30 A: a first impact's plastic work beyond f64), and such a job ends with this
/// instead of a Result of `null`s.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{metric} leaves the range of f64 (beyond 1.8e308) {at}{what}: the scenario's magnitudes \
     combine past what the model can represent (docs/model.md section 9)"
)]
pub struct OutOfRange {
    pub metric: String,
    /// Empty where the values themselves leave it; else which of their summary does.
    pub what: String,
    /// Where: the bin's operations, or the devices at the end of the test.
    pub at: String,
}

/// Every operation bin's and device metric's summary stated in finite numbers (its mean, interval,
/// spread and extremes), and every sensitivity index, or the first that is not.
pub fn check_in_range(result: &JobResult) -> Result<(), OutOfRange> {
    let finite = |s: &Summary| {
        [s.mean, s.mean_ci95[0], s.mean_ci95[1], s.sd, s.min, s.max]
            .iter()
            .all(|v| v.is_finite())
    };
    // Values within f64 whose spread is not: their squares pass it from about 1.3e154. Values
    // none of which is a number (no least and greatest: 0 times infinity, where an input drawn
    // below 1e-30, a Weibull's lower tail left to its draws, made a mass of 0; a run panicked
    // on them, found from outside).
    let what = |s: &Summary| {
        if s.min > s.max {
            " (its values are NaN: an intermediate passed f64's range, 0 times infinity)".to_owned()
        } else if [s.mean, s.min, s.max].iter().all(|v| v.is_finite()) {
            format!(
                " in its spread (values reach {:e}, whose squares pass 1.8e308)",
                s.min.abs().max(s.max.abs())
            )
        } else {
            String::new()
        }
    };
    for (metric, bins) in &result.operations {
        if let Some(bin) = bins.iter().find(|bin| !finite(&bin.summary)) {
            return Err(OutOfRange {
                metric: metric.clone(),
                what: what(&bin.summary),
                at: format!("in the bin from operation {}", bin.op_start),
            });
        }
    }
    if let Some((metric, summary)) = result.devices.iter().find(|(_, summary)| !finite(summary)) {
        return Err(OutOfRange {
            metric: metric.clone(),
            what: what(summary),
            at: "over the devices at the end of the test".to_owned(),
        });
    }
    // The indices' sums of products can pass f64 where no summary's does (they printed null).
    for (metric, bins) in result.sensitivity.iter().flatten() {
        if let Some(bin) = bins.iter().find(|bin| !bin.is_finite()) {
            return Err(OutOfRange {
                metric: metric.clone(),
                what: " in its sensitivity indices (their sums of products of values)".to_owned(),
                at: match bin.op_start {
                    Some(start) => format!("in the bin from operation {start}"),
                    None => "over the devices at the end of the test".to_owned(),
                },
            });
        }
    }
    Ok(())
}

/// Runs a job on the current rayon pool on [`Kernel::active`] and summarises it.
pub fn run_job(job: &Job, observer: &dyn Observer) -> Result<JobResult, RunError> {
    run_job_on(Kernel::active(), job, observer)
}

/// [`run_job`] with the given kernel: every kernel gives the same Result, to the bit.
pub fn run_job_on(
    kernel: Kernel,
    job: &Job,
    observer: &dyn Observer,
) -> Result<JobResult, RunError> {
    let started = Instant::now();
    // The groups make the Result alone: no extremes kept for queries after the run.
    let tally = engine::run_for_result(kernel, job, observer, |tally| precision_met(job, tally))?;
    let rare_event = rare::estimate(job, observer)?;
    let mut result = summarize_job(job, &tally, started.elapsed().as_secs_f64());
    check_in_range(&result)?;
    result.put_rare_event(job, rare_event);
    Ok(result)
}

impl JobResult {
    /// The rare event's report put in, with the warning where its budget ended it short of its
    /// target ([`rare::short_of_target`]).
    pub fn put_rare_event(&mut self, job: &Job, report: Option<RareEventReport>) {
        let short = report.as_ref().and_then(|r| rare::short_of_target(job, r));
        self.diagnostics.extend(short);
        self.rare_event = report;
    }
}

/// Whether the job's precision target is met by what `tally` holds (never, without a target).
pub fn precision_met(job: &Job, tally: &Tally) -> bool {
    job.precision().is_some_and(|p| {
        let (achieved, unbounded) = precision_half_width(job, tally, p);
        unbounded.is_none() && achieved <= p.relative_half_width
    })
}

/// The batch to run after the batches in `tally`, if the job needs one: its precision target is
/// not met yet and `max_devices` not reached. What [`run_job`] decides after each batch, for a
/// run whose groups ran elsewhere ([`engine::run_group`]).
pub fn next_batch(job: &Job, tally: &Tally) -> Option<engine::Batch> {
    let size = job.spec().devices;
    engine::Batch::of(job, tally.devices.div_ceil(size)).filter(|_| !precision_met(job, tally))
}

/// The Result of a run from its groups, however they were run: all at once by [`run_job`], or
/// one by one with [`engine::run_group`] (on several machines) and put back in order with
/// [`Tally::add_batch`].
/// `wall_s` is the time the run took, for the Result's timing.
pub fn summarize_job(job: &Job, tally: &Tally, wall_s: f64) -> JobResult {
    let operations_run = tally.devices * job.spec().operations;
    let mut truncation_rejections = Vec::new();
    for group in &tally.groups {
        engine::add_counts(&mut truncation_rejections, &group.truncation_rejections);
    }
    let counts = diagnostics::Counts {
        operations: operations_run,
        operations_at_max_bounces: tally
            .groups
            .iter()
            .map(|g| g.operations_at_max_bounces)
            .sum(),
        truncation_rejections,
    };
    let mut diagnostics = diagnostics::diagnose(job, &counts);
    let precision = job.precision().map(|p| {
        let (achieved, unbounded) = precision_half_width(job, tally, p);
        PrecisionReport {
            metric: p.metric.name().to_owned(),
            statistic: statistic_name(p.statistic).to_owned(),
            target_relative_half_width: p.relative_half_width,
            achieved_relative_half_width: achieved,
            met: unbounded.is_none() && achieved <= p.relative_half_width,
            reason: unbounded,
            devices: tally.devices,
        }
    });
    diagnostics.extend(precision.as_ref().and_then(diagnostics::stopped_early));
    diagnostics.extend(rare::forced_importance(job));
    JobResult {
        job: ResolvedJob::new(job, tally.devices),
        operations: summarize_operations(job, tally),
        devices: summarize_devices(job, tally),
        precision,
        life: life_report(job, tally),
        sensitivity: job.sensitivity().map(|_| {
            let groups: Vec<_> = tally.groups.iter().map(|g| &g.sensitivity).collect();
            sensitivity::summarize_sensitivity(job, &groups)
        }),
        rare_event: None,
        counts,
        diagnostics,
        timing: Timing {
            wall_s,
            operations_per_s: operations_run as f64 / wall_s.max(1e-9),
        },
    }
}

fn life_report(job: &Job, tally: &Tally) -> Option<LifeReport> {
    if job.failure().is_empty() {
        return None;
    }
    let mut lives = GroupLives::default();
    for group in &tally.groups {
        lives.merge(&group.lives);
    }
    let analysis = crate::life::analyse_lives(&lives.lives());
    Some(LifeReport {
        criteria: job.spec().failure.clone(),
        failures: analysis.failures as u64,
        censored: analysis.censored as u64,
        analysis,
        weibayes: None,
        devices: lives.listed,
    })
}

fn statistic_name(statistic: Statistic) -> &'static str {
    match statistic {
        Statistic::Mean => "mean",
        Statistic::Quantile(name) => name,
    }
}

/// The groups' accumulators of one (bin, metric), in group order.
fn operation_groups<'t>(
    job: &Job,
    tally: &'t Tally,
    bin: usize,
    metric: usize,
) -> Vec<&'t Accumulator> {
    let index = bin * job.operation_metrics().len() + metric;
    tally.groups.iter().map(|g| &g.operations[index]).collect()
}

/// Every bin of every operation metric, all of them in parallel (each summary is computed alone,
/// so the threads change no number).
fn summarize_operations(job: &Job, tally: &Tally) -> BTreeMap<String, Vec<Bin>> {
    let bins = usize::try_from(job.bins()).expect("bins fit in memory");
    let metrics = job.operation_metrics();
    // Every (metric, bin) in one parallel loop, metric after metric: a small job's few bins
    // per metric would leave a thread idle at each metric's end.
    let mut summaries = (0..metrics.len() * bins)
        .into_par_iter()
        .map(|at| {
            let (m, b) = (at / bins, at % bins);
            let metric = metrics[m];
            let operations = job.bin_range(b as u64);
            let groups = operation_groups(job, tally, b, m);
            let per_device = Metric::Operation(metric).values_per_device(operations.clone());
            let mut summary = summarize(&groups, per_device);
            if metric.is_integer() {
                round_quantiles(&mut summary);
            }
            answer_thresholds(
                job,
                Metric::Operation(metric),
                &groups,
                per_device,
                &mut summary,
            );
            Bin {
                summary,
                op_start: operations.start,
                op_end: operations.end,
            }
        })
        .collect::<Vec<Bin>>()
        .into_iter();
    metrics
        .iter()
        .map(|metric| {
            let of_metric = summaries.by_ref().take(bins).collect();
            (metric.name().to_owned(), of_metric)
        })
        .collect()
}

/// The summary's `exceedances`: the metric's thresholds, if the job lists any, answered as a query
/// after the run answers them.
fn answer_thresholds(
    job: &Job,
    metric: Metric,
    groups: &[&Accumulator],
    per_device: u64,
    summary: &mut Summary,
) {
    if let Some(thresholds) = job.thresholds().get(&metric) {
        summary.exceedances = query(groups, per_device, &[], thresholds).exceedance;
    }
}

/// The sketch reports a bucket midpoint (within 0.2 %); for a whole-number metric below 256 each bucket
/// holds one whole number, so the nearest whole number is the exact sample quantile.
fn round_quantiles(summary: &mut Summary) {
    for quantile in summary.quantiles.values_mut() {
        round_quantile(&mut quantile.value, &mut quantile.ci95);
    }
}

/// The value to its whole number, and each end of the interval to the whole numbers the sketch
/// bucket it lies in can hold: below 256 a bucket holds one, so an end at a bucket's edge stays
/// at that bucket's number (the interval of p01 to p75 of bounce counts 86 % at 7 and the rest at
/// 8 reached 8 by rounding the 7s' bucket's upper edge up; found from outside). Never narrower
/// than the whole numbers of the buckets the ends lie in, always holding the value.
fn round_quantile(value: &mut f64, ci95: &mut [f64; 2]) {
    *value = value.round();
    let [lo, hi] = *ci95;
    let least = Sketch::bucket_of(lo)[0].ceil();
    let greatest = Sketch::bucket_of(hi)[1].ceil() - 1.0;
    *ci95 = [
        lo.floor().max(least).min(*value),
        hi.ceil().min(greatest).max(*value),
    ];
}

/// [`query`](fn@query) of one (metric, bin over `operations`) after the run, from the groups
/// [`RunGroups::of`] gave: for a whole-number metric its quantiles rounded, as in the Result's
/// summaries, so that a standard level answers the summary's value and interval, and each
/// threshold answered as [`Threshold::between_whole_values`].
pub fn query_metric(
    metric: Metric,
    operations: std::ops::Range<u64>,
    groups: &[Accumulator],
    levels: &[f64],
    thresholds: &[Threshold],
) -> QueryAnswer {
    let per_device = metric.values_per_device(operations);
    if !matches!(metric, Metric::Operation(m) if m.is_integer()) {
        return query(groups, per_device, levels, thresholds);
    }
    let between: Vec<Threshold> = (thresholds.iter())
        .map(|t| t.between_whole_values())
        .collect();
    let mut answer = query(groups, per_device, levels, &between);
    // Each threshold told as asked.
    for (exceedance, &asked) in answer.exceedance.iter_mut().zip(thresholds) {
        exceedance.threshold = asked;
    }
    for quantile in answer.quantiles.values_mut() {
        if let (Some(value), Some(ci95)) = (&mut quantile.value, &mut quantile.ci95) {
            round_quantile(value, ci95);
        }
    }
    answer
}

/// The groups' accumulators of a finished run, by the (metric, bin) of the Result they summarise:
/// what a query after the run ([`query_metric`]) needs.
#[derive(Debug)]
pub struct RunGroups {
    operation_metrics: Vec<OperationMetric>,
    device_metrics: Vec<DeviceMetric>,
    groups: Vec<engine::GroupStats>,
}

impl RunGroups {
    pub fn new(job: &Job, tally: Tally) -> Self {
        Self::from_groups(job, tally.groups)
    }

    /// The groups of `job`, in group order, as a run's tally holds them (or a store gives them
    /// back).
    pub fn from_groups(job: &Job, groups: Vec<engine::GroupStats>) -> Self {
        Self {
            operation_metrics: job.operation_metrics().to_vec(),
            device_metrics: job.device_metrics().to_vec(),
            groups,
        }
    }

    /// Bin `bin` of the operation metric named `metric`, or the device metric's summary (`bin`
    /// 0), as its groups' accumulators in group order; `None` for a (metric, bin) the run did not
    /// summarise.
    pub fn of(&self, metric: &str, bin: u64) -> Option<Vec<Accumulator>> {
        let bin = usize::try_from(bin).ok()?;
        let take = |pick: &dyn Fn(&engine::GroupStats) -> Option<&Accumulator>| {
            self.groups.iter().map(|g| pick(g).cloned()).collect()
        };
        match Metric::parse(metric)? {
            Metric::Operation(m) => {
                let m = self.operation_metrics.iter().position(|&o| o == m)?;
                let index = bin * self.operation_metrics.len() + m;
                take(&|g| g.operations.get(index))
            }
            Metric::Device(m) if bin == 0 => {
                let m = self.device_metrics.iter().position(|&d| d == m)?;
                take(&|g| g.devices.get(m))
            }
            Metric::Device(_) => None,
        }
    }

    /// Every (metric, bin) with its groups' accumulators in group order, moved out one at a time:
    /// each bin of the operation metrics, then each device metric (bin 0). Storing a Result
    /// encodes and drops each before taking the next, so the groups are never held twice (decoded
    /// and encoded), whatever the job's size.
    pub fn into_bins(self) -> impl Iterator<Item = (Metric, u64, Vec<Accumulator>)> {
        let (operation_metrics, device_metrics) = (self.operation_metrics, self.device_metrics);
        let (mut operations, mut devices): (Vec<_>, Vec<_>) = self
            .groups
            .into_iter()
            .map(|group| (group.operations.into_iter(), group.devices.into_iter()))
            .unzip();
        let bins = operations.first().map_or(0, |o| o.len()) / operation_metrics.len().max(1);
        let per_bin = (0..bins as u64).flat_map(move |bin| {
            operation_metrics
                .clone()
                .into_iter()
                .map(move |m| (Metric::Operation(m), bin))
        });
        let of_bins = per_bin.map(move |(metric, bin)| {
            let groups = operations.iter_mut().filter_map(Iterator::next).collect();
            (metric, bin, groups)
        });
        let of_devices = device_metrics.into_iter().map(move |m| {
            let groups = devices.iter_mut().filter_map(Iterator::next).collect();
            (Metric::Device(m), 0, groups)
        });
        of_bins.chain(of_devices)
    }
}

fn summarize_devices(job: &Job, tally: &Tally) -> BTreeMap<String, Summary> {
    job.device_metrics()
        .iter()
        .enumerate()
        .map(|(m, metric)| {
            let groups: Vec<&Accumulator> = tally.groups.iter().map(|g| &g.devices[m]).collect();
            let mut summary = summarize(&groups, 1);
            answer_thresholds(job, Metric::Device(*metric), &groups, 1, &mut summary);
            (metric.name().to_owned(), summary)
        })
        .collect()
}

/// Why a precision target on the quantile `name` is not checked yet though the groups bound its
/// level: only once `min(q, 1 - q)` of the devices that ran count [`MIN_TAIL_UNITS`] (a `p95`
/// from 100 devices, a `p99` from 500). The groups' count alone bounds a level sooner, and a
/// stop there picks an interval narrow by chance from the few values beyond: a `p99` target
/// was met at 304 devices of one operation, 3 values beyond it, and such stopped intervals held
/// the truth in 89 % of jobs (an outside probe, 7 December 2026).
fn too_few_devices(name: &str, devices: u64) -> Option<String> {
    let (_, q) = quantile_keyed(name)?;
    let rarer = q.min(1.0 - q);
    let needed = (MIN_TAIL_UNITS / rarer).round();
    (devices < needed as u64).then(|| {
        format!(
            "a precision target on {name} is checked once {needed:.0} devices have run ({MIN_TAIL_UNITS} \
             devices' share beyond the level), and {devices} have"
        )
    })
}

/// The relative 95 % CI half-width of the precision statistic in the last bin (half the
/// interval's width, which need not be symmetric; infinite when the statistic is 0 and the
/// interval is not), and why the data cannot bound it (a quantile's `reason`: a level with one
/// meets no target), if they cannot.
fn precision_half_width(
    job: &Job,
    tally: &Tally,
    precision: &job::Precision,
) -> (f64, Option<String>) {
    let metric = job
        .operation_metrics()
        .iter()
        .position(|m| *m == precision.metric)
        .expect("validated");
    let last_bin = usize::try_from(job.bins() - 1).expect("bins fit in memory");
    let per_device =
        Metric::Operation(precision.metric).values_per_device(job.bin_range(last_bin as u64));
    let summary = summarize(&operation_groups(job, tally, last_bin, metric), per_device);
    let (value, [lo, hi], unbounded) = match precision.statistic {
        Statistic::Mean => (summary.mean, summary.mean_ci95, None),
        Statistic::Quantile(name) => {
            let quantile = &summary.quantiles[name];
            let reason = quantile.reason.clone();
            let reason = reason.or_else(|| too_few_devices(name, tally.devices));
            (quantile.value, quantile.ci95, reason)
        }
    };
    let half_width = 0.5 * (hi - lo);
    let relative = if half_width == 0.0 {
        0.0
    } else {
        half_width / value.abs()
    };
    (relative, unbounded)
}
