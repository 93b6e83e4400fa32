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

use super::correlation::Correlation;
use super::distribution::{standard_normal_cdf, standard_normal_quantile, stratified_probability};
use super::job::{Job, Parameter, Per, SamplerKind, Scatter, SensitivityMethod};
use super::kernel::{Kernel, LaneWork};
use super::lives::{DeviceLife, GroupLives};
use super::metric::{DeviceMetric, Metric, OperationMetric};
use super::sensitivity::{LaneCells, SensitivityPlan, SensitivityStats};
use crate::lanes::{Mask, Real};
use crate::operation::{Conditions, Needs, Operation, Outcome, Outcomes, Setup};
use crate::scenario::Scenario;
use crate::stats::{Accumulator, LaneSums, tails};
use crate::wear::{DeviceWear, WearLaw};
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

pub mod limit_state;

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
    /// Called from worker threads as devices finish; keep it cheap.
    fn progress(&self, _operations_done: u64, _operations_total: u64) {}
    /// Checked before every device: cooperative cancellation.
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
    fn new(job: &Job, sensitivity: Option<&SensitivityPlan>) -> Self {
        // A metric's limit and list of thresholds, both counted exactly as the values arrive, and
        // its most extreme values, kept within a budget per metric over the bins.
        let empty = |metric, keep| {
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
        Self {
            operations: (0..bins).flat_map(|_| per_bin.iter().cloned()).collect(),
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

    fn merge(&mut self, other: &GroupStats) {
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

/// Parameters of one device or operation that scatter can replace.
#[derive(Debug, PartialEq)]
struct Draws {
    radius_m: f64,
    pressure_pa: f64,
    conditions: Conditions,
    /// Drawn constants of the scenario ([`Parameter::is_scenario_constant`]): the scenario is
    /// rebuilt with them.
    constants: Vec<(Parameter, f64)>,
}

impl Clone for Draws {
    fn clone(&self) -> Self {
        Self {
            radius_m: self.radius_m,
            pressure_pa: self.pressure_pa,
            conditions: self.conditions,
            constants: self.constants.clone(),
        }
    }

    /// In place, reusing the constants' allocation: each lane's operation draws start from its
    /// device's at every operation.
    fn clone_from(&mut self, source: &Self) {
        self.radius_m = source.radius_m;
        self.pressure_pa = source.pressure_pa;
        self.conditions = source.conditions;
        self.constants.clone_from(&source.constants);
    }
}

impl Draws {
    fn set(&mut self, parameter: Parameter, value: f64) {
        if parameter.is_scenario_constant() {
            self.constants.push((parameter, value));
            return;
        }
        match parameter {
            Parameter::ContactRadius => self.radius_m = value,
            Parameter::DynamicYieldPressure => self.pressure_pa = value,
            Parameter::ImpactVelocity => self.conditions.impact_velocity_m_s = Some(value),
            Parameter::DropHeight => self.conditions.drop_height_m = value,
            Parameter::StaticForce => self.conditions.static_force_n = value,
            Parameter::Current => self.conditions.current_a = value,
            Parameter::BreakdownField => self.conditions.breakdown_field_v_per_m = value,
            _ => unreachable!("scenario constants are kept apart"),
        }
    }
}

/// What a scenario's constants fix for all its operations: built once for the job, and again for
/// each draw that scatters one of them.
#[derive(Debug, Clone)]
struct Model {
    setup: Setup,
    wear: WearLaw,
}

impl Model {
    fn new(scenario: &Scenario) -> Self {
        Self {
            setup: Setup::new(scenario),
            wear: WearLaw::new(scenario),
        }
    }
}

/// The scatter entries of one `per`, in the job's order, and the correlation among some of them.
struct Entries<'a> {
    /// Each entry with its index in the job's scatter.
    scatter: Vec<(usize, &'a Scatter)>,
    /// The job's correlation, when it is over entries of this `per`, and each entry's row in its
    /// matrix (if it has one).
    correlation: Option<(&'a Correlation, Vec<Option<usize>>)>,
}

impl<'a> Entries<'a> {
    fn new(job: &'a Job, per: Per) -> Self {
        let scatter: Vec<_> = job
            .scatter()
            .iter()
            .enumerate()
            .filter(|(_, s)| s.per == per)
            .collect();
        let correlation = job.correlation().filter(|c| c.per() == per).map(|c| {
            let rows = scatter
                .iter()
                .map(|(index, _)| c.members().iter().position(|m| m == index))
                .collect();
            (c, rows)
        });
        Self {
            scatter,
            correlation,
        }
    }

    fn is_empty(&self) -> bool {
        self.scatter.is_empty()
    }

    /// The number of entries, each set once per draw.
    fn len(&self) -> usize {
        self.scatter.len()
    }

    /// Draws every entry from `rng`, in the job's order, and hands each value to `set` with the
    /// entry's index in the job's scatter: entry `k` in stratum `permutations[k][local]` under
    /// LHS (`strata`), otherwise at random, counting the rejections of truncated draws by entry.
    /// Correlated entries draw a standard normal each (from their stratum under LHS), correlated
    /// together and then mapped through `Phi` and the marginal's inverse CDF.
    fn draw(
        &self,
        job: &Job,
        strata: Option<(&[Vec<u32>], usize)>,
        rng: &mut ChaCha8Rng,
        rejections: &mut [u64],
        mut set: impl FnMut(usize, f64),
    ) {
        let mut normals = match &self.correlation {
            Some((correlation, _)) => vec![0.0; correlation.members().len()],
            None => Vec::new(),
        };
        for (k, &(index, scatter)) in self.scatter.iter().enumerate() {
            let stratum = strata.map(|(permutations, local)| {
                let strata = u32::try_from(permutations[k].len()).expect("batch fits u32");
                (permutations[k][local], strata)
            });
            if let Some(row) = self.correlation.as_ref().and_then(|(_, rows)| rows[k]) {
                normals[row] = match stratum {
                    Some((stratum, strata)) => {
                        standard_normal_quantile(stratified_probability(stratum, strata, rng))
                    }
                    None => rng.sample(StandardNormal),
                };
                continue;
            }
            let value = match stratum {
                Some((stratum, strata)) => scatter.distribution.stratified(stratum, strata, rng),
                None => scatter
                    .distribution
                    .sample_counting(rng, &mut rejections[index]),
            };
            set(index, value);
        }
        if let Some((correlation, _)) = &self.correlation {
            correlation.correlate(&mut normals);
            for (&index, normal) in correlation.members().iter().zip(normals) {
                // Phi rounds to 0 or 1 beyond about 8 standard deviations; stay inside (0, 1).
                let u = standard_normal_cdf(normal).clamp(f64::MIN_POSITIVE, 1.0 - f64::EPSILON);
                set(index, job.scatter()[index].distribution.quantile(u));
            }
        }
    }
}

/// The job worked out for the hot loop.
struct Plan<'a> {
    job: &'a Job,
    /// The nominal scenario's model.
    model: Model,
    nominal: Draws,
    device_scatter: Entries<'a>,
    operation_scatter: Entries<'a>,
    /// Per-operation scatter touches only the velocity, radius or pressure: no operation rebuild.
    cheap_operation_scatter: bool,
    /// Per-operation scatter draws a constant of the scenario: a model for every operation.
    operation_constants: bool,
    /// Per-operation scatter draws lane values only, none correlated: without a sensitivity
    /// analysis, which reads the draws, they go straight into lanes ([`Variant::draw_lanes`]).
    lane_draws: bool,
    needs: Needs,
    /// Wear changes the radius only if an arc can burn and a later operation exists.
    track_wear: bool,
    /// Only lane parameters (speed, radius, pressure) scatter, so devices can run in lockstep.
    lockstep: bool,
    kernel: Kernel,
    sensitivity: Option<SensitivityPlan>,
}

impl<'a> Plan<'a> {
    fn new(job: &'a Job, kernel: Kernel) -> Self {
        let scenario = job.scenario();
        let spec = scenario.spec();
        let model = Model::new(scenario);
        let nominal = Draws {
            radius_m: spec.material.contact_radius_m,
            pressure_pa: spec.material.dynamic_yield_pressure_pa,
            conditions: Conditions::nominal(scenario),
            constants: Vec::new(),
        };
        let (device_scatter, operation_scatter) = (
            Entries::new(job, Per::Device),
            Entries::new(job, Per::Operation),
        );
        let cheap_operation_scatter = operation_scatter
            .scatter
            .iter()
            .all(|(_, s)| s.parameter.is_lane_value());
        let operation_constants = operation_scatter
            .scatter
            .iter()
            .any(|(_, s)| s.parameter.is_scenario_constant());
        let lane_draws = !operation_scatter.is_empty()
            && cheap_operation_scatter
            && operation_scatter.correlation.is_none();
        let arcs_scattered = job
            .scatter()
            .iter()
            .any(|s| matches!(s.parameter, Parameter::Current | Parameter::SupplyVoltage));
        let can_arc = model
            .setup
            .operation(&nominal.conditions, job.spec().fidelity)
            .arcs()
            || arcs_scattered;
        let wear = model.wear;
        let mut plan = Self {
            job,
            model,
            nominal,
            device_scatter,
            operation_scatter,
            cheap_operation_scatter,
            operation_constants,
            lane_draws,
            needs: Needs {
                impact: job.operation_metrics().iter().any(|m| m.needs_impact())
                    || job
                        .device_metrics()
                        .iter()
                        .any(|m| Metric::Device(*m).needs_impact())
                    || job.failure().iter().any(|(m, _)| m.needs_impact()),
            },
            track_wear: can_arc && job.spec().operations > 1 && wear.changes_surface(),
            lockstep: job.scatter().iter().all(|s| s.parameter.is_lane_value()),
            kernel,
            sensitivity: None,
        };
        plan.sensitivity = job.sensitivity().map(|method| {
            // Sums are taken about the nominal scenario's values: a new device's operation.
            let fidelity = job.spec().fidelity;
            let nominal = &plan.nominal;
            let operation = plan.model.setup.operation(&nominal.conditions, fidelity);
            let outcome = operation
                .run_lanes(
                    operation.impact_velocity_m_s(),
                    nominal.radius_m,
                    nominal.pressure_pa,
                    plan.needs,
                    |_, _, _, _| {},
                )
                .lane(0);
            let operation_shifts = job
                .operation_metrics()
                .iter()
                .map(|m| m.value(&outcome))
                .collect();
            let device_shifts = job
                .device_metrics()
                .iter()
                .map(|m| plan.device_metric(&plan.model, *m, nominal, &DeviceWear::default()))
                .collect();
            SensitivityPlan::new(job, method, operation_shifts, device_shifts)
        });
        plan
    }

    /// The model of the scenario with the constants `draws` holds: the nominal one when it holds none.
    fn model(&self, draws: &Draws) -> Cow<'_, Model> {
        if draws.constants.is_empty() {
            return Cow::Borrowed(&self.model);
        }
        let scenario = self.job.scenario().with_draws(|spec| {
            for &(parameter, value) in &draws.constants {
                parameter.set_in(spec, value);
            }
        });
        Cow::Owned(Model::new(&scenario))
    }

    /// Draws the device-level scatter of `lanes` devices from `stream_of(device)`, each from its
    /// own stream: their draws, their streams as the operations go on to use them, and the drawn
    /// values by scatter entry (NaN for entries drawn per operation).
    fn draw_devices(
        &self,
        chunk: &Chunk<'_>,
        first_local: u64,
        lanes: usize,
        stream_of: impl Fn(u64) -> u64,
        strata: Option<&[Vec<u32>]>,
        rejections: &mut [u64],
    ) -> (Vec<Draws>, Vec<ChaCha8Rng>, Vec<Vec<f64>>) {
        let job = self.job;
        let mut drawn = (
            Vec::with_capacity(lanes),
            Vec::with_capacity(lanes),
            Vec::with_capacity(lanes),
        );
        for local in first_local..first_local + lanes as u64 {
            let mut rng = ChaCha8Rng::seed_from_u64(job.seed());
            rng.set_stream(stream_of(chunk.first + local));
            let local_index = usize::try_from(local).expect("batch fits in memory");
            let mut device = self.nominal.clone();
            let mut values = vec![f64::NAN; job.scatter().len()];
            self.device_scatter.draw(
                job,
                strata.map(|p| (p, local_index)),
                &mut rng,
                rejections,
                |index, value| {
                    device.set(job.scatter()[index].parameter, value);
                    values[index] = value;
                },
            );
            drawn.0.push(device);
            drawn.1.push(rng);
            drawn.2.push(values);
        }
        drawn
    }

    /// Runs the `active` devices of the chunk from `first_local` on, in lockstep on `L::LANES`
    /// lanes (spare lanes compute a copy of the first device: they draw from a copy of its
    /// stream, count no rejections, and nothing reads their values), into `stats`:
    /// each from its own stream, with the draws and the arithmetic it would have alone. Each
    /// lane sums its device's values of a bin in the lanes ([`LaneSums`]), and the bin's
    /// accumulators add those sums device after device, so the sums come out the same to the bit
    /// for any number of lanes.
    ///
    /// With Sobol' indices over device-level parameters, the devices run again alongside, as
    /// variants: `B`, drawn from the devices' Sobol' streams, and `AB_i`, the devices with
    /// parameter `i` taken from `B`, which draw their operations from the devices' own streams
    /// as the devices do. With operation-level parameters, each operation of the devices is also
    /// evaluated at `B'`, drawn from the devices' operation Sobol' streams, and at `AB'_i`, in
    /// the device's state.
    #[inline(always)]
    fn run_devices<L: Real>(
        &self,
        chunk: &Chunk<'_>,
        first_local: u64,
        active: usize,
        stats: &mut GroupStats,
    ) {
        let job = self.job;
        let lanes = L::LANES;
        debug_assert!(
            active == lanes || (active < lanes && self.sensitivity.is_none()),
            "spare lanes only without a sensitivity analysis"
        );
        let sensitivity = self.sensitivity.as_ref();
        let sobol = sensitivity.filter(|s| s.method == SensitivityMethod::Sobol);
        let mut scratch = vec![0; job.scatter().len()];
        let mut variants = self.variants::<L>(chunk, first_local, active, stats, &mut scratch);
        let operation_sobol = sobol.filter(|p| !p.operation_inputs.is_empty());
        let mut operation_rngs = match operation_sobol {
            Some(_) => self.operation_sobol_rngs(chunk.first + first_local, lanes),
            None => Vec::new(),
        };
        let mut cells = sensitivity.map(|plan| LaneCells::new(plan, lanes));
        let lane_draws = self.lane_draws && sensitivity.is_none();

        let mut failed_at = vec![None; lanes];
        let metrics = job.operation_metrics();
        let operations = job.spec().operations;
        let mut sums: Vec<LaneSums<L>> = Vec::with_capacity(metrics.len());
        let bins = usize::try_from(job.bins()).expect("bins fit in memory");
        // Per evaluation (variants, then B' and AB'_i), lane and metric: this operation's values,
        // for the sensitivity cells.
        let evaluations = variants.len() + sobol.map_or(0, |p| p.operation_evaluations());
        let mut values = vec![0.0; evaluations * lanes * metrics.len()];
        let variant_count = variants.len();
        let swaps_at = variant_count * lanes * metrics.len();
        for bin_index in 0..bins {
            let start = job.bin_operations() * bin_index as u64;
            let end = (start + job.bin_operations()).min(operations);
            let bin = bin_index * metrics.len()..(bin_index + 1) * metrics.len();
            for op in start..end {
                for (v, variant) in variants.iter_mut().enumerate() {
                    let rejections: &mut [u64] = if v == 0 {
                        &mut stats.truncation_rejections
                    } else {
                        &mut scratch
                    };
                    let outcomes = variant.step(self, lane_draws, rejections, operations - op);
                    if v == 0 {
                        if let Some(plan) = operation_sobol {
                            let values = &mut values[swaps_at..];
                            let rngs = &mut operation_rngs;
                            self.evaluate_operation_swaps(
                                plan,
                                variant,
                                rngs,
                                &mut scratch,
                                values,
                            );
                        }
                        let (into, first) = (&mut stats.operations[bin.clone()], op == start);
                        accumulate(metrics, &outcomes, into, &mut sums, first, active);
                        stats.operations_at_max_bounces += (0..active)
                            .map(|k| u64::from(outcomes.truncated.lane(k)))
                            .sum::<u64>();
                    }
                    variant.wear.add_lanes(&outcomes);
                    // Each lane's outcome, only for what reads it: the sensitivity cells and
                    // the failure criteria.
                    if cells.is_none() && (v != 0 || job.failure().is_empty()) {
                        continue;
                    }
                    let lanes_read = LanesRead {
                        variant: v,
                        active,
                        operation: op,
                        cells: cells.is_some(),
                    };
                    self.read_lanes(lanes_read, variant, &outcomes, &mut values, &mut failed_at);
                }
                if let Some(cells) = &mut cells {
                    cells.push_operation(&values, &variants[0].inputs, variant_count);
                }
            }
            if let Some(cells) = &mut cells {
                cells.merge_bin(&mut stats.sensitivity, bin_index);
            }
            for (accumulator, sums) in stats.operations[bin].iter_mut().zip(&sums) {
                accumulator.add_lanes(sums, active);
            }
        }
        self.finish_devices(
            chunk.first + first_local,
            &variants,
            &failed_at[..active],
            stats,
        );
    }

    /// The devices (`A`, in `active` of the lanes) with their draws and streams, and with Sobol'
    /// indices over device-level parameters the variants that run alongside: `B`, drawn from the
    /// devices' Sobol' streams, and each `AB_i`, the devices with parameter `i` taken from `B`.
    #[inline(always)]
    fn variants<L: Real>(
        &self,
        chunk: &Chunk<'_>,
        first_local: u64,
        active: usize,
        stats: &mut GroupStats,
        scratch: &mut [u64],
    ) -> Vec<Variant<'_, L>> {
        let (job, lanes) = (self.job, L::LANES);
        let (mut draws, mut rngs, mut inputs) = self.draw_devices(
            chunk,
            first_local,
            active,
            |device| device,
            chunk.permutations,
            &mut stats.truncation_rejections,
        );
        draws.resize(lanes, draws[0].clone());
        rngs.resize(lanes, rngs[0].clone());
        inputs.resize(lanes, inputs[0].clone());
        let mut variants = vec![Variant::<L>::new(self, draws, rngs, inputs, active)];
        let device_sobol = self
            .sensitivity
            .as_ref()
            .filter(|s| s.method == SensitivityMethod::Sobol && !s.device_inputs.is_empty());
        let Some(plan) = device_sobol else {
            return variants;
        };
        let (b_draws, b_rngs, b_inputs) = self.draw_devices(
            chunk,
            first_local,
            lanes,
            |device| SOBOL_DEVICE_STREAM_BASE | device,
            None,
            scratch,
        );
        let a = &variants[0];
        let swapped: Vec<Variant<L>> = plan
            .device_inputs
            .iter()
            .map(|&input| {
                let (mut draws, mut inputs) = (a.draws.clone(), a.inputs.clone());
                for k in 0..lanes {
                    let value = b_inputs[k][input];
                    draws[k].set(job.scatter()[input].parameter, value);
                    inputs[k][input] = value;
                }
                Variant::new(self, draws, a.rngs.clone(), inputs, lanes)
            })
            .collect();
        variants.push(Variant::new(self, b_draws, b_rngs, b_inputs, lanes));
        variants.extend(swapped);
        variants
    }

    /// Each lane's stream of operation-level `B'` draws: the device's own operation Sobol'
    /// stream, lane `k` being device `first + k`.
    fn operation_sobol_rngs(&self, first: u64, lanes: usize) -> Vec<ChaCha8Rng> {
        (0..lanes as u64)
            .map(|k| {
                let mut rng = ChaCha8Rng::seed_from_u64(self.job.seed());
                rng.set_stream(SOBOL_OPERATION_STREAM_BASE | (first + k));
                rng
            })
            .collect()
    }

    /// Each lane's outcome of one operation, only for what reads it: its metrics' values for
    /// the sensitivity cells, and, for the devices themselves, whether it fails them.
    #[inline(always)]
    fn read_lanes<L: Real>(
        &self,
        read: LanesRead,
        variant: &Variant<'_, L>,
        outcomes: &Outcomes<L>,
        values: &mut [f64],
        failed_at: &mut [Option<u64>],
    ) {
        let metrics = self.job.operation_metrics();
        for (k, failed_at) in failed_at.iter_mut().enumerate() {
            let outcome = outcomes.lane(k);
            if read.cells {
                let at = (read.variant * L::LANES + k) * metrics.len();
                for (slot, metric) in values[at..at + metrics.len()].iter_mut().zip(metrics) {
                    *slot = metric.value(&outcome);
                }
            }
            if read.variant != 0 || k >= read.active {
                continue;
            }
            if failed_at.is_none()
                && self.fails(
                    &variant.model,
                    &outcome,
                    &variant.draws[k],
                    &variant.wear.lane(k),
                )
            {
                *failed_at = Some(read.operation + 1);
            }
        }
    }

    /// What the devices leave at the end of the test: their device metrics, their share of the
    /// device-level sensitivity, and their lives (device `first + k` in lane `k`).
    #[inline(always)]
    fn finish_devices<L: Real>(
        &self,
        first: u64,
        variants: &[Variant<'_, L>],
        failed_at: &[Option<u64>],
        stats: &mut GroupStats,
    ) {
        let (job, a) = (self.job, &variants[0]);
        for (k, failed_at) in failed_at.iter().enumerate() {
            for (accumulator, metric) in stats.devices.iter_mut().zip(job.device_metrics()) {
                accumulator.push(self.device_metric(
                    &a.model,
                    *metric,
                    &a.draws[k],
                    &a.wear.lane(k),
                ));
            }
            if let Some(plan) = &self.sensitivity {
                self.push_device_sensitivity(plan, variants, k, &mut stats.sensitivity);
            }
            if !job.failure().is_empty() {
                stats.lives.record(DeviceLife {
                    device: first + k as u64,
                    operations_to_failure: failed_at.unwrap_or(job.spec().operations),
                    censored: failed_at.is_none(),
                });
            }
        }
    }

    /// Evaluates the operation the devices (`a`) just drew at `B'`, drawn from `rngs`, and at
    /// `AB'_i`, in the devices' state: the values go to `values`, per evaluation, lane and metric.
    #[inline(always)]
    fn evaluate_operation_swaps<L: Real>(
        &self,
        plan: &SensitivityPlan,
        a: &Variant<'_, L>,
        rngs: &mut [ChaCha8Rng],
        rejections: &mut [u64],
        values: &mut [f64],
    ) {
        let job = self.job;
        let (lanes, metrics) = (L::LANES, job.operation_metrics());
        let mut b_draws = Vec::with_capacity(lanes);
        let mut b_values = vec![vec![f64::NAN; job.scatter().len()]; lanes];
        for (k, rng) in rngs.iter_mut().enumerate() {
            let mut draws = a.draws[k].clone();
            let row = &mut b_values[k];
            self.operation_scatter
                .draw(job, None, rng, rejections, |index, value| {
                    draws.set(job.scatter()[index].parameter, value);
                    row[index] = value;
                });
            b_draws.push(draws);
        }
        let mut record = |evaluation: usize, outcomes: Outcomes<L>| {
            for k in 0..lanes {
                let outcome = outcomes.lane(k);
                let at = (evaluation * lanes + k) * metrics.len();
                for (slot, metric) in values[at..at + metrics.len()].iter_mut().zip(metrics) {
                    *slot = metric.value(&outcome);
                }
            }
        };
        record(0, a.evaluate(self, &b_draws));
        for (i, &input) in plan.operation_inputs.iter().enumerate() {
            let swapped: Vec<Draws> = (0..lanes)
                .map(|k| {
                    let mut draws = a.op_draws[k].clone();
                    draws.set(job.scatter()[input].parameter, b_values[k][input]);
                    draws
                })
                .collect();
            record(1 + i, a.evaluate(self, &swapped));
        }
    }

    /// Lane `k`'s device metrics in every variant, into the device cells of `stats`.
    fn push_device_sensitivity<L: Real>(
        &self,
        plan: &SensitivityPlan,
        variants: &[Variant<'_, L>],
        k: usize,
        stats: &mut SensitivityStats,
    ) {
        let job = self.job;
        let first_cell = usize::try_from(job.bins()).expect("bins fit in memory")
            * job.operation_metrics().len();
        let a = &variants[0];
        let inputs: Vec<f64> = plan.device_inputs.iter().map(|&i| a.inputs[k][i]).collect();
        for (j, metric) in job.device_metrics().iter().enumerate() {
            let value = |v: &Variant<'_, L>| {
                self.device_metric(&v.model, *metric, &v.draws[k], &v.wear.lane(k))
            };
            let a_value = value(a);
            if plan.device_sobol() {
                let ab: Vec<f64> = variants[2..].iter().map(value).collect();
                stats.device[first_cell + j].push(a_value, value(&variants[1]), &ab);
            }
            stats.regression[first_cell + j].push(&inputs, a_value);
        }
    }

    /// Whether any failure criterion is met by this operation or by the device's state after it.
    #[inline]
    fn fails(
        &self,
        model: &Model,
        outcome: &Outcome,
        draws: &Draws,
        device_wear: &DeviceWear,
    ) -> bool {
        self.job.failure().iter().any(|(metric, criterion)| {
            let value = match metric {
                Metric::Operation(metric) => metric.value(outcome),
                Metric::Device(metric) => self.device_metric(model, *metric, draws, device_wear),
            };
            criterion.fails(value)
        })
    }

    /// A device metric of the device with `draws` and its `model` (per-operation draws do not
    /// enter: the device's own values do, as for its radius).
    fn device_metric(
        &self,
        model: &Model,
        metric: DeviceMetric,
        draws: &Draws,
        device_wear: &DeviceWear,
    ) -> f64 {
        let wear = &model.wear;
        let energy_j = device_wear.cumulative_arc_energy_j;
        let final_radius_m = || {
            if energy_j > 0.0 {
                wear.radius_m(draws.radius_m, energy_j)
            } else {
                draws.radius_m
            }
        };
        let eroded_mass_split_kg = || {
            wear.eroded_mass_split_kg(energy_j)
                .expect("the job checked that the scenario gives the polarity")
        };
        match metric {
            DeviceMetric::CumulativeArcEnergy => energy_j,
            DeviceMetric::ErodedMass => wear.eroded_mass_kg(energy_j),
            DeviceMetric::FinalRadius => final_radius_m(),
            DeviceMetric::FinalKappa => model.setup.kappa_law().at(
                final_radius_m(),
                wear.pressure_pa(draws.pressure_pa, energy_j),
            ),
            DeviceMetric::CumulativePlasticWork => device_wear.cumulative_plastic_work_j,
            DeviceMetric::AnodeErodedMass => eroded_mass_split_kg().0,
            DeviceMetric::CathodeErodedMass => eroded_mass_split_kg().1,
        }
    }

    /// LHS permutations of one batch: one per device-level parameter, from the batch's own stream.
    fn lhs_permutations(&self, batch: u64, size: u64) -> Vec<Vec<u32>> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.job.seed());
        rng.set_stream(LHS_STREAM_BASE | batch);
        let size = u32::try_from(size).expect("an LHS batch has fewer than 2^32 devices");
        self.device_scatter
            .scatter
            .iter()
            .map(|_| {
                let mut permutation: Vec<u32> = (0..size).collect();
                permutation.shuffle(&mut rng);
                permutation
            })
            .collect()
    }

    /// The LHS permutations of batch `batch` of `size` devices, when the job samples that way.
    fn batch_permutations(&self, batch: u64, size: u64) -> Option<Vec<Vec<u32>>> {
        (self.job.spec().sampler == SamplerKind::Lhs && !self.device_scatter.is_empty())
            .then(|| self.lhs_permutations(batch, size))
    }

    /// Runs devices `first..first + size` as batch `batch`, one chunk per group, in parallel.
    fn run_batch(
        &self,
        batch: u64,
        first: u64,
        size: u64,
        observer: &dyn Observer,
        done: &AtomicU64,
        total: u64,
    ) -> Result<Vec<GroupStats>, Cancelled> {
        let permutations = self.batch_permutations(batch, size);
        let chunk = Chunk {
            first,
            size,
            permutations: permutations.as_deref(),
        };
        (0..GROUPS.min(size))
            .into_par_iter()
            .map(|group| self.run_chunk(&chunk, group, observer, done, total))
            .collect()
    }

    /// Runs group `group`'s contiguous share of a batch, its devices in index order.
    fn run_chunk(
        &self,
        chunk: &Chunk<'_>,
        group: u64,
        observer: &dyn Observer,
        done: &AtomicU64,
        total: u64,
    ) -> Result<GroupStats, Cancelled> {
        let operations = self.job.spec().operations;
        let groups = GROUPS.min(chunk.size);
        let mut stats = GroupStats::new(self.job, self.sensitivity.as_ref());
        let (start, end) = (
            chunk.size * group / groups,
            chunk.size * (group + 1) / groups,
        );
        let mut local = start;
        while local < end {
            if observer.cancelled() {
                return Err(Cancelled);
            }
            let left = end - local;
            let lanes = self.kernel.lanes() as u64;
            // A batch of lanes, full or (without a sensitivity analysis) at least half full, its
            // spare lanes computing a copy of its first device, whose values nobody reads: half a
            // batch costs less in lockstep than its devices one by one (docs/performance.md).
            // Fewer devices run one by one, through the same code.
            let (kernel, devices) = if self.lockstep
                && (left >= lanes || (2 * left >= lanes && self.sensitivity.is_none()))
            {
                (self.kernel, left.min(lanes))
            } else {
                (Kernel::SCALAR, 1)
            };
            kernel.run(Devices {
                plan: self,
                chunk,
                first_local: local,
                active: usize::try_from(devices).expect("a batch fits in memory"),
                stats: &mut stats,
            });
            let ran = operations * devices;
            observer.progress(done.fetch_add(ran, Ordering::Relaxed) + ran, total);
            local += devices;
        }
        Ok(stats)
    }
}

/// Which lanes' outcomes [`Plan::read_lanes`] reads, and for what.
#[derive(Clone, Copy)]
struct LanesRead {
    /// The variant evaluated (0 for the devices themselves).
    variant: usize,
    /// Lanes that hold devices.
    active: usize,
    /// The operation, from 0.
    operation: u64,
    /// Whether the sensitivity cells read the values.
    cells: bool,
}

/// One operation's values of each metric, one dispatch per metric: into the lanes' sums (about
/// the shift the first operation of the bin sets, `first_of_bin`) and counted in the sketches.
#[inline(always)]
fn accumulate<L: Real>(
    metrics: &[OperationMetric],
    outcomes: &Outcomes<L>,
    accumulators: &mut [Accumulator],
    sums: &mut Vec<LaneSums<L>>,
    first_of_bin: bool,
    active: usize,
) {
    if metrics.is_empty() {
        return;
    }
    let mut columns = [&outcomes.impact_velocity_m_s; OperationMetric::ALL.len()];
    for (column, metric) in columns.iter_mut().zip(metrics) {
        *column = metric.lanes(outcomes);
    }
    let columns = &columns[..metrics.len()];
    if first_of_bin {
        sums.clear();
        sums.extend(
            accumulators
                .iter()
                .zip(columns)
                .map(|(accumulator, column)| LaneSums::new(accumulator, column.lane(0))),
        );
    }
    for (sums, column) in sums.iter_mut().zip(columns) {
        sums.push(**column);
    }
    Accumulator::count_lanes(accumulators, columns, active);
}

/// Devices running in lockstep with their draws and state: the job's devices, or, for a
/// sensitivity analysis, the same devices with some parameters drawn again.
struct Variant<'p, L: Real> {
    draws: Vec<Draws>,
    /// Each lane's stream, as its operations draw from it.
    rngs: Vec<ChaCha8Rng>,
    /// Each lane's parameter values by scatter entry: the device's, and this operation's.
    inputs: Vec<Vec<f64>>,
    /// The model of the lanes' scenario constants (lanes in lockstep share them).
    model: Cow<'p, Model>,
    /// The operation of the device's conditions, and the lanes' speed, radius and pressure.
    operation: Operation,
    speed: L,
    radius_m: L,
    pressure_pa: L,
    wear: DeviceWear<L>,
    /// This operation's draws.
    op_draws: Vec<Draws>,
    /// The next operations' per-operation draws, drawn ahead from each lane's stream in one
    /// loop per lane ([`Variant::draw_operation`]): `(scatter index, value)` in the order
    /// [`Entries::draw`] sets them, lane after lane, operation after operation.
    ahead: Vec<(usize, f64)>,
    /// The same for [`Variant::draw_lanes`]: values only, by operation, lane and entry, so that
    /// one operation's values of an entry are a short stride apart (drawn lane after lane).
    lane_ahead: Vec<f64>,
    /// Operations per lane in `ahead` (or `lane_ahead`), and the next one to use.
    ahead_operations: usize,
    ahead_next: usize,
    /// Lanes that are devices; the others are spare and count no rejections.
    active: usize,
    /// The rejections spare lanes count, which nobody reads.
    spare_rejections: Vec<u64>,
}

/// Operations whose per-operation draws a lane takes from its stream in one go.
const DRAW_AHEAD: u64 = 64;

impl<'p, L: Real> Variant<'p, L> {
    fn new(
        plan: &'p Plan<'_>,
        draws: Vec<Draws>,
        rngs: Vec<ChaCha8Rng>,
        inputs: Vec<Vec<f64>>,
        active: usize,
    ) -> Self {
        let model = plan.model(&draws[0]);
        let operation = model
            .setup
            .operation(&draws[0].conditions, plan.job.spec().fidelity);
        let base_speed = operation.impact_velocity_m_s();
        Self {
            speed: L::from_fn(|k| {
                draws[k]
                    .conditions
                    .impact_velocity_m_s
                    .unwrap_or(base_speed)
            }),
            radius_m: L::from_fn(|k| draws[k].radius_m),
            pressure_pa: L::from_fn(|k| draws[k].pressure_pa),
            wear: DeviceWear::new(),
            op_draws: draws.clone(),
            draws,
            rngs,
            inputs,
            model,
            operation,
            ahead: Vec::new(),
            lane_ahead: Vec::new(),
            ahead_operations: 0,
            ahead_next: 0,
            active,
            spare_rejections: vec![0; plan.job.scatter().len()],
        }
    }

    /// Draws the next operation's per-operation scatter of every lane from its stream, of
    /// `remaining` operations (this one included) the device has left. Each lane draws up to
    /// [`DRAW_AHEAD`] operations at a time from its stream, in one loop: the same values from the
    /// same streams in the same order as one operation at a time, and never a draw past the
    /// device's last operation, so the truncation rejections count the same.
    #[inline(always)]
    fn draw_operation(&mut self, plan: &Plan<'_>, rejections: &mut [u64], remaining: u64) {
        let entries = plan.operation_scatter.len();
        if entries == 0 {
            return;
        }
        let job = plan.job;
        if self.start_block(remaining) {
            let mut ahead = std::mem::take(&mut self.ahead);
            ahead.clear();
            self.draw_block(rejections, |_, _, rng, rejections| {
                plan.operation_scatter
                    .draw(job, None, rng, rejections, |index, value| {
                        ahead.push((index, value));
                    });
            });
            self.ahead = ahead;
        }
        for k in 0..L::LANES {
            let draws = &mut self.op_draws[k];
            draws.clone_from(&self.draws[k]);
            let row = &mut self.inputs[k];
            let at = (k * self.ahead_operations + self.ahead_next) * entries;
            for &(index, value) in &self.ahead[at..at + entries] {
                draws.set(job.scatter()[index].parameter, value);
                row[index] = value;
            }
        }
        self.ahead_next += 1;
    }

    /// Whether the operations drawn ahead are used up; if so, starts a new block of up to
    /// [`DRAW_AHEAD`] operations, never past the device's last (`remaining` left, this one
    /// included), so that the rejections count as if drawn one operation at a time.
    #[inline(always)]
    fn start_block(&mut self, remaining: u64) -> bool {
        if self.ahead_next < self.ahead_operations {
            return false;
        }
        self.ahead_operations =
            usize::try_from(remaining.min(DRAW_AHEAD)).expect("a block fits in memory");
        self.ahead_next = 0;
        true
    }

    /// Draws the block [`Variant::start_block`] started: lane after lane, each from its own
    /// stream, `draw(lane, operation, stream, rejections)` for each of the block's operations;
    /// the spare lanes count their rejections apart, where nobody reads them.
    #[inline(always)]
    fn draw_block(
        &mut self,
        rejections: &mut [u64],
        mut draw: impl FnMut(usize, usize, &mut ChaCha8Rng, &mut [u64]),
    ) {
        for (k, rng) in self.rngs.iter_mut().enumerate() {
            let rejections: &mut [u64] = if k < self.active {
                &mut *rejections
            } else {
                &mut self.spare_rejections
            };
            for op in 0..self.ahead_operations {
                draw(k, op, rng, rejections);
            }
        }
    }

    /// Draws this operation's inputs and evaluates it in every lane: from the lanes' own draws
    /// (`lane_draws`), or one lane after another.
    #[inline(always)]
    fn step(
        &mut self,
        plan: &Plan<'_>,
        lane_draws: bool,
        rejections: &mut [u64],
        remaining: u64,
    ) -> Outcomes<L> {
        if lane_draws {
            let (speed, radius_m, pressure_pa) = self.draw_lanes(plan, rejections, remaining);
            self.evaluate_lanes(
                plan,
                &self.operation,
                self.model.wear,
                speed,
                radius_m,
                pressure_pa,
            )
        } else {
            self.draw_operation(plan, rejections, remaining);
            self.evaluate(plan, &self.op_draws)
        }
    }

    /// [`Variant::draw_operation`] when the operation draws only lane values, uncorrelated, and
    /// nothing reads the draws but the lanes (no sensitivity analysis): the same values from the
    /// same streams in the same order, counting the same rejections, straight into this
    /// operation's speed, radius and pressure lanes, without a [`Draws`] and an input row per
    /// lane and operation.
    #[inline(always)]
    fn draw_lanes(&mut self, plan: &Plan<'_>, rejections: &mut [u64], remaining: u64) -> (L, L, L) {
        let entries = &plan.operation_scatter.scatter;
        let width = entries.len();
        if self.start_block(remaining) {
            let mut ahead = std::mem::take(&mut self.lane_ahead);
            ahead.resize(self.ahead_operations * L::LANES * width, 0.0);
            self.draw_block(rejections, |k, op, rng, rejections| {
                let at = (op * L::LANES + k) * width;
                for (slot, &(index, scatter)) in ahead[at..at + width].iter_mut().zip(entries) {
                    *slot = scatter
                        .distribution
                        .sample_counting(rng, &mut rejections[index]);
                }
            });
            self.lane_ahead = ahead;
        }
        let (mut speed, mut radius_m, mut pressure_pa) =
            (self.speed, self.radius_m, self.pressure_pa);
        let row = self.ahead_next * L::LANES * width;
        // In the job's order, as `Draws::set` takes them: a later entry of a parameter wins.
        for (e, &(_, scatter)) in entries.iter().enumerate() {
            let value = L::from_fn(|k| self.lane_ahead[row + k * width + e]);
            match scatter.parameter {
                Parameter::ImpactVelocity => speed = value,
                Parameter::ContactRadius => radius_m = value,
                Parameter::DynamicYieldPressure => pressure_pa = value,
                _ => unreachable!("only lane values draw straight into lanes"),
            }
        }
        self.ahead_next += 1;
        (speed, radius_m, pressure_pa)
    }

    /// The operation with the lanes' draws `op_draws` (this operation's, or swapped ones), on the
    /// lanes' surfaces as their wear has left them.
    #[inline(always)]
    fn evaluate(&self, plan: &Plan<'_>, op_draws: &[Draws]) -> Outcomes<L> {
        let fidelity = plan.job.spec().fidelity;
        let lane_speed = |d: &Draws| {
            d.conditions
                .impact_velocity_m_s
                .unwrap_or(self.operation.impact_velocity_m_s())
        };
        let (operation, wear_law, speed, radius_m, pressure_pa) =
            if plan.operation_scatter.is_empty() {
                (
                    self.operation,
                    self.model.wear,
                    self.speed,
                    self.radius_m,
                    self.pressure_pa,
                )
            } else if plan.cheap_operation_scatter {
                (
                    self.operation,
                    self.model.wear,
                    L::from_fn(|k| lane_speed(&op_draws[k])),
                    L::from_fn(|k| op_draws[k].radius_m),
                    L::from_fn(|k| op_draws[k].pressure_pa),
                )
            } else {
                debug_assert_eq!(L::LANES, 1, "only lane parameters scatter in lockstep");
                let draws = &op_draws[0];
                let model = if plan.operation_constants {
                    plan.model(draws)
                } else {
                    Cow::Borrowed(&*self.model)
                };
                let operation = model.setup.operation(&draws.conditions, fidelity);
                (
                    operation,
                    model.wear,
                    L::splat(operation.impact_velocity_m_s()),
                    L::splat(draws.radius_m),
                    L::splat(draws.pressure_pa),
                )
            };
        self.evaluate_lanes(plan, &operation, wear_law, speed, radius_m, pressure_pa)
    }

    /// The operation at the lanes' speed, radius and pressure, on the lanes' surfaces as their
    /// wear has left them.
    #[inline(always)]
    fn evaluate_lanes(
        &self,
        plan: &Plan<'_>,
        operation: &Operation,
        wear_law: WearLaw,
        speed: L,
        radius_m: L,
        pressure_pa: L,
    ) -> Outcomes<L> {
        let (radius_m, pressure_pa) = if plan.track_wear {
            let energy_j = self.wear.cumulative_arc_energy_j;
            let worn = L::splat(0.0).lt(energy_j);
            (
                L::select(worn, wear_law.radius_m(radius_m, energy_j), radius_m),
                L::select(
                    worn,
                    wear_law.pressure_pa(pressure_pa, energy_j),
                    pressure_pa,
                ),
            )
        } else {
            (radius_m, pressure_pa)
        };
        operation.run_lanes(speed, radius_m, pressure_pa, plan.needs, |_, _, _, _| {})
    }
}

/// One batch of devices, as its groups share it.
struct Chunk<'a> {
    first: u64,
    size: u64,
    permutations: Option<&'a [Vec<u32>]>,
}

/// The devices of a chunk from `first_local` on, as many as the kernel has lanes.
struct Devices<'p, 'a> {
    plan: &'p Plan<'a>,
    chunk: &'p Chunk<'p>,
    first_local: u64,
    /// The batch's devices: its first `active` lanes; the others copy the first device.
    active: usize,
    stats: &'p mut GroupStats,
}

impl LaneWork for Devices<'_, '_> {
    #[inline(always)]
    fn run<L: Real>(self) {
        self.plan
            .run_devices::<L>(self.chunk, self.first_local, self.active, self.stats);
    }
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
        let groups = self.groups();
        self.first + self.size * group / groups..self.first + self.size * (group + 1) / groups
    }
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
    let plan = Plan::new(job, Kernel::best());
    let permutations = plan.batch_permutations(batch.index, batch.size);
    let chunk = Chunk {
        first: batch.first,
        size: batch.size,
        permutations: permutations.as_deref(),
    };
    let devices = batch.group_devices(group);
    let total = (devices.end - devices.start) * job.spec().operations;
    plan.run_chunk(&chunk, group, observer, &AtomicU64::new(0), total)
}

/// The device-level values each device of `batch` draws, as the run draws them: one row per
/// device, one value per scatter entry in the job's order (NaN where the entry is per operation):
/// what an analysis of the inputs, or a test of the sampler, reads.
pub fn batch_draws(job: &Job, batch: Batch) -> Vec<Vec<f64>> {
    let plan = Plan::new(job, Kernel::SCALAR);
    let permutations = plan.batch_permutations(batch.index, batch.size);
    draws_of(&plan, batch, |device| device, permutations.as_deref())
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
    strata: Option<&[Vec<u32>]>,
) -> Vec<Vec<f64>> {
    let chunk = Chunk {
        first: batch.first,
        size: batch.size,
        permutations: strata,
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

/// Runs the job on the current rayon pool with the best kernel this CPU has: the first batch of
/// `devices`, then, with a precision target, more batches of the same size until `accept` says the
/// target is met or `max_devices` ran.
pub fn run(
    job: &Job,
    observer: &dyn Observer,
    accept: impl FnMut(&Tally) -> bool,
) -> Result<Tally, Cancelled> {
    run_on(Kernel::best(), job, observer, accept)
}

/// [`run`] with the given kernel: every kernel gives the same bits.
pub fn run_on(
    kernel: Kernel,
    job: &Job,
    observer: &dyn Observer,
    mut accept: impl FnMut(&Tally) -> bool,
) -> Result<Tally, Cancelled> {
    let plan = Plan::new(job, kernel);
    let done = AtomicU64::new(0);
    let mut tally = Tally::new();
    let mut next = Batch::of(job, 0);
    while let Some(batch) = next {
        let total = (batch.first + batch.size) * job.spec().operations;
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
            permutations: None,
        };
        plan.run_chunk(&chunk, 0, &Silent, &AtomicU64::new(0), 0)
            .expect("not cancelled")
    }

    #[test]
    fn operations_drawn_straight_into_lanes_give_the_bits_of_draws_per_lane() {
        let reference: Value =
            serde_json::from_str(include_str!("../../../tests/data/reference_jobs.json")).unwrap();
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
}
