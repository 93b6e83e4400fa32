//! Two succeeded jobs compared, design `a` against design `b` (docs/contract.md "Comparing
//! designs"): per bin of operations both share, any statistic of a metric with the difference and
//! ratio and their intervals ([`crate::stats::difference`](mod@crate::stats::difference)); and with
//! failure criteria, the B-lives and the probability that a device of `a` outlasts one of `b`
//! ([`crate::life::compare`]). The two jobs are independent samples (their own devices, their own
//! seeds), which is what the intervals assume.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::{Bin, JobResult, Metric};
use crate::life::compare::{LifeComparison, compare_lives};
use crate::stats::{Difference, Estimate, QUANTILES, Summary, difference};

/// The statistics compared when none are asked for.
pub const DEFAULT_STATISTICS: [&str; 3] = ["mean", "p50", "p95"];
/// The B-lives compared when none are asked for.
pub const DEFAULT_B_LIVES: [f64; 2] = [0.01, 0.1];

/// A statistic of a summary that has an interval: `mean`, a reported quantile `p01` ... `p99`,
/// or `exceedance` (the probability beyond the metric's limit).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Statistic {
    Mean,
    Quantile(&'static str),
    Exceedance,
}

impl Statistic {
    /// The statistic called `name`; the error lists the names there are.
    pub fn parse(name: &str) -> Result<Self, String> {
        match name {
            "mean" => Ok(Self::Mean),
            "exceedance" => Ok(Self::Exceedance),
            _ => QUANTILES
                .iter()
                .find(|(key, _)| *key == name)
                .map(|(key, _)| Self::Quantile(key))
                .ok_or_else(|| {
                    let quantiles: Vec<&str> = QUANTILES.iter().map(|(key, _)| *key).collect();
                    format!(
                        "no statistic `{name}`; known: mean, {}, exceedance",
                        quantiles.join(", ")
                    )
                }),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Mean => "mean",
            Self::Quantile(key) => key,
            Self::Exceedance => "exceedance",
        }
    }

    /// The statistic's estimate in `summary`, if it has one.
    fn of(self, summary: &Summary) -> Option<Estimate> {
        match self {
            Self::Mean => Some(Estimate::new(summary.mean, Some(summary.mean_ci95))),
            Self::Quantile(key) => summary.quantiles.get(key).map(|q| {
                // A level the data cannot bound has a value but no interval to lean on.
                Estimate::bucketed(q.value, q.reason.is_none().then_some(q.ci95))
            }),
            Self::Exceedance => summary
                .exceedance
                .as_ref()
                .map(|e| Estimate::new(e.probability, Some(e.ci95))),
        }
    }
}

/// One bin of operations both jobs have, compared.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BinComparison {
    /// First operation of the bin (0-based).
    pub op_start: u64,
    /// End of the bin, exclusive.
    pub op_end: u64,
    /// Per statistic asked that both summaries have: `a` and `b` with their intervals, `a - b` and
    /// `a / b` with theirs.
    #[cfg_attr(feature = "openapi", schema(value_type = BTreeMap<String, Object>))]
    pub statistics: BTreeMap<String, Difference>,
}

/// Two jobs compared.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    /// The metric compared.
    pub metric: String,
    /// The bins of operations both jobs have (the same `op_start` and `op_end`), in operation
    /// order; a device metric has one, over the whole test.
    pub bins: Vec<BinComparison>,
    /// With failure criteria in both jobs: B-lives and who outlasts whom.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(value_type = Option<Object>))]
    pub life: Option<LifeComparison>,
    /// What limits the comparison: bins the jobs do not share, tests of different lengths,
    /// different failure criteria, statistics a summary does not have.
    pub notes: Vec<String>,
}

/// Why two jobs cannot be compared.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CompareError {
    #[error("no metric `{0}`; known: {known}", known = Metric::all_names())]
    UnknownMetric(String),
    #[error("job {0} does not compute `{1}`: it was not among its `metrics`")]
    NoMetric(&'static str, String),
}

/// `a` against `b` on `metric` (an operation or a device metric both jobs report), the
/// `statistics` in every bin they share and, when both have failure criteria, the B-lives at
/// fractions `b_lives`.
pub fn compare(
    a: &JobResult,
    b: &JobResult,
    metric: &str,
    statistics: &[Statistic],
    b_lives: &[f64],
) -> Result<Comparison, CompareError> {
    if Metric::parse(metric).is_none() {
        return Err(CompareError::UnknownMetric(metric.to_owned()));
    }
    let (bins_a, bins_b) = (bins_of(a, metric), bins_of(b, metric));
    let bins_a = bins_a.ok_or_else(|| CompareError::NoMetric("a", metric.to_owned()))?;
    let bins_b = bins_b.ok_or_else(|| CompareError::NoMetric("b", metric.to_owned()))?;
    let mut notes = jobs_notes(a, b);
    let mut bins_notes = Vec::new();
    let bins = compare_bins(&bins_a, &bins_b, statistics, metric, &mut bins_notes);
    if bins.is_empty() {
        let same = if a.devices.contains_key(metric) {
            "a device metric is one summary of each whole test: give both the same `operations`"
        } else {
            "give both the same `operations` and `bin_operations`"
        };
        notes.push(format!("the jobs share no bin of `{metric}`: {same}"));
    }
    notes.extend(bins_notes);
    let life = life_comparison(a, b, b_lives, &mut notes);
    Ok(Comparison {
        metric: metric.to_owned(),
        bins,
        life,
        notes,
    })
}

/// What the two jobs themselves limit: tests of different lengths, the same job on both sides,
/// or a shared seed.
fn jobs_notes(a: &JobResult, b: &JobResult) -> Vec<String> {
    let mut notes = Vec::new();
    let (ops_a, ops_b) = (a.job.spec().operations, b.job.spec().operations);
    if ops_a != ops_b {
        notes.push(format!(
            "the tests have different lengths ({ops_a} and {ops_b} operations): bins are compared where both jobs have them, and lives each at its own test's end"
        ));
    }
    if a.job == b.job {
        notes.push(
            "design a and design b are the same job (one specification and seed): every \
             difference is 0, and the intervals, made for independent samples, say nothing of it"
                .to_owned(),
        );
    } else if a.job.spec().seed == b.job.spec().seed {
        notes.push(
            "the jobs share their seed: their devices draw the same random numbers, not \
             independent samples as the intervals take them to be (give the jobs different seeds)"
                .to_owned(),
        );
    }
    notes
}

/// The `statistics` compared in every bin both jobs have; pushes a note for statistics a bin
/// lacks and for exceedances beyond different limits.
fn compare_bins(
    bins_a: &[(u64, u64, &Summary)],
    bins_b: &[(u64, u64, &Summary)],
    statistics: &[Statistic],
    metric: &str,
    notes: &mut Vec<String>,
) -> Vec<BinComparison> {
    let mut missing: BTreeMap<&str, usize> = BTreeMap::new();
    // An exceedance beyond a different limit in each job: two different probabilities.
    let mut different_limits = None;
    let bins: Vec<BinComparison> = bins_a
        .iter()
        .filter_map(|(start, end, sa)| {
            let (_, _, sb) = bins_b.iter().find(|(s, e, _)| s == start && e == end)?;
            let statistics = statistics
                .iter()
                .filter_map(|&statistic| {
                    if let (Statistic::Exceedance, Some(ea), Some(eb)) =
                        (statistic, &sa.exceedance, &sb.exceedance)
                        && ea.limit != eb.limit
                    {
                        different_limits = Some((ea.limit, eb.limit));
                        return None;
                    }
                    let pair = statistic.of(sa).zip(statistic.of(sb));
                    if pair.is_none() {
                        *missing.entry(statistic.name()).or_default() += 1;
                    }
                    let (ea, eb) = pair?;
                    Some((statistic.name().to_owned(), difference(ea, eb)))
                })
                .collect();
            Some(BinComparison {
                op_start: *start,
                op_end: *end,
                statistics,
            })
        })
        .collect();
    for (name, count) in missing {
        notes.push(format!(
            "`{name}` is missing from {count} bin(s) of one job or both (`exceedance` compares \
             the metric's one limit, `\"limits\": {{METRIC: x}}`; a list of thresholds is not \
             compared)"
        ));
    }
    if let Some((limit_a, limit_b)) = different_limits {
        notes.push(format!(
            "the jobs' limits on `{metric}` differ ({limit_a} and {limit_b}): `exceedance`, the \
             probability beyond each job's own limit, is not compared (give both the same limit)"
        ));
    }
    bins
}

/// The two designs' lives compared, when both have failure criteria; pushes a note where only
/// one has, or their criteria differ.
fn life_comparison(
    a: &JobResult,
    b: &JobResult,
    b_lives: &[f64],
    notes: &mut Vec<String>,
) -> Option<LifeComparison> {
    match (&a.life, &b.life) {
        (Some(la), Some(lb)) => {
            if la.criteria != lb.criteria {
                notes.push("the jobs fail by different criteria".to_owned());
            }
            let (ops_a, ops_b) = (a.job.spec().operations, b.job.spec().operations);
            let (lives_a, lives_b) = (la.lives(ops_a), lb.lives(ops_b));
            Some(compare_lives(
                (&la.analysis, &lives_a),
                (&lb.analysis, &lives_b),
                b_lives,
            ))
        }
        (None, None) => None,
        _ => {
            notes.push("only one of the jobs has failure criteria: no life comparison".to_owned());
            None
        }
    }
}

/// The summaries of `metric` in `result` with their operations: an operation metric's bins, or a
/// device metric's one summary over the whole test.
fn bins_of<'r>(result: &'r JobResult, metric: &str) -> Option<Vec<(u64, u64, &'r Summary)>> {
    if let Some(bins) = result.operations.get(metric) {
        return Some(
            bins.iter()
                .map(
                    |Bin {
                         summary,
                         op_start,
                         op_end,
                     }| (*op_start, *op_end, summary),
                )
                .collect(),
        );
    }
    result
        .devices
        .get(metric)
        .map(|summary| vec![(0, result.job.spec().operations, summary)])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::test_util::SplitMix;
    use crate::stats::{Accumulator, summarize};

    #[test]
    fn bucketed_quantiles_of_many_values_are_compared_honestly() {
        // Two jobs of one design with 10^5 values a bin (32 groups of 3125 independent values of
        // N(0.5, 0.05)), 200 pairs: how often the p50 and p95 differences' intervals hold 0, and
        // how often they did with MOVER centred on the bucketed values.
        let mut rng = SplitMix(5);
        let mut summary = || {
            let groups: Vec<Accumulator> = (0..32)
                .map(|_| {
                    let mut group = Accumulator::new(None);
                    (0..3125).for_each(|_| group.push(0.5 + 0.05 * rng.normal()));
                    group
                })
                .collect();
            summarize(&groups, 1)
        };
        let pairs = 200;
        let (mut covered, mut at_values) = ([0; 2], [0; 2]);
        for _ in 0..pairs {
            let (a, b) = (summary(), summary());
            for (i, key) in ["p50", "p95"].into_iter().enumerate() {
                let statistic = Statistic::Quantile(key);
                let (ea, eb) = (statistic.of(&a).unwrap(), statistic.of(&b).unwrap());
                let [lo, hi] = difference(ea, eb).difference_ci95.unwrap();
                covered[i] += usize::from(lo <= 0.0 && 0.0 <= hi);
                let plain = |e: Estimate| Estimate::new(e.value, e.ci95);
                let [lo, hi] = difference(plain(ea), plain(eb)).difference_ci95.unwrap();
                at_values[i] += usize::from(lo <= 0.0 && 0.0 <= hi);
            }
        }
        let share = |n: usize| n as f64 / f64::from(pairs);
        for (i, key) in ["p50", "p95"].into_iter().enumerate() {
            println!(
                "{key}: covered {}, centred on the values {}",
                share(covered[i]),
                share(at_values[i])
            );
            assert!(share(covered[i]) >= 0.92, "{key}: {}", share(covered[i]));
        }
    }

    #[test]
    fn statistics_parse_by_name() {
        assert_eq!(Statistic::parse("mean"), Ok(Statistic::Mean));
        assert_eq!(Statistic::parse("p99"), Ok(Statistic::Quantile("p99")));
        assert_eq!(Statistic::parse("exceedance"), Ok(Statistic::Exceedance));
        let error = Statistic::parse("p42").unwrap_err();
        assert!(
            error.contains("no statistic `p42`") && error.contains("p05"),
            "{error}"
        );
        for name in DEFAULT_STATISTICS {
            assert_eq!(Statistic::parse(name).unwrap().name(), name);
        }
    }
}
