//! Any quantile and any threshold of one (metric, bin), asked after the run from its groups'
//! accumulators, with the intervals of [`summarize`](super::summarize).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::accumulator::Accumulator;
use super::summary::{Merged, QuantileSummary};

/// One side of a threshold: the share of values above it, or below it.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq)]
#[serde(rename_all = "lowercase")]
pub enum Threshold {
    /// Values strictly above it.
    Above(f64),
    /// Values strictly below it.
    Below(f64),
}

impl Threshold {
    /// The threshold's value, whichever its side.
    pub fn value(self) -> f64 {
        match self {
            Threshold::Above(x) | Threshold::Below(x) => x,
        }
    }

    /// Whether `x` lies beyond the threshold, on its side.
    fn beyond(self, x: f64) -> bool {
        match self {
            Threshold::Above(limit) => x > limit,
            Threshold::Below(limit) => x < limit,
        }
    }
}

/// The probability of a value beyond a threshold, with a 95 % confidence interval; serialised as
/// `{"above": x, "probability", "ci95"}` (or `"below"`).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct ThresholdExceedance {
    /// `above` or `below`, and the threshold.
    #[serde(flatten)]
    pub threshold: Threshold,
    /// The share of values beyond the threshold.
    pub probability: f64,
    /// Its 95 % confidence interval: Wilson's, with the design effect of the groups.
    pub ci95: [f64; 2],
}

/// The answer to a query: the quantiles keyed by their level in shortest form (`"0.999"`), and one
/// exceedance per threshold, in the order asked.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Default)]
pub struct QueryAnswer {
    /// Per level asked, keyed by the level in shortest form: the value and its Woodruff interval.
    pub quantiles: BTreeMap<String, QuantileSummary>,
    /// Per threshold asked, in order: the probability beyond it and its interval.
    pub exceedance: Vec<ThresholdExceedance>,
}

/// The quantiles of `levels` (each in `[0, 1]`) and the probabilities beyond `thresholds` of the
/// values of `groups`, by the estimators of [`summarize`](super::summarize) on the same groups:
/// for a level of [`QUANTILES`](super::QUANTILES) the value and interval are those of the summary,
/// to the bit.
///
/// A threshold's probability counts each value as if moved to its bucket's midpoint, clamped to
/// its group's exact `[min, max]` (as the summary's histogram bins them): it is `c / n` for a whole
/// count `c`, exact unless a value lies within 0.2 % of the threshold, and 0 above the maximum or
/// below the minimum. Its interval is Wilson's with the design effect of the groups' shares, as the
/// summary's `exceedance`.
pub fn query(groups: &[Accumulator], levels: &[f64], thresholds: &[Threshold]) -> QueryAnswer {
    let merged = Merged::of(groups);
    let quantiles = levels
        .iter()
        .zip(merged.quantiles(levels))
        .map(|(level, quantile)| (level.to_string(), quantile))
        .collect();
    let exceedance = thresholds
        .iter()
        .map(|&threshold| {
            let (probability, ci95) = merged.share(|group| count_beyond(group, threshold));
            ThresholdExceedance {
                threshold,
                probability,
                ci95,
            }
        })
        .collect();
    QueryAnswer {
        quantiles,
        exceedance,
    }
}

/// The values of `group` beyond `threshold`, each at its bucket's midpoint clamped to the group's
/// `[min, max]`.
fn count_beyond(group: &Accumulator, threshold: Threshold) -> u64 {
    let (min, max) = (group.min(), group.max());
    group
        .sketch()
        .buckets()
        .filter(|&(midpoint, _)| threshold.beyond(midpoint.clamp(min, max)))
        .map(|(_, count)| count)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::test_util::SplitMix;
    use crate::stats::{QUANTILES, summarize};
    use proptest::prelude::*;

    fn accumulate(values: &[f64]) -> Accumulator {
        let mut acc = Accumulator::new(None);
        values.iter().for_each(|&x| acc.push(x));
        acc
    }

    fn groups_of(values: &[f64], size: usize) -> Vec<Accumulator> {
        values.chunks(size.max(1)).map(accumulate).collect()
    }

    #[test]
    fn answers_serialise_in_the_contract_shape() {
        let groups = groups_of(&[1.0, 2.0, 3.0, 4.0], 2);
        let answer = query(
            &groups,
            &[0.5, 0.999],
            &[Threshold::Above(2.5), Threshold::Below(1.5)],
        );
        let json = serde_json::to_value(&answer).unwrap();
        assert_eq!(
            json["quantiles"]
                .as_object()
                .unwrap()
                .keys()
                .collect::<Vec<_>>(),
            ["0.5", "0.999"]
        );
        assert_eq!(json["exceedance"][0]["above"], 2.5);
        assert_eq!(json["exceedance"][0]["probability"], 0.5);
        assert_eq!(json["exceedance"][1]["below"], 1.5);
        assert_eq!(json["exceedance"][1]["probability"], 0.25);
        assert_eq!(json["exceedance"][1]["ci95"].as_array().unwrap().len(), 2);
    }

    #[test]
    fn no_values_give_zeros() {
        let answer = query(&[], &[0.5], &[Threshold::Above(1.0)]);
        assert_eq!(answer.quantiles["0.5"].value, 0.0);
        assert_eq!(answer.exceedance[0].probability, 0.0);
        assert_eq!(answer.exceedance[0].ci95, [0.0, 0.0]);
    }

    fn value() -> impl Strategy<Value = f64> {
        prop_oneof![Just(0.0), 0.0..1.0f64, -1e3..1e3f64, 1e-6..1e-3f64]
    }

    proptest! {
        #[test]
        fn quantiles_at_the_standard_levels_are_the_summarys_to_the_bit(
            values in prop::collection::vec(value(), 0..400),
            size in 1..100usize,
        ) {
            let groups = groups_of(&values, size);
            let summary = summarize(&groups);
            let levels = QUANTILES.map(|(_, q)| q);
            let answer = query(&groups, &levels, &[]);
            for (key, level) in QUANTILES {
                prop_assert_eq!(&answer.quantiles[&level.to_string()], &summary.quantiles[key]);
            }
        }

        #[test]
        fn exceedance_is_the_exact_count_over_n_away_from_the_values(
            values in prop::collection::vec(-100..100i32, 1..400),
            size in 1..100usize,
            at in -101..101i32,
        ) {
            // Whole values and a threshold halfway between two: no value shares its bucket.
            let values: Vec<f64> = values.into_iter().map(f64::from).collect();
            let x = f64::from(at) + 0.5;
            let answer = query(&groups_of(&values, size), &[], &[Threshold::Above(x), Threshold::Below(x)]);
            let n = values.len() as f64;
            let above = values.iter().filter(|&&v| v > x).count() as f64;
            let below = values.iter().filter(|&&v| v < x).count() as f64;
            prop_assert_eq!(answer.exceedance[0].probability, above / n);
            prop_assert_eq!(answer.exceedance[1].probability, below / n);
            // Wilson's bounds at p = 0 or 1 are p up to rounding.
            for e in &answer.exceedance {
                prop_assert!(e.ci95[0] - 1e-12 <= e.probability && e.probability <= e.ci95[1] + 1e-12);
            }
        }

        #[test]
        fn exceedance_is_monotone_in_the_threshold(
            values in prop::collection::vec(value(), 1..400),
            size in 1..100usize,
            mut thresholds in prop::collection::vec(-1e3..1e3f64, 2..10),
        ) {
            thresholds.sort_by(f64::total_cmp);
            let groups = groups_of(&values, size);
            let above: Vec<Threshold> = thresholds.iter().map(|&x| Threshold::Above(x)).collect();
            let below: Vec<Threshold> = thresholds.iter().map(|&x| Threshold::Below(x)).collect();
            let probability = |answer: QueryAnswer| -> Vec<f64> {
                answer.exceedance.iter().map(|e| e.probability).collect()
            };
            let above = probability(query(&groups, &[], &above));
            let below = probability(query(&groups, &[], &below));
            prop_assert!(above.windows(2).all(|w| w[0] >= w[1]));
            prop_assert!(below.windows(2).all(|w| w[0] <= w[1]));
        }
    }

    #[test]
    fn beyond_the_extremes_is_exactly_zero() {
        let mut rng = SplitMix(31);
        let values: Vec<f64> = (0..1000).map(|_| 1e-3 * rng.uniform() + 1e-3).collect();
        let groups = groups_of(&values, 100);
        let max = values.iter().copied().fold(f64::MIN, f64::max);
        let min = values.iter().copied().fold(f64::MAX, f64::min);
        let answer = query(
            &groups,
            &[],
            &[Threshold::Above(max), Threshold::Below(min)],
        );
        assert_eq!(answer.exceedance[0].probability, 0.0);
        assert_eq!(answer.exceedance[1].probability, 0.0);
    }

    /// Standard normal quantiles and tail probabilities of the truth below.
    const Z_90: f64 = 1.281_551_565_544_600_4;
    const P_ABOVE_HALF: f64 = 0.308_537_538_725_986_9;
    const P_BELOW_MINUS_ONE: f64 = 0.158_655_253_931_457_05;

    /// A job's design: groups of devices of operations, the sd of the devices' offsets.
    struct Design {
        groups: usize,
        devices: usize,
        operations: usize,
        device_sd: f64,
    }

    /// Strongly correlated operations: 16 groups of 4 devices of 25 operations each.
    const CLUSTERED: Design = Design {
        groups: 16,
        devices: 4,
        operations: 25,
        device_sd: 1.5,
    };

    /// Independent values: 32 groups of 50 devices of one operation.
    const INDEPENDENT: Design = Design {
        groups: 32,
        devices: 50,
        operations: 1,
        device_sd: 0.0,
    };

    /// How often the after-run intervals of `reps` simulated jobs (seeds `seed..seed + reps`) cover
    /// the truth: the 0.9 quantile, the share above 0.5 sd and the share below -1 sd. A value is
    /// its device's offset plus noise, so the whole is normal with sd `s = sqrt(1 + device_sd^2)`.
    fn coverage(design: &Design, reps: u64, seed: u64) -> [f64; 3] {
        let s = (1.0 + design.device_sd * design.device_sd).sqrt();
        let mut hits = [0u64; 3];
        for rep in 0..reps {
            let mut rng = SplitMix(seed + rep);
            let accumulators: Vec<Accumulator> = (0..design.groups)
                .map(|_| {
                    let mut acc = Accumulator::new(None);
                    for _ in 0..design.devices {
                        let offset = design.device_sd * rng.normal();
                        (0..design.operations).for_each(|_| acc.push(offset + rng.normal()));
                    }
                    acc
                })
                .collect();
            let answer = query(
                &accumulators,
                &[0.9],
                &[Threshold::Above(0.5 * s), Threshold::Below(-s)],
            );
            let covers = |[lo, hi]: [f64; 2], truth: f64| u64::from(lo <= truth && truth <= hi);
            hits[0] += covers(answer.quantiles["0.9"].ci95, Z_90 * s);
            hits[1] += covers(answer.exceedance[0].ci95, P_ABOVE_HALF);
            hits[2] += covers(answer.exceedance[1].ci95, P_BELOW_MINUS_ONE);
        }
        hits.map(|h| h as f64 / reps as f64)
    }

    #[test]
    fn after_run_intervals_cover_the_truth() {
        for design in [CLUSTERED, INDEPENDENT] {
            let [quantile, above, below] = coverage(&design, 200, 1000);
            assert!((0.88..=0.99).contains(&quantile), "p90 {quantile}");
            assert!((0.88..=0.99).contains(&above), "above {above}");
            assert!((0.88..=0.99).contains(&below), "below {below}");
        }
    }

    /// The figures over 1200 seeds, in three blocks of 400: `cargo test -p bouncewear-model
    /// --release -- --ignored --nocapture after_run_coverage_over_1200_seeds`. A coverage of 95 %
    /// over 400 seeds has a standard error of 1.1 points, so only the pooled figure is held to
    /// 93-97 %; each block to 92-98 %.
    #[test]
    #[ignore = "slow: the 1200-seed coverage figures"]
    fn after_run_coverage_over_1200_seeds() {
        for (name, design) in [("clustered", CLUSTERED), ("independent", INDEPENDENT)] {
            let blocks = [5000, 5400, 5800].map(|seed| coverage(&design, 400, seed));
            for (block, figures) in blocks.iter().enumerate() {
                let [quantile, above, below] = figures;
                println!(
                    "{name}, 400 seeds (block {block}): p90 {quantile}, above {above}, below {below}"
                );
                for covered in figures {
                    assert!(
                        (0.92..=0.98).contains(covered),
                        "{name} block {block}: {covered}"
                    );
                }
            }
            let pooled: [f64; 3] =
                std::array::from_fn(|i| blocks.iter().map(|b| b[i]).sum::<f64>() / 3.0);
            let [quantile, above, below] = pooled;
            println!("{name}, 1200 seeds: p90 {quantile}, above {above}, below {below}");
            for covered in pooled {
                assert!((0.93..=0.97).contains(&covered), "{name}: {covered}");
            }
        }
    }
}
