//! A rare-event question as a job asks it ([`RareEventSpec`]) and as it passed every rule
//! ([`RareEvent`]): what it reads, beyond which threshold, at which operation, by which method and
//! within which budget (docs/contract.md "Rare events"). The estimate is the parent module's.

use super::methods::{Budget, SAMPLES_PER_LEVEL};
use crate::error::{FieldError, Pointer};
use crate::montecarlo::metric::{Metric, needs_polarity};
use serde::{Deserialize, Serialize};

/// What an evaluation reads off the device.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reading {
    /// A metric: an operation metric at the last operation run, a device metric after it.
    Metric(Metric),
    /// The job's failure criteria: the largest margin past any of them over the operations run
    /// ([`Criterion::margin`](crate::montecarlo::job::Criterion::margin)), above 0 exactly when
    /// the device failed by then.
    FailureMargin,
}

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

/// Where a rare event's faults go: each below the section's pointer.
struct Faults<'a> {
    at: &'a Pointer,
    errors: &'a mut Vec<FieldError>,
}

impl Faults<'_> {
    /// A fault of `field` (`""`: of the section as a whole).
    fn push(&mut self, field: &str, detail: String) {
        self.errors.push(FieldError {
            pointer: if field.is_empty() {
                self.at.to_string()
            } else {
                self.at.child(field).to_string()
            },
            detail,
        });
    }
}

/// What the event reads: a known metric the job can give, or the life with failure criteria.
fn check_reading(spec: &RareEventSpec, shape: &JobShape, faults: &mut Faults) -> Option<Reading> {
    match Metric::parse(&spec.metric) {
        None if spec.metric == LIFE => {
            if !shape.failure {
                faults.push(
                    "metric",
                    format!("`{LIFE}` needs the job's `failure` criteria"),
                );
            }
            Some(Reading::FailureMargin)
        }
        None => {
            faults.push(
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
            faults.push("metric", needs_polarity(&spec.metric));
            None
        }
        Some(metric) => Some(Reading::Metric(metric)),
    }
}

/// The threshold and whether the event is above it: exactly one finite `above` or `below`.
fn check_side(spec: &RareEventSpec, faults: &mut Faults) -> (f64, bool) {
    let (threshold, above) = match (spec.above, spec.below) {
        (Some(t), None) => (t, true),
        (None, Some(t)) => (t, false),
        _ => {
            faults.push("", "give exactly one of `above` and `below`".to_owned());
            (0.0, true)
        }
    };
    if !threshold.is_finite() {
        faults.push(side_name(above), "must be a finite number".to_owned());
    }
    (threshold, above)
}

fn side_name(above: bool) -> &'static str {
    if above { "above" } else { "below" }
}

/// How many operations an evaluation runs: to the operation read, the whole test for a device
/// metric, or the operations before the one the life's event names.
fn operations_read(
    spec: &RareEventSpec,
    reading: Option<Reading>,
    (threshold, above): (f64, bool),
    operations: u64,
    faults: &mut Faults,
) -> u64 {
    match (reading, spec.operation) {
        (Some(Reading::Metric(Metric::Device(_)) | Reading::FailureMargin), Some(_)) => {
            faults.push(
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
                faults.push(
                    side_name(above),
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
                faults.push(
                    "operation",
                    format!("must be from 1 to operations ({operations}), got {operation}"),
                );
            }
            operation
        }
    }
}

/// `target_cov` in (0, 1] and `max_evaluations` within its range.
fn check_budget(spec: &RareEventSpec, faults: &mut Faults) {
    if !(spec.target_cov > 0.0 && spec.target_cov <= 1.0) {
        faults.push("target_cov", "must be above 0 and at most 1".to_owned());
    }
    if !(MIN_EVALUATIONS..=MAX_EVALUATIONS).contains(&spec.max_evaluations) {
        faults.push(
            "max_evaluations",
            format!(
                "must be from {MIN_EVALUATIONS} (two levels of {SAMPLES_PER_LEVEL} samples) \
                 to {MAX_EVALUATIONS}, got {}",
                spec.max_evaluations
            ),
        );
    }
}

/// The inputs the event explores, those of the device and of each operation read: at least one,
/// at most [`MAX_DIMENSION`], and for importance sampling at most [`MAX_IMPORTANCE_DIMENSION`].
fn check_inputs(
    spec: &RareEventSpec,
    shape: &JobShape,
    (reading, above): (Option<Reading>, bool),
    read: u64,
    faults: &mut Faults,
) {
    let (device_inputs, operation_inputs) = (shape.device_inputs, shape.operation_inputs);
    let per_operation = u64::try_from(operation_inputs).unwrap_or(u64::MAX);
    let dimension = u64::try_from(device_inputs)
        .unwrap_or(u64::MAX)
        .saturating_add(per_operation.saturating_mul(read));
    if dimension == 0 {
        faults.push(
            "",
            "needs a scattered input: without `scatter` every device gives the same value"
                .to_owned(),
        );
    } else if dimension > MAX_DIMENSION as u64 {
        let field = match reading {
            Some(Reading::Metric(Metric::Operation(_))) => "operation",
            Some(Reading::FailureMargin) => side_name(above),
            _ => "",
        };
        faults.push(
            field,
            format!(
                "explores {dimension} inputs ({device_inputs} per device and \
                 {operation_inputs} per operation for {read} operations); at most \
                 {MAX_DIMENSION}"
            ),
        );
    } else if spec.method == RareMethod::Importance && dimension > MAX_IMPORTANCE_DIMENSION as u64 {
        faults.push(
            "method",
            format!(
                "importance sampling takes at most {MAX_IMPORTANCE_DIMENSION} inputs; this \
                 event has {dimension}: use `subset`"
            ),
        );
    }
}

impl RareEvent {
    /// Checks `spec` against the job's `shape`, each fault below `at`.
    pub fn new(
        spec: &RareEventSpec,
        shape: &JobShape,
        at: &Pointer,
        errors: &mut Vec<FieldError>,
    ) -> Option<Self> {
        let before = errors.len();
        let mut faults = Faults { at, errors };
        let reading = check_reading(spec, shape, &mut faults);
        let (threshold, above) = check_side(spec, &mut faults);
        let faults_before = faults.errors.len();
        let read = operations_read(
            spec,
            reading,
            (threshold, above),
            shape.operations,
            &mut faults,
        );
        // The inputs explored depend on the operations read: none to count where those are at
        // fault (an `operation` of 0 read no operation, and was told it needs a scatter).
        let read_is_valid = faults.errors.len() == faults_before;
        check_budget(spec, &mut faults);
        if read_is_valid {
            check_inputs(spec, shape, (reading, above), read, &mut faults);
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
    pub(super) fn limit(&self) -> (f64, f64) {
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
