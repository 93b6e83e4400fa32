//! The running state of one (metric, bin, group): everything a [`Summary`](super::Summary) needs,
//! in constant memory and a few nanoseconds per value.

use super::sketch::{Sketch, rank};
use super::tails::Tails;
use super::threshold::{Beyond, Threshold, ThresholdCount};
use crate::lanes::{Real, fill_lanes, within_lanes};
use std::ops::Range;

/// The sums of one run of values per lane, in the lanes: for the engine, each lane's device's
/// values of one (metric, bin), in operation order, about the shift of the [`Accumulator`] they
/// will join. [`Accumulator::add_lanes`] then adds each lane's run as one term, in lane (device)
/// order, so the sums depend on the devices and their values, not on how many lanes ran side by
/// side: one lane or thirty-two give the same bits. Per value this is a handful of vector
/// operations on independent lanes, instead of one long chain of dependent additions per metric
/// over every device's values in turn. Lanes of several accumulators (small groups sharing a
/// batch) run side by side, each lane about its own accumulator's shift and threshold
/// ([`LaneSums::about`]).
#[derive(Debug, Clone, Copy)]
pub struct LaneSums<L: Real> {
    shift: L,
    threshold: L,
    min: L,
    max: L,
    sum: L,
    sum_sq: L,
    /// Exact: a run of fewer than 2^53 values.
    above: L,
}

impl<L: Real> LaneSums<L> {
    /// Empty runs whose lanes join no accumulator yet: [`LaneSums::about`] gives them theirs.
    pub fn empty() -> Self {
        let zero = L::splat(0.0);
        Self {
            shift: zero,
            threshold: L::splat(f64::INFINITY),
            min: L::splat(f64::INFINITY),
            max: L::splat(f64::NEG_INFINITY),
            sum: zero,
            sum_sq: zero,
            above: zero,
        }
    }

    /// The lanes `lanes` run about `accumulator`'s shift, or, while it is empty, about `first`:
    /// the value it is going to see first (an empty accumulator takes its first value as its
    /// shift); and count its exceedances.
    pub fn about(&mut self, accumulator: &Accumulator, first: f64, lanes: Range<usize>) {
        let shift = if accumulator.count() == 0 {
            first
        } else {
            accumulator.shift
        };
        for k in lanes {
            self.shift.set_lane(k, shift);
            self.threshold.set_lane(k, accumulator.threshold);
        }
    }

    /// Adds the next value of each lane's run, with [`Accumulator::push`]'s arithmetic.
    #[inline(always)]
    pub fn push(&mut self, x: L) {
        self.min = L::select(x.lt(self.min), x, self.min);
        self.max = L::select(x.gt(self.max), x, self.max);
        let d = x - self.shift;
        self.sum = self.sum + d;
        self.sum_sq = self.sum_sq + d * d;
        self.above = L::select(x.gt(self.threshold), self.above + L::splat(1.0), self.above);
    }
}

/// Count, exact min and max, shifted sums, an exact exceedance count, a [`Sketch`] and, when
/// asked for, the most extreme values themselves ([`Tails`]).
///
/// Mean and variance use sums shifted by the first value `s`: `S = sum(x - s)`,
/// `Q = sum((x - s)^2)`, `mean = s + S/n`, `var = (Q - S^2/n) / (n - 1)`. Shifting by a value of
/// the data keeps the subtraction from cancelling catastrophically when the spread is small
/// against the mean, and costs no division per push (unlike Welford's update).
///
/// Deterministic: counts, min, max and the sketch do not depend on the order of pushes and merges;
/// the float sums do, so the caller fixes that order.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Accumulator {
    #[serde(with = "super::bits")]
    min: f64,
    #[serde(with = "super::bits")]
    max: f64,
    #[serde(with = "super::bits")]
    shift: f64,
    #[serde(with = "super::bits")]
    sum: f64,
    #[serde(with = "super::bits")]
    sum_sq: f64,
    #[serde(with = "super::bits::optional")]
    limit: Option<f64>,
    /// `limit`, or `+inf` without one, so the exceedance count needs no branch.
    #[serde(with = "super::bits")]
    threshold: f64,
    above: u64,
    /// A metric's list of thresholds, each with its exact count of values beyond. Always written,
    /// even empty, as is `tails`: the store's binary format has no field names to skip by (JSON
    /// stored before they existed reads as empty).
    #[serde(default)]
    thresholds: Vec<ThresholdCount>,
    sketch: Sketch,
    /// The most extreme values, exactly; none in accumulators stored before they were kept.
    #[serde(default)]
    tails: Option<Tails>,
}

impl Accumulator {
    /// An empty accumulator; with `Some(limit)` it also counts the values `x > limit`.
    pub fn new(limit: Option<f64>) -> Self {
        debug_assert!(limit.is_none_or(|l| !l.is_nan()), "limit must not be NaN");
        Self {
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            shift: 0.0,
            sum: 0.0,
            sum_sq: 0.0,
            limit,
            threshold: limit.unwrap_or(f64::INFINITY),
            above: 0,
            thresholds: Vec::new(),
            sketch: Sketch::new(),
            tails: None,
        }
    }

    /// This accumulator, also keeping exactly its `keep` smallest and `keep` largest values (none
    /// with `None`).
    pub fn keeping(mut self, keep: Option<u32>) -> Self {
        self.tails = keep.map(Tails::new);
        self
    }

    /// This accumulator, also counting exactly the values beyond each of `thresholds`.
    pub fn counting(mut self, thresholds: &[Threshold]) -> Self {
        debug_assert!(
            thresholds.iter().all(|t| !t.value().is_nan()),
            "thresholds must not be NaN"
        );
        self.thresholds = thresholds
            .iter()
            .copied()
            .map(ThresholdCount::new)
            .collect();
        self
    }

    /// An empty accumulator with this one's limit and thresholds: what its values merge into.
    pub fn empty_like(&self) -> Self {
        let thresholds: Vec<Threshold> = self.thresholds.iter().map(|t| t.threshold).collect();
        Self::new(self.limit)
            .counting(&thresholds)
            .keeping(self.tails.as_ref().map(Tails::keep))
    }

    /// Counts the values of `values` beyond each threshold of the list.
    #[inline(always)]
    fn count_thresholds(&mut self, values: impl Iterator<Item = f64> + Clone) {
        for counted in &mut self.thresholds {
            let threshold = counted.threshold;
            counted.beyond += values.clone().filter(|&x| threshold.beyond(x)).count() as u64;
        }
    }

    /// Adds one finite value: compares, three additions, a multiplication and the sketch's shift
    /// and increment.
    #[inline]
    pub fn push(&mut self, x: f64) {
        self.push_batch(std::slice::from_ref(&x));
    }

    /// Pushes `values` in order, as [`Accumulator::push`] on each in turn would, to the bit, with
    /// the running state in registers across the loop instead of loaded and stored per value.
    #[inline]
    pub fn push_batch(&mut self, values: &[f64]) {
        if let Some(&first) = values.first()
            && self.count() == 0
        {
            self.shift = first;
        }
        let (shift, threshold) = (self.shift, self.threshold);
        let (mut min, mut max, mut sum, mut sum_sq, mut above) =
            (self.min, self.max, self.sum, self.sum_sq, self.above);
        for &x in values {
            min = if x < min { x } else { min };
            max = if x > max { x } else { max };
            let d = x - shift;
            sum += d;
            sum_sq += d * d;
            above += u64::from(x > threshold);
        }
        (self.min, self.max, self.sum, self.sum_sq, self.above) = (min, max, sum, sum_sq, above);
        self.count_values(values.iter().copied());
    }

    /// Counts `values` in the sketch, against the list of thresholds and in the tails, one at a
    /// time: what [`Accumulator::count_lanes`] does for a batch's lanes, for the few lanes of a
    /// small group among others, where a pass over every lane of the batch would cost more.
    /// Counts do not depend on order.
    #[inline(always)]
    pub fn count_values(&mut self, values: impl Iterator<Item = f64> + Clone) {
        for x in values.clone() {
            self.sketch.push(x);
            if let Some(tails) = &mut self.tails {
                tails.push(x);
            }
        }
        self.count_thresholds(values);
    }

    /// Counts the lanes `lanes` of each of `columns[m]` in the sketch of `accumulators[m]`
    /// ([`Sketch::push_lanes`]), against its list of thresholds and in its tails: values whose
    /// sums join later, through [`Accumulator::add_lanes`] (until then the counts run ahead of the
    /// sums). Counts do not depend on order.
    #[inline(always)]
    pub fn count_lanes<L: Real>(
        accumulators: &mut [Accumulator],
        columns: &[&L],
        lanes: Range<usize>,
    ) {
        debug_assert_eq!(
            accumulators.len(),
            columns.len(),
            "a column per accumulator"
        );
        let within = within_lanes::<L>(&lanes);
        for (accumulator, column) in accumulators.iter_mut().zip(columns) {
            let filled = fill_lanes(*column, &lanes, within);
            let positive = accumulator.sketch.push_filled_lanes(&filled, lanes.clone());
            if let Some(tails) = &mut accumulator.tails {
                tails.push_bounded_lanes(*column, lanes.clone(), positive);
            }
            if !accumulator.thresholds.is_empty() {
                accumulator.count_thresholds(lanes.clone().map(|k| column.lane(k)));
            }
        }
    }

    /// Adds the runs of the lanes `lanes` of `sums` (made about this accumulator in these lanes by
    /// [`LaneSums::about`], their values already counted by
    /// [`Accumulator::count_lanes`] or [`Accumulator::count_values`]), lane after lane, each run's
    /// sums as one term.
    #[inline(always)]
    pub fn add_lanes<L: Real>(&mut self, sums: &LaneSums<L>, lanes: Range<usize>) {
        debug_assert!(
            lanes
                .clone()
                .all(|k| sums.threshold.lane(k).to_bits() == self.threshold.to_bits()),
            "sums made for another accumulator"
        );
        if let Some(k) = lanes.clone().next() {
            self.shift = sums.shift.lane(k);
        }
        for k in lanes {
            let (min, max) = (sums.min.lane(k), sums.max.lane(k));
            self.min = if min < self.min { min } else { self.min };
            self.max = if max > self.max { max } else { self.max };
            self.sum += sums.sum.lane(k);
            self.sum_sq += sums.sum_sq.lane(k);
            self.above += sums.above.lane(k) as u64;
        }
    }

    /// Adds the values of `other`, re-expressing its sums around this shift `a`: with
    /// `delta = b - a` for its shift `b` and its count `m`,
    /// `sum(x - a) = S_b + m delta` and `sum((x - a)^2) = Q_b + 2 delta S_b + m delta^2`.
    /// An empty `self` takes the other's shift, so merging into an empty accumulator copies exactly.
    ///
    /// # Panics
    /// If the two accumulators were made with different limits or thresholds.
    pub fn merge(&mut self, other: &Accumulator) {
        assert!(
            self.limit.map(f64::to_bits) == other.limit.map(f64::to_bits)
                && self.thresholds.len() == other.thresholds.len()
                && (self.thresholds.iter().zip(&other.thresholds))
                    .all(|(a, b)| a.threshold.same(b.threshold)),
            "merging accumulators with different limits ({:?}, {:?}) or thresholds",
            self.limit,
            other.limit
        );
        for (mine, theirs) in self.thresholds.iter_mut().zip(&other.thresholds) {
            mine.beyond += theirs.beyond;
        }
        // Tails stay exact only while every part kept them.
        match (&mut self.tails, &other.tails) {
            (Some(mine), Some(theirs)) => mine.merge(theirs),
            (tails, _) => *tails = None,
        }
        if other.count() == 0 {
            return;
        }
        if self.count() == 0 {
            self.shift = other.shift;
        }
        let delta = other.shift - self.shift;
        let m = other.count() as f64;
        self.sum_sq += other.sum_sq + 2.0 * delta * other.sum + m * delta * delta;
        self.sum += other.sum + m * delta;
        self.min = self.min.min(other.min);
        self.max = self.max.max(other.max);
        self.above += other.above;
        self.sketch.merge(&other.sketch);
    }

    /// Number of values.
    pub fn count(&self) -> u64 {
        self.sketch.count()
    }

    /// Smallest value, exact; 0 when empty.
    pub fn min(&self) -> f64 {
        if self.count() == 0 { 0.0 } else { self.min }
    }

    /// Largest value, exact; 0 when empty.
    pub fn max(&self) -> f64 {
        if self.count() == 0 { 0.0 } else { self.max }
    }

    /// `s + S/n`, clamped to `[min, max]` against rounding; 0 when empty. Values that are all
    /// NaN (0 times infinity in a run whose inputs passed f64's range) leave no range to clamp
    /// to: their NaN mean stands, for the run's range check to name (`check_in_range`).
    pub fn mean(&self) -> f64 {
        if self.count() == 0 {
            return 0.0;
        }
        let mean = self.shift + self.sum / self.count() as f64;
        if self.min > self.max {
            return mean;
        }
        mean.clamp(self.min, self.max)
    }

    /// Sample variance `(Q - S^2/n) / (n - 1)`, never negative; 0 for fewer than two values.
    /// `S^2` past f64 where `S^2/n` is not is taken as `S (S/n)` (10,000 values of 2e151: their
    /// squares within f64, their sum's square not). Where the squares themselves pass f64,
    /// infinite, never 0: a run's range check names the metric (`check_in_range`); values of
    /// 1e153 and more read a spread of 0 (found from outside).
    pub fn variance(&self) -> f64 {
        let n = self.count();
        if n < 2 {
            return 0.0;
        }
        let n = n as f64;
        let square = self.sum * self.sum;
        let mean_square = if square.is_finite() {
            square / n
        } else {
            self.sum * (self.sum / n)
        };
        let variance = (self.sum_sq - mean_square) / (n - 1.0);
        if variance.is_finite() {
            variance.max(0.0)
        } else {
            f64::INFINITY
        }
    }

    /// Sample standard deviation (`n - 1` in the denominator); 0 for fewer than two values.
    pub fn sd(&self) -> f64 {
        self.variance().sqrt()
    }

    /// The exceedance limit given at construction.
    pub fn limit(&self) -> Option<f64> {
        self.limit
    }

    /// Exact number of values `x > limit`; 0 without a limit.
    pub fn count_above(&self) -> u64 {
        self.above
    }

    /// The list of thresholds counted, each with its exact count.
    pub fn thresholds(&self) -> &[ThresholdCount] {
        &self.thresholds
    }

    /// The exact number of values beyond `threshold`, when it was counted as the values arrived:
    /// one of the list, or `above` the limit.
    pub fn counted_beyond(&self, threshold: Threshold) -> Option<u64> {
        if let (Threshold::Above(x), Some(limit)) = (threshold, self.limit)
            && x.to_bits() == limit.to_bits()
        {
            return Some(self.above);
        }
        self.thresholds
            .iter()
            .find(|counted| counted.threshold.same(threshold))
            .map(|counted| counted.beyond)
    }

    /// The exact number of values beyond `threshold` when the kept extremes settle it
    /// ([`Tails::beyond`]).
    pub fn tails_beyond(&self, threshold: Threshold) -> Option<u64> {
        self.tails.as_ref()?.beyond(threshold, self.count())
    }

    /// The bucket histogram of the values.
    pub fn sketch(&self) -> &Sketch {
        &self.sketch
    }

    /// [`Sketch::quantile`] clamped to the exact `[min, max]` (which never moves an estimate away
    /// from the true quantile), and exactly `min` or `max` at the ranks 1 and `n`; 0 when empty.
    pub fn quantile(&self, q: f64) -> f64 {
        self.quantiles(&[q])[0]
    }

    /// [`Accumulator::quantile`] for several levels in one pass.
    pub fn quantiles(&self, levels: &[f64]) -> Vec<f64> {
        let (n, min, max) = (self.count(), self.min(), self.max());
        let mut values = self.sketch.quantiles(levels);
        for (value, &q) in values.iter_mut().zip(levels) {
            *value = match rank(q, n) {
                1 => min,
                k if k == n => max,
                // Every value NaN: no range (as in `mean`).
                _ if min > max => f64::NAN,
                _ => value.clamp(min, max),
            };
        }
        values
    }
}

/// Queries after the run ([`super::query`]).
impl Accumulator {
    /// What this group says of its values beyond `threshold`: its exact count when it counted that
    /// threshold as it ran or its kept extremes settle it ([`Tails::beyond`](super::Tails::beyond)); otherwise the exact `[min, max]` settles the threshold outside them,
    /// and inside the sketch settles every bucket but the one holding the threshold.
    pub(super) fn beyond(&self, threshold: Threshold) -> (Beyond, Option<[f64; 2]>) {
        if let Some(count) = self
            .counted_beyond(threshold)
            .or_else(|| self.tails_beyond(threshold))
        {
            return (Beyond::exact(count), None);
        }
        let (n, min, max) = (self.count(), self.min(), self.max());
        let t = threshold.value();
        let settled = match threshold {
            _ if n == 0 => Some(0),
            Threshold::Above(_) if t >= max => Some(0),
            Threshold::Above(_) if t < min => Some(n),
            Threshold::Below(_) if t <= min => Some(0),
            Threshold::Below(_) if t > max => Some(n),
            _ => None,
        };
        if let Some(count) = settled {
            return (Beyond::exact(count), None);
        }
        let around = self.sketch().around(t);
        let [lo, hi] = around.bucket;
        // The bucket's values lie within the group's exact range too.
        let (lo, hi) = (lo.max(min), hi.min(max));
        let share_beyond = match threshold {
            _ if hi <= lo => f64::from(u8::from(threshold.beyond(lo))),
            Threshold::Above(_) => ((hi - t) / (hi - lo)).clamp(0.0, 1.0),
            Threshold::Below(_) => ((t - lo) / (hi - lo)).clamp(0.0, 1.0),
        };
        let sure = match threshold {
            Threshold::Above(_) => around.above,
            Threshold::Below(_) => around.below,
        };
        let within = around.within;
        if hi <= lo || within == 0 {
            let count = sure + if share_beyond == 1.0 { within } else { 0 };
            return (Beyond::exact(count), None);
        }
        let beyond = Beyond {
            sure,
            unsure: within,
            spread: sure as f64 + within as f64 * share_beyond,
        };
        (beyond, Some(around.bucket))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lanes::Lanes;
    use crate::stats::QUANTILES;
    use crate::stats::test_util::{SplitMix, exact_quantile};
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    fn accumulate(values: &[f64], limit: Option<f64>) -> Accumulator {
        let mut acc = Accumulator::new(limit);
        values.iter().for_each(|&x| acc.push(x));
        acc
    }

    fn exact_mean_sd(values: &[f64]) -> (f64, f64) {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, var.sqrt())
    }

    #[test]
    fn empty_is_zero() {
        let acc = Accumulator::new(Some(1.0));
        assert_eq!(acc.count(), 0);
        for v in [
            acc.min(),
            acc.max(),
            acc.mean(),
            acc.sd(),
            acc.quantile(0.5),
        ] {
            assert_eq!(v, 0.0);
        }
        assert_eq!(acc.count_above(), 0);
    }

    #[test]
    fn single_value() {
        let acc = accumulate(&[7.25], None);
        assert_eq!((acc.count(), acc.min(), acc.max()), (1, 7.25, 7.25));
        assert_eq!((acc.mean(), acc.sd()), (7.25, 0.0));
        assert_eq!(acc.quantile(0.01), 7.25);
    }

    #[test]
    fn moments_match_two_pass() {
        let mut rng = SplitMix(11);
        // A large offset against a small spread: the shift keeps the variance accurate.
        let values: Vec<f64> = (0..10_000).map(|_| 1e6 + rng.normal()).collect();
        let acc = accumulate(&values, None);
        let (mean, sd) = exact_mean_sd(&values);
        assert_relative_eq!(acc.mean(), mean, max_relative = 1e-14);
        assert_relative_eq!(acc.sd(), sd, max_relative = 1e-9);
    }

    #[test]
    fn exceedance_counts_strictly_above() {
        let mut rng = SplitMix(12);
        let values: Vec<f64> = (0..10_000)
            .map(|_| (rng.next_u64() % 10) as f64 * 0.5)
            .collect();
        let limit = 2.5;
        let acc = accumulate(&values, Some(limit));
        let direct = values.iter().filter(|&&x| x > limit).count() as u64;
        assert_eq!(acc.count_above(), direct);
        assert_eq!(acc.limit(), Some(limit));
        assert_eq!(accumulate(&values, None).count_above(), 0);
    }

    proptest! {
        /// A list of thresholds is counted exactly, value by value, however the values arrive
        /// (pushed, in batches, in lanes, merged from parts) and across serialisation.
        #[test]
        fn a_list_of_thresholds_is_counted_exactly_however_the_values_arrive(
            values in prop::collection::vec(batch_value(), 1..300),
            at in prop::collection::vec(-1.0..1.0f64, 1..6),
            cut in 0..300usize,
        ) {
            let thresholds: Vec<Threshold> = at
                .iter()
                .enumerate()
                .map(|(i, &x)| if i % 2 == 0 { Threshold::Above(x) } else { Threshold::Below(x) })
                .collect();
            let expected: Vec<u64> = thresholds
                .iter()
                .map(|t| values.iter().filter(|&&x| t.beyond(x)).count() as u64)
                .collect();
            let fresh = || Accumulator::new(Some(0.25)).counting(&thresholds);
            let counts = |acc: &Accumulator| -> Vec<u64> {
                thresholds.iter().map(|&t| acc.counted_beyond(t).unwrap()).collect()
            };
            let mut pushed = fresh();
            values.iter().for_each(|&x| pushed.push(x));
            let mut batched = fresh();
            batched.push_batch(&values);
            let mut lanes = fresh();
            for chunk in values.chunks(4) {
                let x = Lanes::<4>::from_fn(|k| chunk.get(k).copied().unwrap_or(0.0));
                Accumulator::count_lanes(std::slice::from_mut(&mut lanes), &[&x], 0..chunk.len());
            }
            let (a, b) = values.split_at(cut.min(values.len()));
            let (mut merged, mut part) = (fresh(), fresh());
            merged.push_batch(a);
            part.push_batch(b);
            merged.merge(&part);
            let text = serde_json::to_string(&merged).unwrap();
            let restored: Accumulator = serde_json::from_str(&text).unwrap();
            for acc in [&pushed, &batched, &lanes, &merged, &restored] {
                prop_assert_eq!(counts(acc), expected.clone());
            }
            prop_assert_eq!(pushed.counted_beyond(Threshold::Above(0.25)), Some(pushed.count_above()));
            prop_assert_eq!(pushed.counted_beyond(Threshold::Below(0.25)), None);
            prop_assert_eq!(restored.empty_like().thresholds().len(), thresholds.len());
        }
    }

    #[test]
    #[should_panic(expected = "or thresholds")]
    fn merge_rejects_different_thresholds() {
        let counting = Accumulator::new(None).counting(&[Threshold::Above(1.0)]);
        Accumulator::new(None).merge(&counting);
    }

    #[test]
    fn quantiles_are_clamped_to_min_max() {
        let values = [1.0, 2.0, 3.0];
        let acc = accumulate(&values, None);
        assert_eq!(acc.quantile(0.0), 1.0);
        assert_eq!(acc.quantile(1.0), 3.0);
        for (_, q) in QUANTILES {
            let exact = exact_quantile(&values, q);
            assert!(((acc.quantile(q) - exact) / exact).abs() < 0.005);
        }
    }

    #[test]
    #[should_panic(expected = "different limits")]
    fn merge_rejects_different_limits() {
        Accumulator::new(Some(1.0)).merge(&Accumulator::new(None));
    }

    /// The cuts clamped to `len`, with 0 and `len`, in order: consecutive pairs bound the parts.
    fn parts(len: usize, cuts: Vec<usize>) -> Vec<usize> {
        let mut cuts: Vec<usize> = cuts.into_iter().map(|c| c.min(len)).collect();
        cuts.extend([0, len]);
        cuts.sort_unstable();
        cuts
    }

    fn value() -> impl Strategy<Value = f64> {
        prop_oneof![Just(0.0), 0.0..1.0f64, -1e3..1e3f64, 10.0..10.5f64]
    }

    proptest! {
        #[test]
        fn merge_equals_pushing_everything(
            values in prop::collection::vec(value(), 0..400),
            cuts in prop::collection::vec(0..400usize, 0..6),
            limit in prop::option::of(-1.0..1.0f64),
        ) {
            let cuts = parts(values.len(), cuts);
            let mut merged = Accumulator::new(limit);
            for part in cuts.windows(2) {
                merged.merge(&accumulate(&values[part[0]..part[1]], limit));
            }
            let whole = accumulate(&values, limit);
            prop_assert_eq!(merged.count(), whole.count());
            prop_assert_eq!(merged.min(), whole.min());
            prop_assert_eq!(merged.max(), whole.max());
            prop_assert_eq!(merged.count_above(), whole.count_above());
            let levels: Vec<f64> = QUANTILES.iter().map(|&(_, q)| q).collect();
            prop_assert_eq!(merged.quantiles(&levels), whole.quantiles(&levels));
            // Relative to the data's scale, so that a mean or sd near 0 is not held to 1e-12 of itself.
            let scale = values.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            prop_assert!((merged.mean() - whole.mean()).abs() <= 1e-12 * scale);
            prop_assert!((merged.sd() - whole.sd()).abs() <= 1e-12 * scale);
            if values.len() >= 2 {
                let (mean, sd) = exact_mean_sd(&values);
                prop_assert!((whole.mean() - mean).abs() <= 1e-12 * scale);
                prop_assert!((whole.sd() - sd).abs() <= 1e-12 * scale);
            }
        }
    }

    /// Mixed signs, signed zeros and new extremes beyond the sketch's growth slack.
    fn batch_value() -> impl Strategy<Value = f64> {
        prop_oneof![
            Just(0.0),
            Just(-0.0),
            value(),
            (-30.0..30.0f64, any::<bool>()).prop_map(|(e, negative)| {
                let x = 10f64.powf(e);
                if negative { -x } else { x }
            }),
        ]
    }

    /// Every float by its bits, every count, every sketch slot.
    fn state(acc: &Accumulator) -> serde_json::Value {
        serde_json::to_value(acc).expect("an accumulator serialises")
    }

    proptest! {
        #[test]
        fn push_batch_equals_pushing_one_by_one(
            start in prop::collection::vec(batch_value(), 0..20),
            values in prop::collection::vec(batch_value(), 0..400),
            cuts in prop::collection::vec(0..400usize, 0..6),
            limit in prop::option::of(-1.0..1.0f64),
        ) {
            let cuts = parts(values.len(), cuts);
            let mut one_by_one = accumulate(&start, limit);
            let mut batched = one_by_one.clone();
            values.iter().for_each(|&x| one_by_one.push(x));
            for part in cuts.windows(2) {
                batched.push_batch(&values[part[0]..part[1]]);
            }
            prop_assert_eq!(state(&batched), state(&one_by_one));
            prop_assert_eq!(batched, one_by_one);
        }
    }

    /// An accumulator keeping three values at each end, `start` pushed.
    fn started(start: &[f64], limit: Option<f64>) -> Accumulator {
        let mut accumulator = Accumulator::new(limit).keeping(Some(3));
        start.iter().for_each(|&x| accumulator.push(x));
        accumulator
    }

    /// Devices' runs of values as [`LaneSums`] on `L::LANES` lanes, the spare lanes copying the
    /// first device; `start` pushed before.
    fn lane_runs<L: Real>(start: &[f64], runs: &[&[f64]], limit: Option<f64>) -> Accumulator {
        let mut accumulator = started(start, limit);
        for batch in runs.chunks(L::LANES) {
            let lane = |k: usize| batch.get(k).unwrap_or(&batch[0]);
            let mut sums = LaneSums::<L>::empty();
            sums.about(&accumulator, batch[0][0], 0..L::LANES);
            for i in 0..batch[0].len() {
                let x = L::from_fn(|k| lane(k)[i]);
                sums.push(x);
                Accumulator::count_lanes(
                    std::slice::from_mut(&mut accumulator),
                    &[&x],
                    0..batch.len(),
                );
            }
            accumulator.add_lanes(&sums, 0..batch.len());
        }
        accumulator
    }

    /// The runs of two accumulators side by side in one batch (`runs[..split]` and the rest, at
    /// most `L::LANES` in all), each lane about its own accumulator ([`LaneSums::about`]), the
    /// values counted a batch at a time or, with `one_at_a_time`, a value at a time.
    fn shared_runs<L: Real>(
        start: &[f64],
        runs: &[&[f64]],
        split: usize,
        limit: Option<f64>,
        one_at_a_time: bool,
    ) -> [Accumulator; 2] {
        let mut accumulators = [started(start, limit), started(start, limit)];
        let lanes = [0..split, split..runs.len()];
        let lane = |k: usize| runs.get(k).unwrap_or(&runs[0]);
        let mut sums = LaneSums::<L>::empty();
        for (accumulator, lanes) in accumulators.iter().zip(&lanes) {
            sums.about(accumulator, runs[lanes.start][0], lanes.clone());
        }
        for i in 0..runs[0].len() {
            let x = L::from_fn(|k| lane(k)[i]);
            sums.push(x);
            for (accumulator, lanes) in accumulators.iter_mut().zip(&lanes) {
                if one_at_a_time {
                    accumulator.count_values(lanes.clone().map(|k| x.lane(k)));
                } else {
                    Accumulator::count_lanes(
                        std::slice::from_mut(accumulator),
                        &[&x],
                        lanes.clone(),
                    );
                }
            }
        }
        for (accumulator, lanes) in accumulators.iter_mut().zip(lanes) {
            accumulator.add_lanes(&sums, lanes);
        }
        accumulators
    }

    proptest! {
        /// Two accumulators sharing a batch's lanes, counted either way, each come out with the
        /// bits they have with a batch of their own.
        #[test]
        fn accumulators_sharing_lanes_get_the_bits_they_get_alone(
            start in prop::collection::vec(batch_value(), 0..4),
            devices in 2..9usize,
            split in 1..8usize,
            len in 1..30usize,
            values in prop::collection::vec(batch_value(), 270),
            limit in prop::option::of(-1.0..1.0f64),
        ) {
            let split = split.min(devices - 1);
            let runs: Vec<&[f64]> = values.chunks_exact(len).take(devices).collect();
            let alone = [
                lane_runs::<Lanes<8>>(&start, &runs[..split], limit),
                lane_runs::<Lanes<8>>(&start, &runs[split..], limit),
            ];
            for one_at_a_time in [false, true] {
                let shared = shared_runs::<Lanes<8>>(&start, &runs, split, limit, one_at_a_time);
                for (shared, alone) in shared.iter().zip(&alone) {
                    prop_assert_eq!(shared, alone);
                    for (a, b) in [(shared.min, alone.min), (shared.max, alone.max),
                        (shared.sum, alone.sum), (shared.sum_sq, alone.sum_sq),
                        (shared.shift, alone.shift)] {
                        prop_assert_eq!(a.to_bits(), b.to_bits());
                    }
                }
            }
        }

        /// The same bits on one lane, four or eight (full and partly spare batches), and what
        /// pushing every value in device order gives: the same count, extremes, exceedances and
        /// sketch, and sums apart only by their rounding.
        #[test]
        fn lane_sums_give_the_bits_of_any_width_and_the_values_of_pushing_each(
            start in prop::collection::vec(batch_value(), 0..4),
            devices in 1..20usize,
            len in 1..30usize,
            values in prop::collection::vec(batch_value(), 600),
            limit in prop::option::of(-1.0..1.0f64),
        ) {
            let runs: Vec<&[f64]> = values.chunks_exact(len).take(devices).collect();
            let one = lane_runs::<f64>(&start, &runs, limit);
            for other in [
                lane_runs::<Lanes<4>>(&start, &runs, limit),
                lane_runs::<Lanes<8>>(&start, &runs, limit),
            ] {
                prop_assert_eq!(&other, &one);
                for (a, b) in [(other.min, one.min), (other.max, one.max), (other.sum, one.sum),
                    (other.sum_sq, one.sum_sq), (other.shift, one.shift)] {
                    prop_assert_eq!(a.to_bits(), b.to_bits());
                }
            }
            let mut pushed = accumulate(&start, limit);
            runs.iter().for_each(|run| run.iter().for_each(|&x| pushed.push(x)));
            prop_assert_eq!(one.count(), pushed.count());
            prop_assert_eq!(one.min.to_bits(), pushed.min.to_bits());
            prop_assert_eq!(one.max.to_bits(), pushed.max.to_bits());
            prop_assert_eq!(one.count_above(), pushed.count_above());
            prop_assert_eq!(one.sketch(), pushed.sketch());
            prop_assert_eq!(one.shift.to_bits(), pushed.shift.to_bits());
            let scale = start.iter().chain(runs.concat().iter()).map(|x| (x - one.shift).abs())
                .fold(0.0, f64::max);
            let n = one.count() as f64;
            prop_assert!((one.sum - pushed.sum).abs() <= 1e-13 * n * scale);
            prop_assert!((one.sum_sq - pushed.sum_sq).abs() <= 1e-13 * n * scale * scale);
        }
    }

    #[test]
    fn merge_of_groups_matches_one_accumulator_relatively() {
        let mut rng = SplitMix(13);
        let values: Vec<f64> = (0..32_000)
            .map(|_| 2e-3 * (0.5 * rng.normal()).exp())
            .collect();
        let mut merged = Accumulator::new(Some(3e-3));
        for group in values.chunks(1000) {
            merged.merge(&accumulate(group, Some(3e-3)));
        }
        let whole = accumulate(&values, Some(3e-3));
        assert_eq!(merged.count(), whole.count());
        assert_eq!(merged.count_above(), whole.count_above());
        assert_relative_eq!(merged.mean(), whole.mean(), max_relative = 1e-12);
        assert_relative_eq!(merged.sd(), whole.sd(), max_relative = 1e-12);
    }
}
