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

/// Each run's value of each statistic, oldest run first, keyed by the statistic's name: `results`
/// holds each run's result (`None` until its job succeeded).
pub fn trend(
    statistics: &[Statistic],
    results: &[Option<JobResult>],
) -> Vec<BTreeMap<String, Option<TrendValue>>> {
    let columns: Vec<Vec<Option<TrendValue>>> = statistics
        .iter()
        .map(|statistic| {
            let values: Vec<_> = results
                .iter()
                .map(|result| result.as_ref().and_then(|r| statistic.read(r)))
                .collect();
            flag_drift(&values)
        })
        .collect();
    (0..results.len())
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
        let runs = trend(&statistics, &[None, None]);
        assert_eq!(runs.len(), 2);
        assert_eq!(runs[0]["life.b10"], None);
    }
}
