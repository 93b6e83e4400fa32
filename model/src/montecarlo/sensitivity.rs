//! Which scattered parameters drive each metric (docs/contract.md "Sensitivity"): Sobol' indices
//! by pick-freeze and standardised regression coefficients, per metric and bin, from mergeable
//! sums kept in every group.
//!
//! The output is one operation's metric (or, for a device metric, one device's value at the end of
//! the test); its variance `V` is over every operation of the bin, across devices.
//! - **Device-level parameters** (`per: device`): each device also runs as `B` (every device-level
//!   parameter drawn again, from the device's Sobol' stream, operations included) and as `AB_i`
//!   (the device with parameter `i` from `B`, its operations drawn as the device's own). Operation
//!   `t` of the three gives `a`, `b`, `ab_i`: the indices are the unconditional first-order and
//!   total indices of the parameter for the operation's metric.
//! - **Operation-level parameters** (`per: operation`): each operation of a device is also
//!   evaluated, in the device's state, at `B'` (every operation-level parameter drawn again, from
//!   the device's operation Sobol' stream) and at `AB'_i`. The total index is the unconditional
//!   one; the first-order one is pooled over the devices' states, which lies between the
//!   unconditional first-order index and the total one, and equals the first when the parameter
//!   does not interact with what the device carries.
//!
//! The operations of one device share its draws and wear, so each device is one cluster of
//! samples ([`SobolAccumulator::merge_cluster`]): the intervals come from the spread between
//! devices. The regression is of the metric on every parameter's value, over the same operations
//! (device metrics: on the device-level parameters).

use super::job::{Job, Per, SensitivityMethod};
use crate::stats::regression::RegressionAccumulator;
use crate::stats::sobol::{IndexEstimate, SobolAccumulator, SobolEstimate};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// What the engine needs to know of a job's sensitivity analysis.
#[derive(Debug, Clone)]
pub(crate) struct SensitivityPlan {
    pub method: SensitivityMethod,
    /// The scatter entries drawn per device, by index in the job's scatter.
    pub device_inputs: Vec<usize>,
    /// The scatter entries drawn per operation.
    pub operation_inputs: Vec<usize>,
    /// Per operation metric and device metric: a new device's value with every scattered
    /// parameter at its median, near the mean, from which sums are taken.
    pub operation_shifts: Vec<f64>,
    pub device_shifts: Vec<f64>,
    /// Per scatter entry: its distribution's median.
    pub input_shifts: Vec<f64>,
}

impl SensitivityPlan {
    pub fn new(
        job: &Job,
        method: SensitivityMethod,
        operation_shifts: Vec<f64>,
        device_shifts: Vec<f64>,
        input_shifts: Vec<f64>,
    ) -> Self {
        let inputs = |per| {
            job.scatter()
                .iter()
                .enumerate()
                .filter(|(_, s)| s.per == per)
                .map(|(index, _)| index)
                .collect()
        };
        Self {
            method,
            device_inputs: inputs(Per::Device),
            operation_inputs: inputs(Per::Operation),
            operation_shifts,
            device_shifts,
            input_shifts,
        }
    }

    fn sobol(&self) -> bool {
        self.method == SensitivityMethod::Sobol
    }

    /// Whether devices run again as `B` and `AB_i`.
    pub fn device_sobol(&self) -> bool {
        self.sobol() && !self.device_inputs.is_empty()
    }

    /// Whether operations are evaluated again at `B'` and `AB'_i`.
    pub fn operation_sobol(&self) -> bool {
        self.sobol() && !self.operation_inputs.is_empty()
    }

    /// The evaluations of an operation at `B'` and `AB'_i`.
    pub fn operation_evaluations(&self) -> usize {
        if self.operation_sobol() {
            self.operation_inputs.len() + 1
        } else {
            0
        }
    }

    /// The regression's inputs of an operation metric: every scatter entry.
    fn operation_regression(&self, shift: f64) -> RegressionAccumulator {
        RegressionAccumulator::new(&self.input_shifts, shift)
    }

    /// The regression's inputs of a device metric: the device-level entries.
    fn device_regression(&self, shift: f64) -> RegressionAccumulator {
        let shifts: Vec<f64> = self
            .device_inputs
            .iter()
            .map(|&i| self.input_shifts[i])
            .collect();
        RegressionAccumulator::new(&shifts, shift)
    }
}

/// One group's sensitivity sums. Cells are `[bin][operation metric]`, then the device metrics.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct SensitivityStats {
    /// Per cell, over the device-level parameters (empty without Sobol' indices over them).
    pub device: Vec<SobolAccumulator>,
    /// Per operation cell, over the operation-level parameters (empty without them).
    pub operation: Vec<SobolAccumulator>,
    /// Per cell, the regression of the output on the parameters.
    pub regression: Vec<RegressionAccumulator>,
}

impl SensitivityStats {
    pub(crate) fn new(plan: &SensitivityPlan, bins: usize) -> Self {
        let operation_cells = || (0..bins).flat_map(|_| plan.operation_shifts.iter().copied());
        let device = if plan.device_sobol() {
            operation_cells()
                .chain(plan.device_shifts.iter().copied())
                .map(|shift| SobolAccumulator::new(plan.device_inputs.len(), shift))
                .collect()
        } else {
            Vec::new()
        };
        let operation = if plan.operation_sobol() {
            operation_cells()
                .map(|shift| SobolAccumulator::new(plan.operation_inputs.len(), shift))
                .collect()
        } else {
            Vec::new()
        };
        let regression = operation_cells()
            .map(|shift| plan.operation_regression(shift))
            .chain(
                plan.device_shifts
                    .iter()
                    .map(|&shift| plan.device_regression(shift)),
            )
            .collect();
        Self {
            device,
            operation,
            regression,
        }
    }

    pub fn merge(&mut self, other: &SensitivityStats) {
        for (mine, theirs) in self.device.iter_mut().zip(&other.device) {
            mine.merge(theirs);
        }
        for (mine, theirs) in self.operation.iter_mut().zip(&other.operation) {
            mine.merge(theirs);
        }
        for (mine, theirs) in self.regression.iter_mut().zip(&other.regression) {
            mine.merge(theirs);
        }
    }
}

/// Each lane's sums for the bin being run, one per operation metric: a device's operations are
/// gathered here and merged into the group's cells as one cluster at the end of the bin, lane
/// after lane, in device order whatever the number of lanes.
pub(crate) struct LaneCells<'p> {
    plan: &'p SensitivityPlan,
    lanes: usize,
    metrics: usize,
    device: Vec<SobolAccumulator>,
    operation: Vec<SobolAccumulator>,
    regression: Vec<RegressionAccumulator>,
    ab: Vec<f64>,
}

impl<'p> LaneCells<'p> {
    pub fn new(plan: &'p SensitivityPlan, lanes: usize) -> Self {
        let per_lane = |make: &dyn Fn(f64) -> Option<SobolAccumulator>| -> Vec<SobolAccumulator> {
            (0..lanes)
                .flat_map(|_| plan.operation_shifts.iter().filter_map(|&s| make(s)))
                .collect()
        };
        Self {
            plan,
            lanes,
            metrics: plan.operation_shifts.len(),
            device: per_lane(&|shift| {
                plan.device_sobol()
                    .then(|| SobolAccumulator::new(plan.device_inputs.len(), shift))
            }),
            operation: per_lane(&|shift| {
                plan.operation_sobol()
                    .then(|| SobolAccumulator::new(plan.operation_inputs.len(), shift))
            }),
            regression: (0..lanes)
                .flat_map(|_| {
                    plan.operation_shifts
                        .iter()
                        .map(|&shift| plan.operation_regression(shift))
                })
                .collect(),
            ab: Vec::new(),
        }
    }

    /// One operation of every lane. `values` holds, per evaluation, lane and metric, the
    /// operation's metric values: the variants (the devices, `B`, then `AB_i`), then `B'` and
    /// `AB'_i` from `variants` on. `inputs` are the devices' parameter values, by scatter entry.
    pub fn push_operation(&mut self, values: &[f64], inputs: &[Vec<f64>], variants: usize) {
        let (lanes, metrics) = (self.lanes, self.metrics);
        let at =
            |evaluation: usize, k: usize, m: usize| values[(evaluation * lanes + k) * metrics + m];
        for (k, lane_inputs) in inputs.iter().enumerate().take(lanes) {
            for m in 0..metrics {
                let cell = k * metrics + m;
                let a = at(0, k, m);
                if self.plan.device_sobol() {
                    self.ab.clear();
                    self.ab
                        .extend((0..self.plan.device_inputs.len()).map(|i| at(2 + i, k, m)));
                    self.device[cell].push_to_cluster(a, at(1, k, m), &self.ab);
                }
                if self.plan.operation_sobol() {
                    self.ab.clear();
                    self.ab.extend(
                        (0..self.plan.operation_inputs.len()).map(|i| at(variants + 1 + i, k, m)),
                    );
                    self.operation[cell].push_to_cluster(a, at(variants, k, m), &self.ab);
                }
                self.regression[cell].push(lane_inputs, a);
            }
        }
    }

    /// Merges each lane's bin into the group's cells of bin `bin`, lane after lane, and clears
    /// it for the next bin.
    pub fn merge_bin(&mut self, stats: &mut SensitivityStats, bin: usize) {
        let metrics = self.metrics;
        for k in 0..self.lanes {
            for m in 0..metrics {
                let (cell, lane_cell) = (bin * metrics + m, k * metrics + m);
                if let Some(lane) = self.device.get_mut(lane_cell) {
                    stats.device[cell].merge_cluster(lane);
                    lane.clear();
                }
                if let Some(lane) = self.operation.get_mut(lane_cell) {
                    stats.operation[cell].merge_cluster(lane);
                    lane.clear();
                }
                stats.regression[cell].merge(&self.regression[lane_cell]);
                self.regression[lane_cell].clear();
            }
        }
    }
}

/// The sensitivity of one metric in one bin (a device metric: over the devices, without
/// `op_start` and `op_end`).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensitivityBin {
    /// First operation of the bin (0-based); absent for a device metric.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub op_start: Option<u64>,
    /// End of the bin, exclusive; absent for a device metric.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub op_end: Option<u64>,
    /// By parameter name.
    pub indices: BTreeMap<String, ParameterSensitivity>,
    /// The share of the metric's variance the regression on every parameter explains (absent
    /// when the regression is degenerate: an output that does not vary, say).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub r_squared: Option<f64>,
    /// Why the Sobol' intervals say other than the spread between devices: the values of one
    /// device, whose intervals are their points; or values so far from the value their sums are
    /// taken about that the sums' rounding widens an interval by more than 0.001 either side (or
    /// leaves no digit of the variance).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// How much one parameter drives one metric in one bin.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterSensitivity {
    /// First-order Sobol' index: the share of the variance the parameter explains alone (method
    /// `sobol` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first: Option<IndexEstimate>,
    /// Total Sobol' index: the share it has a part in, interactions included (method `sobol`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub total: Option<IndexEstimate>,
    /// Standardised regression coefficient: standard deviations of the metric per standard
    /// deviation of the parameter (absent when the regression is degenerate).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub src: Option<f64>,
    /// Whether the parameter is drawn per `device` or per `operation`.
    pub per: Per,
}

impl SensitivityBin {
    /// Whether every index, interval and coefficient of the bin is a finite number.
    pub fn is_finite(&self) -> bool {
        let estimate = |e: &IndexEstimate| {
            [e.value, e.ci95[0], e.ci95[1]]
                .iter()
                .all(|v| v.is_finite())
        };
        self.r_squared.is_none_or(f64::is_finite)
            && self.indices.values().all(|p| {
                [p.first, p.total].iter().flatten().all(estimate)
                    && p.src.is_none_or(f64::is_finite)
            })
    }
}

/// How much the sums' rounding may widen an interval (either side, in the indices' units)
/// before a bin says so.
const WIDENING_SAID: f64 = 1e-3;

/// Why a bin's Sobol' intervals are their points: the values of one device.
const ONE_DEVICE: &str = "one device: the intervals come from the spread between devices, which \
     one device cannot show, so each is its point; run two devices or more for intervals";

/// Why a level's Sobol' intervals say other than the spread between devices, if they do: the
/// values of one device, or the sums' rounding widening them by more than [`WIDENING_SAID`].
fn not_the_spread(sums: &SobolAccumulator, estimate: &SobolEstimate, shift: f64) -> Option<String> {
    if sums.clusters() == 1 {
        return Some(ONE_DEVICE.to_owned());
    }
    (estimate.widening > WIDENING_SAID).then(|| rounding_reason(estimate, shift))
}

/// Why a bin's Sobol' intervals include their rounding ([`SobolEstimate`]).
fn rounding_reason(estimate: &SobolEstimate, shift: f64) -> String {
    let about = format!(
        "sums taken about {shift:.4e} (a new device's value with every scattered parameter at its \
         median)"
    );
    if estimate.offset_sds.is_infinite() {
        return format!(
            "the values' variance is lost in the rounding of {about}: every index is unknown, \
             given as 0 in [0, 1]"
        );
    }
    format!(
        "the values lie {:.2e} of their standard deviations from the {about}: the intervals \
         include the sums' rounding, which widens them by up to {:.2e} either side",
        estimate.offset_sds, estimate.widening
    )
}

/// The Result's `sensitivity`: per metric, its bins (a device metric: one entry), from the
/// groups' sums merged in group order.
pub fn summarize_sensitivity(
    job: &Job,
    groups: &[&SensitivityStats],
) -> BTreeMap<String, Vec<SensitivityBin>> {
    let Some(first) = groups.first() else {
        return BTreeMap::new();
    };
    let mut merged = (*first).clone();
    for group in &groups[1..] {
        merged.merge(group);
    }
    let metrics = job.operation_metrics().len();
    let scatter = job.scatter();
    let name = |index: usize| scatter[index].parameter.name();
    let inputs = |per| -> Vec<usize> {
        (0..scatter.len())
            .filter(|&i| scatter[i].per == per)
            .collect()
    };
    let (device_inputs, operation_inputs) = (inputs(Per::Device), inputs(Per::Operation));
    // One cell: Sobol' indices by level, regression over `regressors` (scatter indices).
    let cell = |cell: usize, regressors: &[usize], with_operation: bool| {
        let mut indices: BTreeMap<String, ParameterSensitivity> = BTreeMap::new();
        let mut reason = None;
        let regression = merged.regression[cell].standardised();
        let src = |input: usize| {
            let position = regressors.iter().position(|&r| r == input)?;
            regression.as_ref().and_then(|r| r.coefficients[position])
        };
        let levels = [
            (Per::Device, &device_inputs, merged.device.get(cell)),
            (
                Per::Operation,
                &operation_inputs,
                merged.operation.get(cell).filter(|_| with_operation),
            ),
        ];
        for (per, level_inputs, sobol) in levels {
            if per == Per::Operation && !with_operation {
                continue;
            }
            let estimate = sobol.map(|sums| (sums.estimate(), sums.shift()));
            if let (Some(sums), Some((estimate, shift))) = (sobol, &estimate) {
                reason = reason.or_else(|| not_the_spread(sums, estimate, *shift));
            }
            for (position, &input) in level_inputs.iter().enumerate() {
                let estimate = estimate.as_ref().map(|(e, _)| e.indices[position]);
                indices.insert(
                    name(input),
                    ParameterSensitivity {
                        first: estimate.map(|e| e.first),
                        total: estimate.map(|e| e.total),
                        src: src(input),
                        per,
                    },
                );
            }
        }
        (indices, regression.map(|r| r.r_squared), reason)
    };
    let all: Vec<usize> = (0..scatter.len()).collect();
    let mut result = BTreeMap::new();
    let bins = usize::try_from(job.bins()).expect("bins fit in memory");
    for (m, metric) in job.operation_metrics().iter().enumerate() {
        let entries = (0..bins)
            .map(|b| {
                let operations = job.bin_range(b as u64);
                let (indices, r_squared, reason) = cell(b * metrics + m, &all, true);
                SensitivityBin {
                    op_start: Some(operations.start),
                    op_end: Some(operations.end),
                    indices,
                    r_squared,
                    reason,
                }
            })
            .collect();
        result.insert(metric.name().to_owned(), entries);
    }
    if !device_inputs.is_empty() {
        for (j, metric) in job.device_metrics().iter().enumerate() {
            let (indices, r_squared, reason) = cell(bins * metrics + j, &device_inputs, false);
            result.insert(
                metric.name().to_owned(),
                vec![SensitivityBin {
                    op_start: None,
                    op_end: None,
                    indices,
                    r_squared,
                    reason,
                }],
            );
        }
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bin whose index, interval or coefficient is not a number is not finite (such a Result
    /// printed `null` indices, found from outside); one without a regression's numbers is.
    #[test]
    fn a_bin_is_finite_when_every_number_it_states_is() {
        let estimate = |value: f64| IndexEstimate {
            value,
            ci95: [0.0, 1.0],
        };
        let bin = |first: f64, src: Option<f64>| SensitivityBin {
            op_start: Some(0),
            op_end: Some(10),
            indices: BTreeMap::from([(
                "contact_radius_m".to_owned(),
                ParameterSensitivity {
                    first: Some(estimate(first)),
                    total: Some(estimate(0.5)),
                    src,
                    per: Per::Device,
                },
            )]),
            r_squared: src.map(|_| 0.9),
            reason: None,
        };
        assert!(bin(0.4, Some(0.7)).is_finite());
        assert!(bin(0.4, None).is_finite());
        assert!(!bin(f64::NAN, Some(0.7)).is_finite());
        assert!(!bin(0.4, Some(f64::INFINITY)).is_finite());
    }
}
