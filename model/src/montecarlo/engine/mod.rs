//! Runs a [`Job`]: devices in parallel, each on its own random stream, merged in a fixed order.
//!
//! Determinism: device `d` draws from ChaCha8 seeded with the job seed on stream `d`, whatever thread
//! runs it. Each batch of devices is cut into `G` contiguous chunks (at most [`GROUPS`]); chunk `g` runs
//! its devices in index order into its own accumulators and is merged into group `g` in batch order.
//! Nothing depends on the number of threads, so results are bit-identical for any `--threads`.
//!
//! Independence: a device's operations share its scatter and wear state, so they are not independent
//! samples; groups of devices are. Confidence intervals come from the spread between the groups
//! (see [`crate::stats`]).
//!
//! Its rooms: `plan` works a job out once for the hot loop and runs its batches, each group on
//! its own thread; `draws` draws a device's or an operation's scattered parameters; `lanes`
//! runs devices in lockstep on a kernel's lanes, operation after operation; `accumulate` counts
//! each operation's values into the bins and each device's into the sensitivity cells. Here: the
//! public surface (batches, groups, their tally) that the service and the summaries see.

use super::correlation::Correlation;
use super::distribution::{standard_normal_cdf, standard_normal_quantile, stratified_probability};
use super::job::{Job, Parameter, Per, SamplerKind, Scatter, SensitivityMethod};
use super::kernel::{Kernel, LaneWork};
use super::lives::{DeviceLife, GroupLives};
use super::metric::{DeviceMetric, Metric, OperationMetric};
use super::sensitivity::{LaneCells, SensitivityPlan, SensitivityStats};
use crate::feistel::Permutation;
use crate::lanes::{Mask, Real};
use crate::operation::{Conditions, Needs, Operation, Outcome, Outcomes, Setup};
use crate::scenario::Scenario;
use crate::stats::{Accumulator, LaneSums, tails};
use crate::wear::{DeviceWear, WearLaw};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use std::borrow::Cow;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

mod accumulate;
mod draws;
mod lanes;
pub mod limit_state;
mod plan;

use accumulate::*;
use draws::*;
use lanes::*;
use plan::*;

/// The most groups (independent units for confidence intervals) a summary is built from.
pub const GROUPS: u64 = 32;

/// LHS permutations draw from streams at and above this; device streams are below it.
const LHS_STREAM_BASE: u64 = 1 << 63;

/// Sensitivity analysis: device `d`'s `B` draws come from stream `2^62 + d`, its operations' `B'`
/// draws from stream `2^62 + 2^61 + d` (devices are fewer than `2^61`).
const SOBOL_DEVICE_STREAM_BASE: u64 = 1 << 62;
const SOBOL_OPERATION_STREAM_BASE: u64 = (1 << 62) | (1 << 61);

/// What the engine reports while it runs, and how it is stopped.
pub trait Observer: Sync {
    /// Called from worker threads as devices run (every 1024 operations of a batch,
    /// `OPERATIONS_PER_LOOK`) and finish; keep it cheap.
    fn progress(&self, _operations_done: u64, _operations_total: u64) {}
    /// Checked before every batch of devices and as [`Observer::progress`] is told within one:
    /// cooperative cancellation.
    fn cancelled(&self) -> bool {
        false
    }
}

/// An observer that ignores progress and never cancels.
pub struct Silent;
impl Observer for Silent {}

/// A cancellation flag and a progress callback.
pub struct Watch<'a, F: Fn(u64, u64) + Sync> {
    pub cancel: &'a AtomicBool,
    pub on_progress: F,
}

impl<F: Fn(u64, u64) + Sync> Observer for Watch<'_, F> {
    fn progress(&self, done: u64, total: u64) {
        (self.on_progress)(done, total);
    }
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

/// The run was cancelled through its [`Observer`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the job was cancelled")]
pub struct Cancelled;

/// Accumulators of every requested metric for one group of devices: operation metrics by
/// `[bin][metric]`, then device metrics. Serialisable exactly (every float by its bits), so a group
/// run on one machine merges on another into the same numbers.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GroupStats {
    pub operations: Vec<Accumulator>,
    pub devices: Vec<Accumulator>,
    /// With failure criteria: the devices' lives.
    pub lives: GroupLives,
    /// Operations whose bounce sequence reached `max_bounces` with another bounce to come.
    #[serde(default)]
    pub operations_at_max_bounces: u64,
    /// Per scatter entry, in the job's order: draws of its truncated distribution that fell
    /// outside the window and were drawn again.
    #[serde(default)]
    pub truncation_rejections: Vec<u64>,
    /// With a sensitivity analysis: its sums.
    #[serde(default)]
    pub sensitivity: SensitivityStats,
}

impl GroupStats {
    fn new(job: &Job, sensitivity: Option<&SensitivityPlan>, keep_tails: bool) -> Self {
        // A metric's limit and list of thresholds, both counted exactly as the values arrive, and
        // (`keep_tails`) its most extreme values, kept within a budget per metric over the bins.
        let empty = |metric, keep: Option<u32>| {
            let keep = keep.filter(|_| keep_tails);
            let thresholds = job.thresholds().get(&metric).map_or(&[][..], Vec::as_slice);
            Accumulator::new(job.limits().get(&metric).copied())
                .counting(thresholds)
                .keeping(keep)
        };
        let keep = tails::keep_for_bins(job.bins());
        let per_bin: Vec<Accumulator> = job
            .operation_metrics()
            .iter()
            .map(|m| empty(Metric::Operation(*m), keep))
            .collect();
        let bins = usize::try_from(job.bins()).expect("bins fit in memory");
        // Laid out at its size at once: collected from a `flat_map` (no size hint) the vector
        // grew by doubling, each time into fresh pages copied over, a third of a 1000-bin job's
        // samples (docs/performance-history.md, "A group's accumulators laid out at their size").
        let mut operations = Vec::with_capacity(bins.saturating_mul(per_bin.len()));
        for _ in 0..bins {
            operations.extend(per_bin.iter().cloned());
        }
        Self {
            operations,
            devices: job
                .device_metrics()
                .iter()
                .map(|m| empty(Metric::Device(*m), Some(tails::MAX_KEEP)))
                .collect(),
            lives: GroupLives::default(),
            operations_at_max_bounces: 0,
            truncation_rejections: vec![0; job.scatter().len()],
            sensitivity: sensitivity
                .map(|plan| SensitivityStats::new(plan, bins))
                .unwrap_or_default(),
        }
    }

    /// Adds `other`'s accumulators to these, entry by entry: the same group of a later batch.
    pub fn merge(&mut self, other: &GroupStats) {
        for (mine, theirs) in self.operations.iter_mut().zip(&other.operations) {
            mine.merge(theirs);
        }
        for (mine, theirs) in self.devices.iter_mut().zip(&other.devices) {
            mine.merge(theirs);
        }
        self.lives.merge(&other.lives);
        self.operations_at_max_bounces += other.operations_at_max_bounces;
        add_counts(
            &mut self.truncation_rejections,
            &other.truncation_rejections,
        );
        self.sensitivity.merge(&other.sensitivity);
    }
}

/// Adds `other` to `counts` entry by entry (a missing entry counts 0).
pub fn add_counts(counts: &mut Vec<u64>, other: &[u64]) {
    if counts.len() < other.len() {
        counts.resize(other.len(), 0);
    }
    for (count, add) in counts.iter_mut().zip(other) {
        *count += add;
    }
}

/// Everything a run produced before it is summarised: one [`GroupStats`] per group.
#[derive(Debug, Clone)]
pub struct Tally {
    pub groups: Vec<GroupStats>,
    pub devices: u64,
}

/// The devices one batch runs: `first..first + size`. Every job runs batch 0 (its `devices`); a
/// precision target adds batches of the same size, the last one cut to `max_devices`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Batch {
    pub index: u64,
    pub first: u64,
    pub size: u64,
}

impl Batch {
    /// Batch `index` of `job`, or `None` when the job can never run that many devices.
    pub fn of(job: &Job, index: u64) -> Option<Self> {
        let size = job.spec().devices;
        let max_devices = job.precision().map_or(size, |p| p.max_devices);
        let first = index
            .checked_mul(size)
            .filter(|first| *first < max_devices)?;
        Some(Self {
            index,
            first,
            size: size.min(max_devices - first),
        })
    }

    /// The groups the batch is cut into: the unit one machine runs alone.
    pub fn groups(&self) -> u64 {
        GROUPS.min(self.size)
    }

    /// The devices of group `group`: a contiguous share of the batch.
    pub fn group_devices(&self, group: u64) -> std::ops::Range<u64> {
        self.first + group_start(self.size, group)..self.first + group_start(self.size, group + 1)
    }
}

/// Where group `group` of a batch of `size` devices starts, counted from the batch's first
/// device: the groups cut the batch into contiguous shares ([`Batch::group_devices`]).
pub(super) fn group_start(size: u64, group: u64) -> u64 {
    size * group / GROUPS.min(size)
}

/// Runs group `group` of `batch` alone: exactly the accumulators [`run`] builds for it, so groups
/// run anywhere, in any order, and put back with [`Tally::add_batch`] in order give the same
/// Result to the bit.
pub fn run_group(
    job: &Job,
    batch: Batch,
    group: u64,
    observer: &dyn Observer,
) -> Result<GroupStats, Cancelled> {
    assert!(
        group < batch.groups() && Batch::of(job, batch.index) == Some(batch),
        "group {group} of {batch:?} is not part of the job"
    );
    let plan = Plan::new(job, Kernel::active());
    let devices = batch.group_devices(group);
    let strata = plan.batch_strata(batch.index, batch.size);
    let chunk = Chunk {
        first: batch.first,
        size: batch.size,
        strata: strata.as_ref(),
    };
    let total = (devices.end - devices.start) * job.spec().operations;
    plan.run_chunk(&chunk, group, observer, &AtomicU64::new(0), total)
}

/// The device-level values each device of `batch` draws, as the run draws them: one row per
/// device, one value per scatter entry in the job's order (NaN where the entry is per operation):
/// what an analysis of the inputs, or a test of the sampler, reads.
pub fn batch_draws(job: &Job, batch: Batch) -> Vec<Vec<f64>> {
    let plan = Plan::new(job, Kernel::SCALAR);
    let strata = plan.batch_strata(batch.index, batch.size);
    draws_of(&plan, batch, |device| device, strata.as_ref())
}

/// The device-level values of the devices' `B` samples in a Sobol' analysis, as
/// [`batch_draws`] gives the devices' own (the `A` samples): what a check of the indices against
/// another implementation on the same samples reads.
pub fn sobol_b_draws(job: &Job, batch: Batch) -> Vec<Vec<f64>> {
    let plan = Plan::new(job, Kernel::SCALAR);
    draws_of(
        &plan,
        batch,
        |device| SOBOL_DEVICE_STREAM_BASE | device,
        None,
    )
}

fn draws_of(
    plan: &Plan<'_>,
    batch: Batch,
    stream_of: impl Fn(u64) -> u64,
    strata: Option<&Strata>,
) -> Vec<Vec<f64>> {
    let chunk = Chunk {
        first: batch.first,
        size: batch.size,
        strata,
    };
    let lanes = usize::try_from(batch.size).expect("batch fits in memory");
    let mut rejections = vec![0; plan.job.scatter().len()];
    plan.draw_devices(&chunk, 0, lanes, stream_of, strata, &mut rejections)
        .2
}

impl Tally {
    pub fn new() -> Self {
        Self {
            groups: Vec::new(),
            devices: 0,
        }
    }

    /// Adds the next batch's groups, in group order (a batch smaller than [`GROUPS`] devices has
    /// fewer groups, merged into the first ones).
    pub fn add_batch(&mut self, batch: Batch, groups: Vec<GroupStats>) {
        debug_assert_eq!(batch.first, self.devices, "batches are added in order");
        if self.groups.is_empty() {
            self.groups = groups;
        } else {
            for (group, stats) in self.groups.iter_mut().zip(&groups) {
                group.merge(stats);
            }
        }
        self.devices += batch.size;
    }
}

impl Default for Tally {
    fn default() -> Self {
        Self::new()
    }
}

/// Runs the job on the current rayon pool on [`Kernel::active`]: the first batch of
/// `devices`, then, with a precision target, more batches of the same size until `accept` says the
/// target is met or `max_devices` ran.
pub fn run(
    job: &Job,
    observer: &dyn Observer,
    accept: impl FnMut(&Tally) -> bool,
) -> Result<Tally, Cancelled> {
    run_on(Kernel::active(), job, observer, accept)
}

/// [`run`] with the given kernel: every kernel gives the same bits.
pub fn run_on(
    kernel: Kernel,
    job: &Job,
    observer: &dyn Observer,
    accept: impl FnMut(&Tally) -> bool,
) -> Result<Tally, Cancelled> {
    run_plan(&Plan::new(job, kernel), Tally::new(), observer, accept)
}

/// [`run_on`] from the batches in `tally` on, as if they had just run here: the batches after
/// them until `accept` says so, and the same bits as one run of them all. Progress counts the
/// operations of this run alone.
pub fn run_on_from(
    kernel: Kernel,
    job: &Job,
    tally: Tally,
    observer: &dyn Observer,
    accept: impl FnMut(&Tally) -> bool,
) -> Result<Tally, Cancelled> {
    run_plan(&Plan::new(job, kernel), tally, observer, accept)
}

/// [`run_on`] for a run whose groups make its Result and nothing else
/// ([`crate::montecarlo::summarize_job`]): the most extreme values each accumulator keeps for a
/// threshold asked after the run ([`crate::stats::Tails`]) are not kept, since no summary reads
/// them. Every summary is the same to the bit; a query of these groups after the run answers a
/// threshold that no list counted from the sketch alone.
pub fn run_for_result(
    kernel: Kernel,
    job: &Job,
    observer: &dyn Observer,
    accept: impl FnMut(&Tally) -> bool,
) -> Result<Tally, Cancelled> {
    let mut plan = Plan::new(job, kernel);
    plan.keep_tails = false;
    run_plan(&plan, Tally::new(), observer, accept)
}

/// The batches of [`run_on`] after those in `tally` as `plan` runs them.
fn run_plan(
    plan: &Plan<'_>,
    mut tally: Tally,
    observer: &dyn Observer,
    mut accept: impl FnMut(&Tally) -> bool,
) -> Result<Tally, Cancelled> {
    let job = plan.job;
    let done = AtomicU64::new(0);
    let start = tally.devices;
    let mut next = Batch::of(job, start.div_ceil(job.spec().devices));
    while let Some(batch) = next {
        let total = (batch.first + batch.size - start) * job.spec().operations;
        let stats = plan.run_batch(batch.index, batch.first, batch.size, observer, &done, total)?;
        tally.add_batch(batch, stats);
        next = Batch::of(job, batch.index + 1).filter(|_| !accept(&tally));
    }
    Ok(tally)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{Value, json};

    /// Group 0 of the job's first batch on `kernel`, each operation's draws going straight into
    /// lanes or through a [`Draws`] per lane.
    fn group_zero(job: &Job, kernel: Kernel, lane_draws: bool) -> GroupStats {
        let mut plan = Plan::new(job, kernel);
        assert!(plan.lane_draws, "the job draws lane values per operation");
        plan.lane_draws = lane_draws;
        let batch = Batch::of(job, 0).expect("a first batch");
        let chunk = Chunk {
            first: batch.first,
            size: batch.size,
            strata: None,
        };
        plan.run_chunk(&chunk, 0, &Silent, &AtomicU64::new(0), 0)
            .expect("not cancelled")
    }

    /// Remembers every count of operations done it is told; cancelled once one reaches
    /// `cancel_at`.
    struct Counting {
        told: std::sync::Mutex<Vec<u64>>,
        cancel_at: u64,
    }

    impl Observer for Counting {
        fn progress(&self, done: u64, _total: u64) {
            self.told.lock().unwrap().push(done);
        }
        fn cancelled(&self) -> bool {
            self.told
                .lock()
                .unwrap()
                .iter()
                .any(|&done| done >= self.cancel_at)
        }
    }

    /// A batch's LHS strata give each device-level entry each of the batch's strata once, the
    /// entries and the batches in other orders, the same whenever they are asked for (a group
    /// run alone asks for its own devices' only).
    #[test]
    fn lhs_strata_fill_each_stratum_once_in_orders_of_their_own() {
        let job = Job::from_json(
            r#"{"devices": 1000, "operations": 2, "seed": 9, "sampler": "lhs",
                "scatter": [
                  {"parameter": "contact_radius_m", "per": "device",
                   "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 1e-3, "min": 1e-3}},
                  {"parameter": "impact_velocity_m_s", "per": "operation",
                   "distribution": {"kind": "uniform", "min": 0.2, "max": 0.3}},
                  {"parameter": "dynamic_yield_pressure_pa", "per": "device",
                   "distribution": {"kind": "lognormal", "median": 3e8, "sigma": 0.1}}]}"#,
            || 0,
        )
        .unwrap();
        let plan = Plan::new(&job, Kernel::SCALAR);
        let strata_of = |batch: u64, size: u64| {
            let strata = plan.batch_strata(batch, size).expect("stratified");
            assert_eq!(strata.permutations.len(), 2, "the device-level entries");
            (0..2)
                .map(|k| {
                    (0..size as usize)
                        .map(|device| {
                            let (stratum, of) = strata.of(k, device);
                            assert_eq!(u64::from(of), size);
                            stratum
                        })
                        .collect::<Vec<u32>>()
                })
                .collect::<Vec<_>>()
        };
        let first = strata_of(0, 1000);
        for order in &first {
            let mut sorted = order.clone();
            sorted.sort_unstable();
            assert!(sorted.iter().copied().eq(0..1000), "each stratum once");
        }
        assert_ne!(first[0], first[1], "entries in orders of their own");
        assert_eq!(first, strata_of(0, 1000), "the same when asked again");
        assert_ne!(first, strata_of(1, 1000), "another batch, other orders");
        // An odd size, whose permutation walks its cycles back into the batch.
        let odd = strata_of(3, 37);
        assert!(
            odd.iter()
                .all(|o| o.len() == 37 && o.iter().all(|&s| s < 37))
        );
    }

    /// A run continued from the batches an earlier one ran is the run of them all, to the bit,
    /// wherever the earlier one stopped (the service's job run whole hands its work on so), a
    /// last batch cut short by `max_devices` included; its progress counts its own operations.
    #[test]
    fn a_run_continued_from_its_batches_is_the_run_of_them_all() {
        let job = Job::from_json(
            r#"{"devices": 16, "operations": 3, "seed": 5,
                "scatter": [{"parameter": "contact_radius_m", "per": "device",
                    "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 1e-3, "min": 1e-3}}],
                "precision": {"metric": "e1", "relative_half_width": 1e-9, "max_devices": 72}}"#,
            || 0,
        )
        .unwrap();
        let kernel = Kernel::active();
        let all = run_on(kernel, &job, &Silent, |_| false).unwrap();
        assert_eq!(all.devices, 72);
        for stop in [16, 48, 64] {
            let first = run_on(kernel, &job, &Silent, |tally| tally.devices >= stop).unwrap();
            assert_eq!(first.devices, stop);
            let told = Counting {
                told: Default::default(),
                cancel_at: u64::MAX,
            };
            let rest = run_on_from(kernel, &job, first, &told, |_| false).unwrap();
            assert_eq!(
                (rest.devices, &rest.groups),
                (72, &all.groups),
                "from {stop}"
            );
            let told = told.told.into_inner().unwrap();
            assert_eq!(told.last(), Some(&((72 - stop) * 3)), "from {stop}");
        }
        let ended = run_on_from(kernel, &job, all.clone(), &Silent, |_| false).unwrap();
        assert_eq!(ended.groups, all.groups, "nothing left to run");
    }

    /// A batch of few devices with many operations each (a sweep of the HTTP API found one of 20
    /// devices x 10^8 operations at progress 0 and running half a minute after its cancellation)
    /// tells its progress every [`OPERATIONS_PER_LOOK`] operations, and stops at the first look
    /// after its job was cancelled.
    #[test]
    fn a_long_batch_tells_its_progress_as_it_runs_and_stops_when_cancelled() {
        let job = |operations: u64| {
            Job::from_json(
                &format!(r#"{{"devices": 4, "operations": {operations}, "seed": 2}}"#),
                || 0,
            )
            .unwrap()
        };
        let operations = 3 * OPERATIONS_PER_LOOK + 100;
        let whole = Counting {
            told: Default::default(),
            cancel_at: u64::MAX,
        };
        let tally = run_on(Kernel::active(), &job(operations), &whole, |_| true).unwrap();
        let looks = (1..=3).map(|look| 4 * look * OPERATIONS_PER_LOOK);
        let told = whole.told.into_inner().unwrap();
        assert_eq!(told, looks.chain([4 * operations]).collect::<Vec<_>>());
        let silent = run_on(Kernel::active(), &job(operations), &Silent, |_| true).unwrap();
        assert_eq!(tally.groups, silent.groups, "looking changes nothing");

        let cancelled = Counting {
            told: Default::default(),
            cancel_at: 1,
        };
        let long = job(100_000_000);
        assert_eq!(
            run_on(Kernel::active(), &long, &cancelled, |_| true).unwrap_err(),
            Cancelled
        );
        assert_eq!(
            cancelled.told.into_inner().unwrap(),
            [4 * OPERATIONS_PER_LOOK]
        );
    }

    #[test]
    fn a_run_for_its_result_keeps_no_extremes_and_the_same_summaries() {
        let job = Job::from_json(
            r#"{"devices": 40, "operations": 30, "seed": 4, "bin_operations": 10,
                "limits": {"total_bounce_s": [{"above": 0.012}]}}"#,
            || 0,
        )
        .unwrap();
        let kept = run_on(Kernel::active(), &job, &Silent, |_| false).unwrap();
        let left_out = run_for_result(Kernel::active(), &job, &Silent, |_| false).unwrap();
        let tails = |tally: &Tally| -> Vec<bool> {
            let group = serde_json::to_value(&tally.groups[0]).unwrap();
            ["operations", "devices"]
                .iter()
                .flat_map(|part| group[part].as_array().unwrap().clone())
                .map(|accumulator| !accumulator["tails"].is_null())
                .collect()
        };
        assert!(tails(&kept).iter().all(|&kept| kept));
        assert!(tails(&left_out).iter().all(|&kept| !kept));
        let summaries = |tally: &Tally| {
            let summary = crate::montecarlo::summarize_job(&job, tally, 1.0);
            let mut result = serde_json::to_value(summary).unwrap();
            result.as_object_mut().unwrap().remove("timing");
            result
        };
        assert_eq!(summaries(&kept), summaries(&left_out));
    }

    #[test]
    fn operations_drawn_straight_into_lanes_give_the_bits_of_draws_per_lane() {
        let reference: Value =
            serde_json::from_str(include_str!("../../../../tests/data/reference_jobs.json"))
                .unwrap();
        let mut spec = reference["mechanical"].clone();
        // Group 0 holds 45 devices: a full batch of every width, and a remainder. 70 operations
        // draw ahead twice. The velocity's window rejects about a quarter of its draws; the
        // radius is drawn per operation as well, after it.
        spec["devices"] = json!(45 * GROUPS);
        spec["operations"] = json!(70);
        spec["scatter"][2]["distribution"]["min"] = json!(0.21);
        let radius = json!({"parameter": "contact_radius_m", "per": "operation",
            "distribution": {"kind": "normal", "mean": 0.0077, "sd": 0.0008, "min": 0.001}});
        spec["scatter"][0] = radius;
        let job = Job::from_json(&spec.to_string(), || 0).unwrap();
        for kernel in Kernel::all() {
            let straight = group_zero(&job, kernel, true);
            assert!(
                straight.truncation_rejections[2] > 0,
                "{kernel:?}: no rejection"
            );
            assert!(
                straight == group_zero(&job, kernel, false),
                "{kernel:?}: lane draws differ from draws per lane"
            );
        }
    }

    /// Small groups share a kernel's lanes ([`Plan::tasks`]) and each comes out as it does alone,
    /// to the bit: accumulators and extremes, lives, the devices' and the operations' rejections.
    #[test]
    fn groups_sharing_lanes_give_each_group_the_stats_it_has_alone() {
        // 50 devices: groups of 1 and 2, a few to a kernel. Both windows reject about a third
        // of the draws.
        let job = Job::from_json(
            r#"{"devices": 50, "operations": 30, "bin_operations": 10, "seed": 4,
                "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
                "scatter": [
                  {"parameter": "contact_radius_m", "per": "device",
                   "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 1.5e-3, "min": 7e-3}},
                  {"parameter": "impact_velocity_m_s", "per": "operation",
                   "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.215}}],
                "limits": {"total_bounce_s": 0.011},
                "failure": {"e1": {"below": 0.40}}}"#,
            || 0,
        )
        .unwrap();
        let plan = Plan::new(&job, Kernel::best());
        let tasks = plan.tasks(50);
        assert!(
            tasks.iter().any(|groups| groups.end - groups.start > 1),
            "{tasks:?}: no groups share lanes"
        );
        let shared = plan
            .run_batch(0, 0, 50, &Silent, &AtomicU64::new(0), 0)
            .unwrap();
        assert_eq!(shared.len(), 32);
        let chunk = Chunk {
            first: 0,
            size: 50,
            strata: None,
        };
        for (group, stats) in (0..).zip(&shared) {
            let alone = plan
                .run_chunk(&chunk, group, &Silent, &AtomicU64::new(0), 0)
                .unwrap();
            assert!(*stats == alone, "group {group}");
        }
        let rejected = |entry: usize| -> u64 {
            (shared.iter())
                .map(|stats| stats.truncation_rejections[entry])
                .sum()
        };
        assert!(rejected(0) > 0 && rejected(1) > 0, "no rejections");
        let failed =
            |stats: &GroupStats| stats.lives.counts.values().any(|&[failed, _]| failed > 0);
        assert!(shared.iter().any(failed), "no device failed");
    }
}
