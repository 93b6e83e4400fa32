//! The run-by-run trend of a schedule's statistics, and the drift flag that says a run left the
//! interval of the run before it.

use super::schedules::{Reading, Statistic};
use bouncewear_model::montecarlo::JobResult;
use serde::Serialize;
use std::collections::BTreeMap;
use utoipa::ToSchema;

/// One night's value of one statistic.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct TrendValue {
    pub value: f64,
    pub ci95: [f64; 2],
    /// The value left the 95 % interval of the last night before it whose value has no `reason`.
    pub drift: bool,
    /// Present where the Result's quantile carries it (the data cannot bound the level): the
    /// interval claims more than the data hold, so the value is never flagged, nor a later one
    /// judged by its interval.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// Flags every value that leaves the interval of the value before it (nights without a value, or
/// whose value carries a reason, are skipped: the comparison is with the last night whose value
/// the data bound). A value with a reason is never flagged: a drift alarm is a decision, and
/// such an interval is not one to rest a decision on (found from outside: a p99 of 4 devices,
/// carrying its reason in every Result, raised one).
pub fn flag_drift(values: impl IntoIterator<Item = Option<Reading>>) -> Vec<Option<TrendValue>> {
    let mut previous: Option<[f64; 2]> = None;
    values
        .into_iter()
        .map(|entry| {
            let bounded = judges_later_runs(entry.as_ref());
            entry.map(
                |Reading {
                     value,
                     ci95,
                     reason,
                 }| {
                    let drift =
                        bounded && previous.is_some_and(|[lo, hi]| value < lo || value > hi);
                    if bounded {
                        previous = Some(ci95);
                    }
                    TrendValue {
                        value,
                        ci95,
                        drift,
                        reason,
                    }
                },
            )
        })
        .collect()
}

/// Whether a run's reading is one a later run's drift is judged by: a value whose interval the
/// data bound (no `reason`). A trend that shows only its latest runs looks back past the others
/// to it, so that a run's flag is the same whatever the window.
pub fn judges_later_runs(reading: Option<&Reading>) -> bool {
    reading.is_some_and(|reading| reading.reason.is_none())
}

/// A run's reading of each statistic of a schedule, in its order.
pub type RunValues = Vec<Option<Reading>>;

/// What `result` gives of each statistic: none of any for a run whose job has no Result.
pub fn run_values(statistics: &[Statistic], result: Option<&JobResult>) -> RunValues {
    statistics
        .iter()
        .map(|statistic| result.and_then(|r| statistic.read(r)))
        .collect()
}

/// Each run's value of each statistic, oldest run first, keyed by the statistic's name: `runs`
/// holds each run's [`run_values`].
pub fn trend(
    statistics: &[Statistic],
    runs: &[RunValues],
) -> Vec<BTreeMap<String, Option<TrendValue>>> {
    let columns: Vec<Vec<Option<TrendValue>>> = (0..statistics.len())
        .map(|column| flag_drift(runs.iter().map(|run| run[column].clone())))
        .collect();
    (0..runs.len())
        .map(|run| {
            statistics
                .iter()
                .zip(&columns)
                .map(|(statistic, column)| (statistic.to_string(), column[run].clone()))
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(value: f64, ci95: [f64; 2], reason: Option<&str>) -> Option<Reading> {
        Some(Reading {
            value,
            ci95,
            reason: reason.map(str::to_owned),
        })
    }

    #[test]
    fn drift_is_a_value_outside_the_previous_nights_interval() {
        let flags = flag_drift([
            reading(1.0, [0.9, 1.1], None),
            reading(1.05, [0.95, 1.15], None),
            None,
            reading(1.3, [1.2, 1.4], None),
            reading(1.35, [1.25, 1.45], None),
            // Beyond the data: never flagged, and not the interval the next night is judged by.
            reading(2.0, [1.99, 2.01], Some("beyond the data")),
            reading(1.4, [1.3, 1.5], None),
            reading(3.0, [2.9, 3.1], None),
        ]);
        let drift: Vec<Option<bool>> = flags.iter().map(|f| f.as_ref().map(|v| v.drift)).collect();
        assert_eq!(
            drift,
            [
                Some(false),
                Some(false),
                None,
                Some(true),
                Some(false),
                Some(false),
                Some(false),
                Some(true)
            ]
        );
        assert_eq!(
            flags[5].as_ref().unwrap().reason.as_deref(),
            Some("beyond the data")
        );
    }

    #[test]
    fn a_run_without_a_result_has_no_values() {
        let statistics = ["life.b10".parse::<Statistic>().unwrap()];
        let none = run_values(&statistics, None);
        let runs = trend(&statistics, &[none.clone(), none]);
        assert_eq!(runs.len(), 2);
        assert_eq!(runs[0]["life.b10"], None);
    }
}
