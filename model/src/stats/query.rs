//! Any quantile and any threshold of one (metric, bin), asked after the run from its groups'
//! accumulators, with the intervals of [`summarize`](super::summarize).

use std::borrow::Borrow;
use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::accumulator::Accumulator;
use super::summary::{Merged, QuantileSummary};
use super::threshold::{Beyond, Resolution, Threshold, ThresholdExceedance};

/// One quantile level asked after the run: its value and Woodruff interval, or, when the data
/// cannot bound the level (a [`QuantileSummary`] with a `reason`), no value and the reason.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct QueryQuantile {
    /// The quantile, within 0.2 %; `null` when the data cannot bound the level.
    pub value: Option<f64>,
    /// Its 95 % interval; `null` when the data cannot bound the level.
    pub ci95: Option<[f64; 2]>,
    /// Why there is no value, and what would give one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

impl From<QuantileSummary> for QueryQuantile {
    fn from(quantile: QuantileSummary) -> Self {
        match quantile.reason {
            None => Self {
                value: Some(quantile.value),
                ci95: Some(quantile.ci95),
                reason: None,
            },
            reason => Self {
                value: None,
                ci95: None,
                reason,
            },
        }
    }
}

/// The answer to a query: the quantiles keyed by their level in shortest form (`"0.999"`), and one
/// exceedance per threshold, in the order asked.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Default)]
pub struct QueryAnswer {
    /// Per level asked, keyed by the level in shortest form: the value and its Woodruff interval,
    /// or no value and the reason.
    pub quantiles: BTreeMap<String, QueryQuantile>,
    /// Per threshold asked, in order: the probability beyond it and its interval.
    pub exceedance: Vec<ThresholdExceedance>,
}

/// A level as [`QueryAnswer::quantiles`] keys it: its shortest decimal form (`0.50` is `"0.5"`).
pub fn level_key(level: f64) -> String {
    level.to_string()
}

/// The quantiles of `levels` (each in `[0, 1]`) and the probabilities beyond `thresholds` of the
/// values of `groups` (`per_device` values from each device), by the estimators of
/// [`summarize`](super::summarize) on the same groups:
/// for a level of [`QUANTILES`](super::QUANTILES) the value and interval are those of the summary,
/// to the bit. A level the data cannot bound (fewer than
/// [`MIN_TAIL_UNITS`](super::summary::MIN_TAIL_UNITS) independent units beyond it, devices or
/// groups, or one group)
/// has no value, only the reason: its interval would end at the sample's extreme.
///
/// A threshold's probability is exact, `c / n` with its proportion interval
/// ([`super::intervals::proportion_interval`]) and the design effect of the
/// groups' shares (as the summary's `exceedance`), when every value was compared with it: a
/// threshold the groups counted as they ran (the job's limit, or one of its list), or one that no
/// value shares a sketch bucket with (each group's exact `[min, max]` settles the values outside
/// it). Otherwise it is bucket-limited ([`Resolution::Bucket`]): the values in the threshold's
/// bucket count as spread evenly over the bucket's width for the probability, and the interval runs
/// from the lower end of the interval with none of them beyond to the upper end of the interval
/// with all of them beyond, so the store's resolution never puts the truth outside it.
pub fn query<A: Borrow<Accumulator>>(
    groups: &[A],
    per_device: u64,
    levels: &[f64],
    thresholds: &[Threshold],
) -> QueryAnswer {
    let merged = Merged::of(groups, per_device);
    let quantiles = levels
        .iter()
        .zip(merged.quantiles(levels))
        .map(|(&level, quantile)| (level_key(level), quantile.into()))
        .collect();
    let exceedance = thresholds
        .iter()
        .map(|&threshold| exceedance(&merged, threshold))
        .collect();
    QueryAnswer {
        quantiles,
        exceedance,
    }
}

/// The probability beyond `threshold` of the merged groups, exact or bucket-limited (see [`query`]).
fn exceedance(merged: &Merged, threshold: Threshold) -> ThresholdExceedance {
    let counts: Vec<(Beyond, Option<[f64; 2]>)> = merged
        .filled
        .iter()
        .map(|group| group.beyond(threshold))
        .collect();
    let sure: Vec<u64> = counts.iter().map(|(beyond, _)| beyond.sure).collect();
    let above = matches!(threshold, Threshold::Above(_));
    let (probability, ci95) = merged.share(&sure, above);
    let Some(bucket) = counts.iter().find_map(|&(_, bucket)| bucket) else {
        return ThresholdExceedance {
            threshold,
            probability,
            ci95,
            resolution: Resolution::Exact,
            bucket: None,
        };
    };
    let most: Vec<u64> = counts
        .iter()
        .map(|(beyond, _)| beyond.sure + beyond.unsure)
        .collect();
    let (highest, [_, upper]) = merged.share(&most, above);
    let spread: f64 = counts.iter().map(|(beyond, _)| beyond.spread).sum();
    let n = merged.all.count() as f64;
    ThresholdExceedance {
        threshold,
        probability: (spread / n).clamp(probability, highest),
        ci95: [ci95[0], upper],
        resolution: Resolution::Bucket,
        bucket: Some(bucket),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::test_util::SplitMix;
    use crate::stats::{QUANTILES, summarize};
    use crate::stats::{QueryQuantile, Resolution};
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
            1,
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
        let answer = query::<Accumulator>(&[], 1, &[0.5], &[Threshold::Above(1.0)]);
        assert_eq!(answer.quantiles["0.5"].value, Some(0.0));
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
            let summary = summarize(&groups, 1);
            let levels = QUANTILES.map(|(_, q)| q);
            let answer = query(&groups, 1, &levels, &[]);
            for (key, level) in QUANTILES {
                prop_assert_eq!(
                    &answer.quantiles[&level.to_string()],
                    &QueryQuantile::from(summary.quantiles[key].clone())
                );
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
            let answer = query(&groups_of(&values, size), 1, &[], &[Threshold::Above(x), Threshold::Below(x)]);
            let n = values.len() as f64;
            let above = values.iter().filter(|&&v| v > x).count() as f64;
            let below = values.iter().filter(|&&v| v < x).count() as f64;
            prop_assert_eq!(answer.exceedance[0].probability, above / n);
            prop_assert_eq!(answer.exceedance[1].probability, below / n);
            for e in &answer.exceedance {
                prop_assert_eq!(e.resolution, Resolution::Exact);
                prop_assert_eq!(e.bucket, None);
            }
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
            let above = probability(query(&groups, 1, &[], &above));
            let below = probability(query(&groups, 1, &[], &below));
            prop_assert!(above.windows(2).all(|w| w[0] >= w[1]));
            prop_assert!(below.windows(2).all(|w| w[0] <= w[1]));
        }
    }

    proptest! {
        /// Whatever the values and the threshold, the interval holds the exact share of the
        /// values beyond it (a Wilson interval holds its own proportion): the store's resolution
        /// never puts the sample's own answer outside. Exact answers are the exact share.
        #[test]
        fn the_interval_holds_the_exact_share_whatever_shares_the_thresholds_bucket(
            values in prop::collection::vec(value(), 1..400),
            size in 1..100usize,
            pick in 0..400usize,
            nudge in prop_oneof![Just(0.0), -1e-3..1e-3f64],
            above in any::<bool>(),
        ) {
            let x = values[pick % values.len()] * (1.0 + nudge);
            let threshold = if above { Threshold::Above(x) } else { Threshold::Below(x) };
            let answer = query(&groups_of(&values, size), 1, &[], &[threshold]);
            let e = &answer.exceedance[0];
            let exact = values.iter().filter(|&&v| threshold.beyond(v)).count() as f64
                / values.len() as f64;
            prop_assert!(e.ci95[0] <= exact && exact <= e.ci95[1], "{e:?} against {exact}");
            prop_assert!(e.ci95[0] <= e.probability && e.probability <= e.ci95[1], "{e:?}");
            match e.resolution {
                Resolution::Exact => prop_assert_eq!(e.probability, exact),
                Resolution::Bucket => {
                    let [lo, hi] = e.bucket.unwrap();
                    prop_assert!(lo <= x && x <= hi);
                }
            }
        }
    }

    #[test]
    fn a_counted_threshold_is_exact_and_one_sharing_a_bucket_is_bucket_limited() {
        let mut rng = SplitMix(7);
        let values: Vec<f64> = (0..20_000).map(|_| 1.0 + rng.normal()).collect();
        let counted = [Threshold::Above(1.5), Threshold::Below(0.0)];
        let groups: Vec<Accumulator> = values
            .chunks(1000)
            .map(|chunk| {
                let mut acc = Accumulator::new(Some(2.0)).counting(&counted);
                acc.push_batch(chunk);
                acc
            })
            .collect();
        let asked = [
            counted[0],
            counted[1],
            Threshold::Above(2.0),
            Threshold::Above(1.2),
        ];
        let answer = query(&groups, 1, &[], &asked);
        let exact = |t: Threshold| {
            values.iter().filter(|&&v| t.beyond(v)).count() as f64 / values.len() as f64
        };
        for e in &answer.exceedance[..3] {
            assert_eq!(e.resolution, Resolution::Exact, "{e:?}");
            assert_eq!(e.probability, exact(e.threshold));
        }
        let e = &answer.exceedance[3];
        assert_eq!(e.resolution, Resolution::Bucket);
        assert!(e.ci95[0] <= exact(e.threshold) && exact(e.threshold) <= e.ci95[1]);
        // The bucket's values are unknown: the interval is wider than the exact one.
        let json = serde_json::to_value(e).unwrap();
        assert_eq!(json["resolution"], "bucket");
        assert_eq!(json["bucket"].as_array().unwrap().len(), 2);
        let json = serde_json::to_value(&answer.exceedance[0]).unwrap();
        assert_eq!(json["resolution"], "exact");
        assert!(json.get("bucket").is_none());
    }

    #[test]
    fn a_level_beyond_the_data_has_no_value_and_says_why() {
        let mut rng = SplitMix(11);
        let values: Vec<f64> = (0..200_000).map(|_| 5.0 + rng.normal()).collect();
        let groups = groups_of(&values, 200_000 / 32);
        let answer = query(&groups, 1, &[0.999_999, 0.000_001, 0.999, 0.5], &[]);
        for level in ["0.999999", "0.000001"] {
            let q = &answer.quantiles[level];
            assert_eq!((q.value, q.ci95), (None, None), "{level}");
            assert!(
                q.reason.as_deref().unwrap().contains("beyond the data"),
                "{q:?}"
            );
        }
        let json = serde_json::to_value(&answer.quantiles["0.999999"]).unwrap();
        assert!(json["value"].is_null() && json["ci95"].is_null());
        for level in ["0.999", "0.5"] {
            let q = &answer.quantiles[level];
            let [lo, hi] = q.ci95.unwrap();
            assert!(
                lo < q.value.unwrap() && q.value.unwrap() < hi,
                "{level}: {q:?}"
            );
            assert_eq!(q.reason, None);
        }
        // One group cannot measure the spread between groups: no interval either.
        let one = query(&groups_of(&values[..1000], 1000), 1, &[0.5], &[]);
        assert!(one.quantiles["0.5"].value.is_none());
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
            1,
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
                1,
                &[0.9],
                &[Threshold::Above(0.5 * s), Threshold::Below(-s)],
            );
            let covers = |[lo, hi]: [f64; 2], truth: f64| u64::from(lo <= truth && truth <= hi);
            hits[0] += answer.quantiles["0.9"]
                .ci95
                .map_or(0, |ci95| covers(ci95, Z_90 * s));
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
