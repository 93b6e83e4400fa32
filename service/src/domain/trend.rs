//! The run-by-run trend of a schedule's statistics, and the drift flag that says a run left the
//! interval of the run before it.

use super::schedules::Statistic;
use bouncewear_model::montecarlo::JobResult;
use serde::Serialize;
use std::collections::BTreeMap;
use utoipa::ToSchema;

/// One night's value of one statistic.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct TrendValue {
    pub value: f64,
    pub ci95: [f64; 2],
    /// The value left the previous night's 95 % interval.
    pub drift: bool,
}

/// Flags every value that leaves the interval of the value before it (nights without a value are
/// skipped: the comparison is with the last night that has one).
pub fn flag_drift(values: &[Option<(f64, [f64; 2])>]) -> Vec<Option<TrendValue>> {
    let mut previous: Option<[f64; 2]> = None;
    values
        .iter()
        .map(|entry| {
            entry.map(|(value, ci95)| {
                let drift = previous.is_some_and(|[lo, hi]| value < lo || value > hi);
                previous = Some(ci95);
                TrendValue { value, ci95, drift }
            })
        })
        .collect()
}

/// A run's value and 95 % interval of each statistic of a schedule, in its order.
pub type RunValues = Vec<Option<(f64, [f64; 2])>>;

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
        .map(|column| flag_drift(&runs.iter().map(|run| run[column]).collect::<Vec<_>>()))
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

    #[test]
    fn drift_is_a_value_outside_the_previous_nights_interval() {
        let flags = flag_drift(&[
            Some((1.0, [0.9, 1.1])),
            Some((1.05, [0.95, 1.15])),
            None,
            Some((1.3, [1.2, 1.4])),
            Some((1.35, [1.25, 1.45])),
        ]);
        let drift: Vec<Option<bool>> = flags.iter().map(|f| f.as_ref().map(|v| v.drift)).collect();
        assert_eq!(
            drift,
            [Some(false), Some(false), None, Some(true), Some(false)]
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
