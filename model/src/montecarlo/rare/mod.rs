//! Rare events (docs/contract.md "Rare events"): the probability that one device's metric lies
//! beyond a threshold far out in its tail, `P(metric > t)` or `P(metric < t)`, estimated in the
//! job's own input space by subset simulation, importance sampling or crude Monte Carlo
//! ([`methods`]), with the most probable failing inputs and the tail curve.

pub mod methods;

use super::engine::limit_state::DeviceFunction;
pub use super::engine::limit_state::Reading;
use super::job::Job;
use super::metric::Metric;
use super::{Observer, RunError};
use crate::error::{FieldError, Pointer};
use crate::montecarlo::distribution::standard_normal_quantile;
use methods::{Budget, LimitState, SAMPLES_PER_LEVEL, Stop};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The fewest evaluations a rare-event estimate may be given: two levels of subset simulation.
pub const MIN_EVALUATIONS: u64 = 2 * SAMPLES_PER_LEVEL as u64;
/// The most evaluations one estimate may be given (each also counts against the server's job
/// size by the operations it runs).
pub const MAX_EVALUATIONS: u64 = 100_000_000;
/// The most inputs an estimate may explore: every sample of a level is kept, `1000 x 5000`
/// numbers (40 MB), twice.
pub const MAX_DIMENSION: usize = 5000;
/// The most inputs importance sampling may take: around one design point its weights stay sane
/// only in few dimensions.
pub const MAX_IMPORTANCE_DIMENSION: usize = 20;

/// A rare-event question, as the user writes it.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RareEventSpec {
    /// The metric: an operation metric (read at `operation`) or a device metric (read at the
    /// end of the test).
    pub metric: String,
    /// The event is the metric strictly above this.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub above: Option<f64>,
    /// The event is the metric strictly below this.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub below: Option<f64>,
    /// Which operation of a device an operation metric is read at, from 1 to `operations`
    /// (default 1), on the surface the operations before it left; not for a device metric.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operation: Option<u64>,
    /// `auto` (default: importance sampling up to 20 inputs, subset simulation beyond),
    /// `subset`, `importance` or `crude`.
    #[serde(default)]
    pub method: RareMethod,
    /// The coefficient of variation sought, in (0, 1] (default 0.1); the estimate stops there or
    /// at `max_evaluations`, whichever comes first.
    #[serde(default = "default_target_cov")]
    pub target_cov: f64,
    /// The most evaluations of a device, 2000 to 100000000 (default 200000).
    #[serde(default = "default_max_evaluations")]
    #[cfg_attr(feature = "openapi", schema(minimum = 2000, maximum = 100_000_000))]
    pub max_evaluations: u64,
}

fn default_target_cov() -> f64 {
    0.1
}

fn default_max_evaluations() -> u64 {
    200_000
}

/// How a rare-event probability is estimated.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RareMethod {
    #[default]
    Auto,
    Subset,
    Importance,
    Crude,
}

impl RareMethod {
    pub fn name(self) -> &'static str {
        match self {
            RareMethod::Auto => "auto",
            RareMethod::Subset => "subset",
            RareMethod::Importance => "importance",
            RareMethod::Crude => "crude",
        }
    }
}

/// A validated rare-event question.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RareEvent {
    /// A metric, or the failure criteria's margin for the life (`operations_to_failure`).
    pub reading: Reading,
    /// The threshold as asked, and whether the event is above it (else below).
    pub threshold: f64,
    pub above: bool,
    /// Operations a device runs per evaluation: to the one read, the whole test, or (life) the
    /// operations before the one asked.
    pub operations: u64,
    pub method: RareMethod,
    pub budget: Budget,
}

/// What of a job a rare event is checked against.
#[derive(Debug, Clone, Copy)]
pub struct JobShape {
    pub operations: u64,
    /// Scattered parameters drawn per device and per operation.
    pub device_inputs: usize,
    pub operation_inputs: usize,
    /// Whether the scenario gives the anode's share of the eroded mass.
    pub polarity: bool,
    /// Whether the job has failure criteria.
    pub failure: bool,
}

/// The life's name as a rare event's metric.
pub const LIFE: &str = "operations_to_failure";

impl RareEvent {
    /// Checks `spec` against the job's `shape`, each fault below `at`.
    pub fn new(
        spec: &RareEventSpec,
        shape: &JobShape,
        at: &Pointer,
        errors: &mut Vec<FieldError>,
    ) -> Option<Self> {
        let before = errors.len();
        let mut fault = |field: &str, detail: String| {
            errors.push(FieldError {
                pointer: if field.is_empty() {
                    at.to_string()
                } else {
                    at.child(field).to_string()
                },
                detail,
            });
        };
        let operations = shape.operations;
        let reading = match Metric::parse(&spec.metric) {
            None if spec.metric == LIFE => {
                if !shape.failure {
                    fault(
                        "metric",
                        format!("`{LIFE}` needs the job's `failure` criteria"),
                    );
                }
                Some(Reading::FailureMargin)
            }
            None => {
                fault(
                    "metric",
                    format!(
                        "unknown metric `{}`; known: {}, {LIFE}",
                        spec.metric,
                        Metric::all_names()
                    ),
                );
                None
            }
            Some(Metric::Device(metric)) if metric.needs_polarity() && !shape.polarity => {
                fault(
                    "metric",
                    format!(
                        "`{}` needs scenario/material/anode_erosion_fraction",
                        spec.metric
                    ),
                );
                None
            }
            Some(metric) => Some(Reading::Metric(metric)),
        };
        let (threshold, above) = match (spec.above, spec.below) {
            (Some(t), None) => (t, true),
            (None, Some(t)) => (t, false),
            _ => {
                fault("", "give exactly one of `above` and `below`".to_owned());
                (0.0, true)
            }
        };
        let side = if above { "above" } else { "below" };
        if !threshold.is_finite() {
            fault(side, "must be a finite number".to_owned());
        }
        let read = match (reading, spec.operation) {
            (Some(Reading::Metric(Metric::Device(_)) | Reading::FailureMargin), Some(_)) => {
                fault(
                    "operation",
                    "a device metric is read at the end of the test, the life by `below`; \
                     leave `operation` out"
                        .to_owned(),
                );
                operations
            }
            (Some(Reading::Metric(Metric::Device(_))), None) => operations,
            (Some(Reading::FailureMargin), None) => {
                // P(life < N): failed within the first N - 1 operations.
                let whole = threshold.fract() == 0.0;
                if above || !whole || !(2.0..=operations as f64 + 1.0).contains(&threshold) {
                    fault(
                        side,
                        format!(
                            "the life's event is `below` a whole number of operations from 2 to \
                             operations + 1 ({}): P(the device fails before it)",
                            operations + 1
                        ),
                    );
                    1
                } else {
                    threshold as u64 - 1
                }
            }
            (_, operation) => {
                let operation = operation.unwrap_or(1);
                if !(1..=operations).contains(&operation) {
                    fault(
                        "operation",
                        format!("must be from 1 to operations ({operations}), got {operation}"),
                    );
                }
                operation
            }
        };
        if !(spec.target_cov > 0.0 && spec.target_cov <= 1.0) {
            fault("target_cov", "must be above 0 and at most 1".to_owned());
        }
        if !(MIN_EVALUATIONS..=MAX_EVALUATIONS).contains(&spec.max_evaluations) {
            fault(
                "max_evaluations",
                format!(
                    "must be from {MIN_EVALUATIONS} (two levels of {SAMPLES_PER_LEVEL} samples) \
                     to {MAX_EVALUATIONS}, got {}",
                    spec.max_evaluations
                ),
            );
        }
        let (device_inputs, operation_inputs) = (shape.device_inputs, shape.operation_inputs);
        let per_operation = u64::try_from(operation_inputs).unwrap_or(u64::MAX);
        let dimension = u64::try_from(device_inputs)
            .unwrap_or(u64::MAX)
            .saturating_add(per_operation.saturating_mul(read));
        if dimension == 0 {
            fault(
                "",
                "needs a scattered input: without `scatter` every device gives the same value"
                    .to_owned(),
            );
        } else if dimension > MAX_DIMENSION as u64 {
            let field = match reading {
                Some(Reading::Metric(Metric::Operation(_))) => "operation",
                Some(Reading::FailureMargin) => side,
                _ => "",
            };
            fault(
                field,
                format!(
                    "explores {dimension} inputs ({device_inputs} per device and \
                     {operation_inputs} per operation for {read} operations); at most \
                     {MAX_DIMENSION}"
                ),
            );
        } else if spec.method == RareMethod::Importance
            && dimension > MAX_IMPORTANCE_DIMENSION as u64
        {
            fault(
                "method",
                format!(
                    "importance sampling takes at most {MAX_IMPORTANCE_DIMENSION} inputs; this \
                     event has {dimension}: use `subset`"
                ),
            );
        }
        if errors.len() > before {
            return None;
        }
        Some(Self {
            reading: reading.expect("no errors"),
            threshold,
            above,
            operations: read,
            method: spec.method,
            budget: Budget {
                max_evaluations: spec.max_evaluations,
                target_cov: spec.target_cov,
            },
        })
    }

    /// The sign that turns the event into a response above a threshold, and that threshold:
    /// the life's event is a failure margin above 0.
    fn limit(&self) -> (f64, f64) {
        match self.reading {
            Reading::FailureMargin => (1.0, 0.0),
            Reading::Metric(_) if self.above => (1.0, self.threshold),
            Reading::Metric(_) => (-1.0, -self.threshold),
        }
    }

    /// The most operations the estimate runs: what counts against a server's job size.
    pub fn max_operations(&self) -> u64 {
        self.budget.max_evaluations.saturating_mul(self.operations)
    }
}

/// The Result's `rare_event`.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RareEventReport {
    /// The estimated probability that one device's metric lies beyond the threshold.
    pub probability: f64,
    /// Its 95 % interval.
    pub ci95: [f64; 2],
    /// The estimate's coefficient of variation (null when no sample reached the threshold).
    pub cov: Option<f64>,
    /// Devices evaluated.
    pub evaluations: u64,
    /// The method that ran: `subset`, `importance` or `crude`.
    pub method: String,
    /// The generalized reliability index `-Phi^-1(probability)` (null at probability 0).
    pub beta: Option<f64>,
    /// The most probable failing inputs evaluated, in physical units, by parameter name (a
    /// per-operation parameter as `name@operation`); empty when none failed.
    pub design_point: BTreeMap<String, f64>,
    /// `P(metric beyond threshold)` from the bulk out to the threshold asked.
    pub tail: Vec<TailPoint>,
}

/// One point of the tail curve.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TailPoint {
    /// A threshold of the metric (the life: of the failure criteria's margin, 0 at failure).
    pub threshold: f64,
    /// The estimated probability that one device's metric lies beyond it.
    pub probability: f64,
}

/// Why a rare-event estimate gave no answer.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("rare event: {0}")]
pub struct RareEventError(pub String);

/// A device metric with the sign that makes the event a response above the threshold.
struct Signed<'a> {
    function: DeviceFunction<'a>,
    sign: f64,
}

impl LimitState for Signed<'_> {
    fn dimension(&self) -> usize {
        self.function.dimension()
    }
    fn response(&self, u: &[f64]) -> f64 {
        self.sign * self.function.value(u)
    }
}

/// Progress told in operations, as the rest of a job tells it.
struct InOperations<'a> {
    inner: &'a dyn Observer,
    per_evaluation: u64,
}

impl Observer for InOperations<'_> {
    fn progress(&self, done: u64, total: u64) {
        let operations = |evaluations: u64| evaluations.saturating_mul(self.per_evaluation);
        self.inner.progress(operations(done), operations(total));
    }
    fn cancelled(&self) -> bool {
        self.inner.cancelled()
    }
}

/// The job's rare event estimated, if it asks one: deterministic for its seed on any number of
/// threads.
pub fn estimate(job: &Job, observer: &dyn Observer) -> Result<Option<RareEventReport>, RunError> {
    let Some(rare) = job.rare_event() else {
        return Ok(None);
    };
    let (sign, threshold) = rare.limit();
    let state = Signed {
        function: DeviceFunction::new(job, rare.reading, rare.operations),
        sign,
    };
    let method = match rare.method {
        RareMethod::Auto if state.dimension() <= MAX_IMPORTANCE_DIMENSION => RareMethod::Importance,
        RareMethod::Auto => RareMethod::Subset,
        other => other,
    };
    let run = match method {
        RareMethod::Importance => methods::importance,
        RareMethod::Crude => methods::crude,
        _ => methods::subset,
    };
    let observer = InOperations {
        inner: observer,
        per_evaluation: rare.operations,
    };
    let estimate =
        run(&state, threshold, rare.budget, job.seed(), &observer).map_err(|stop| match stop {
            Stop::Cancelled => RunError::Cancelled(super::Cancelled),
            Stop::Failed(reason) => RunError::RareEvent(RareEventError(reason)),
        })?;
    let design_point = estimate
        .design_point
        .as_ref()
        .map(|u| {
            state
                .function
                .input_names()
                .into_iter()
                .zip(state.function.physical(u))
                .collect()
        })
        .unwrap_or_default();
    Ok(Some(RareEventReport {
        probability: estimate.probability,
        ci95: estimate.ci95,
        cov: estimate.cov,
        evaluations: estimate.evaluations,
        method: method.name().to_owned(),
        beta: (estimate.probability > 0.0).then(|| -standard_normal_quantile(estimate.probability)),
        design_point,
        tail: estimate
            .tail
            .iter()
            .map(|&(threshold, probability)| TailPoint {
                threshold: sign * threshold,
                probability,
            })
            .collect(),
    }))
}

/// The median device's reading, for a check before a job is accepted: a threshold the median
/// device already passes asks no rare event.
pub fn check_threshold(job: &Job, at: &Pointer) -> Result<(), crate::error::InvalidInput> {
    let Some(rare) = job.rare_event() else {
        return Ok(());
    };
    let (sign, threshold) = rare.limit();
    let function = DeviceFunction::new(job, rare.reading, rare.operations);
    let median = function.value(&vec![0.0; function.dimension()]);
    if sign * median < threshold {
        return Ok(());
    }
    let side = if rare.above { "above" } else { "below" };
    let detail = match rare.reading {
        Reading::Metric(metric) => format!(
            "the device with median inputs already gives {median} for {}: the event has \
             probability near one half or more, not a rare event (ask for it with `limits`)",
            metric.name()
        ),
        Reading::FailureMargin => format!(
            "the device with median inputs already fails before operation {}: the event has \
             probability near one half or more, not a rare event (see `life`)",
            rare.threshold
        ),
    };
    Err(crate::error::InvalidInput::single(&at.child(side), detail))
}
