//! The running state of one (metric, bin, group): everything a [`Summary`](super::Summary) needs,
//! in constant memory and a few nanoseconds per value.

use super::sketch::{Sketch, rank};

/// Accumulators [`Accumulator::push_rows`] takes through their values side by side.
pub const INTERLEAVED: usize = 4;

/// Where [`Accumulator::push_rows`] reads each metric's values in a block of `metrics` metrics x
/// `values` values: the metrics in groups of [`INTERLEAVED`] (the last one narrower), each group
/// row by row, a row holding one value of each of its metrics. A row is one vector load, and the
/// group's running sums one vector of independent chains.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rows {
    metrics: usize,
    values: usize,
}

impl Rows {
    pub fn new(metrics: usize, values: usize) -> Self {
        Self { metrics, values }
    }

    /// Values in the block.
    pub fn len(&self) -> usize {
        self.metrics * self.values
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Value `i` of metric `m` is at `offset + i * stride`: `(offset, stride)`.
    #[inline(always)]
    pub fn place(&self, m: usize) -> (usize, usize) {
        debug_assert!(m < self.metrics, "metric {m} of {}", self.metrics);
        let group = m / INTERLEAVED * INTERLEAVED;
        let width = (self.metrics - group).min(INTERLEAVED);
        (group * self.values + (m - group), width)
    }
}

/// `K` accumulators from rows of `K` values, value `k` of each row into `accumulators[k]`: each
/// accumulator sees its values in order, so its bits are those of pushing them one by one, while
/// the `K` chains of dependent additions (and of sketch increments) overlap.
#[inline(always)]
fn push_side_by_side<const K: usize>(accumulators: &mut [Accumulator; K], rows: &[f64]) {
    debug_assert_eq!(rows.len() % K, 0, "whole rows");
    if let Some(first) = rows.first_chunk::<K>() {
        for (accumulator, &first) in accumulators.iter_mut().zip(first) {
            if accumulator.count() == 0 {
                accumulator.shift = first;
            }
        }
    }
    let shift = accumulators.each_ref().map(|a| a.shift);
    let threshold = accumulators.each_ref().map(|a| a.threshold);
    let mut min = accumulators.each_ref().map(|a| a.min);
    let mut max = accumulators.each_ref().map(|a| a.max);
    let mut sum = accumulators.each_ref().map(|a| a.sum);
    let mut sum_sq = accumulators.each_ref().map(|a| a.sum_sq);
    let mut above = accumulators.each_ref().map(|a| a.above);
    for x in rows.chunks_exact(K) {
        for k in 0..K {
            min[k] = if x[k] < min[k] { x[k] } else { min[k] };
            max[k] = if x[k] > max[k] { x[k] } else { max[k] };
            let d = x[k] - shift[k];
            sum[k] += d;
            sum_sq[k] += d * d;
            above[k] += u64::from(x[k] > threshold[k]);
        }
    }
    // The sketches in a second pass: their increments are memory updates, kept out of the loop
    // of register sums.
    Sketch::push_rows(accumulators.each_mut().map(|a| &mut a.sketch), rows);
    for (k, accumulator) in accumulators.iter_mut().enumerate() {
        (
            accumulator.min,
            accumulator.max,
            accumulator.sum,
            accumulator.sum_sq,
            accumulator.above,
        ) = (min[k], max[k], sum[k], sum_sq[k], above[k]);
    }
}

/// [`push_side_by_side`] on `K` accumulators.
#[inline(always)]
fn push_group<const K: usize>(accumulators: &mut [Accumulator], rows: &[f64]) {
    let accumulators: &mut [Accumulator; K] = accumulators.try_into().expect("K accumulators");
    push_side_by_side(accumulators, rows);
}

/// The last, narrower group of [`Accumulator::push_rows`], out of line: compiled into each kernel
/// as well, it made the kernel slower than it saved (docs/performance.md).
#[inline(never)]
fn push_rest(accumulators: &mut [Accumulator], rows: &[f64]) {
    match accumulators.len() {
        0 => {}
        1 => push_group::<1>(accumulators, rows),
        2 => push_group::<2>(accumulators, rows),
        3 => push_group::<3>(accumulators, rows),
        _ => unreachable!("fewer than INTERLEAVED accumulators are left"),
    }
}

/// Count, exact min and max, shifted sums, an exact exceedance count and a [`Sketch`].
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
    sketch: Sketch,
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
            sketch: Sketch::new(),
        }
    }

    /// Adds one finite value: compares, three additions, a multiplication and the sketch's shift
    /// and increment.
    #[inline]
    pub fn push(&mut self, x: f64) {
        self.push_batch(std::slice::from_ref(&x));
    }

    /// Pushes `values` in order, as [`Accumulator::push`] on each in turn would, to the bit: the
    /// sums are added in the same sequence, but the running state stays in registers across the
    /// loop instead of being loaded and stored per value (a bin of a metric in the engine).
    #[inline]
    pub fn push_batch(&mut self, values: &[f64]) {
        push_side_by_side(std::array::from_mut(self), values);
    }

    /// Pushes a block laid out as [`Rows`] says, metric `m`'s values into `accumulators[m]`, as
    /// [`Accumulator::push_batch`] on each metric's values in turn would, to the bit. Each
    /// accumulator's sums are one chain of dependent additions that must stay in order; taking
    /// [`INTERLEAVED`] accumulators through their values side by side lets those chains (and the
    /// sketches' increments) run at the same time instead of one after another.
    ///
    /// # Panics
    /// If `rows` does not split into `accumulators.len()` equally many values.
    #[inline(always)]
    pub fn push_rows(accumulators: &mut [Accumulator], rows: &[f64]) {
        if accumulators.is_empty() {
            assert!(rows.is_empty(), "values without an accumulator");
            return;
        }
        let values = rows.len() / accumulators.len();
        assert_eq!(
            values * accumulators.len(),
            rows.len(),
            "metrics with unequally many values"
        );
        let mut accumulators = accumulators.chunks_exact_mut(INTERLEAVED);
        let mut rows = rows.chunks_exact(INTERLEAVED * values.max(1));
        for (group, rows) in accumulators.by_ref().zip(rows.by_ref()) {
            push_group::<INTERLEAVED>(group, rows);
        }
        push_rest(accumulators.into_remainder(), rows.remainder());
    }

    /// Adds the values of `other`, re-expressing its sums around this shift `a`: with
    /// `delta = b - a` for its shift `b` and its count `m`,
    /// `sum(x - a) = S_b + m delta` and `sum((x - a)^2) = Q_b + 2 delta S_b + m delta^2`.
    /// An empty `self` takes the other's shift, so merging into an empty accumulator copies exactly.
    ///
    /// # Panics
    /// If the two accumulators were made with different limits.
    pub fn merge(&mut self, other: &Accumulator) {
        assert!(
            self.limit.map(f64::to_bits) == other.limit.map(f64::to_bits),
            "merging accumulators with different limits ({:?}, {:?})",
            self.limit,
            other.limit
        );
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

    /// `s + S/n`, clamped to `[min, max]` against rounding; 0 when empty.
    pub fn mean(&self) -> f64 {
        if self.count() == 0 {
            return 0.0;
        }
        let mean = self.shift + self.sum / self.count() as f64;
        mean.clamp(self.min, self.max)
    }

    /// Sample variance `(Q - S^2/n) / (n - 1)`, never negative; 0 for fewer than two values.
    pub fn variance(&self) -> f64 {
        let n = self.count();
        if n < 2 {
            return 0.0;
        }
        let n = n as f64;
        ((self.sum_sq - self.sum * self.sum / n) / (n - 1.0)).max(0.0)
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
                _ => value.clamp(min, max),
            };
        }
        values
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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

    proptest! {
        /// Whole groups of four and a narrower last one, empty and fresh accumulators, one value
        /// per metric.
        #[test]
        fn push_rows_equals_push_batch_per_metric(
            starts in prop::collection::vec(prop::collection::vec(batch_value(), 0..6), 0..11),
            len in 0..70usize,
            values in prop::collection::vec(batch_value(), 770),
            limit in prop::option::of(-1.0..1.0f64),
        ) {
            let mut by_metric: Vec<Accumulator> =
                starts.iter().map(|start| accumulate(start, limit)).collect();
            let mut side_by_side = by_metric.clone();
            let layout = Rows::new(starts.len(), len);
            let mut rows = vec![f64::NAN; layout.len()];
            for (m, (accumulator, column)) in
                by_metric.iter_mut().zip(values.chunks_exact(len.max(1))).enumerate()
            {
                let column = &column[..len];
                accumulator.push_batch(column);
                let (offset, stride) = layout.place(m);
                for (i, &x) in column.iter().enumerate() {
                    rows[offset + i * stride] = x;
                }
            }
            prop_assert!(rows.iter().all(|x| !x.is_nan()), "every slot placed once");
            Accumulator::push_rows(&mut side_by_side, &rows);
            for (a, b) in side_by_side.iter().zip(&by_metric) {
                prop_assert_eq!(state(a), state(b));
            }
            prop_assert_eq!(side_by_side, by_metric);
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
