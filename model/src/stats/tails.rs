//! The most extreme values of an accumulator, kept exactly, so that a threshold asked after the run
//! in the far tail is counted exactly rather than to its sketch bucket.
//!
//! [`Tails`] keeps the `k` smallest and the `k` largest values seen (every value while there are at
//! most `2k`), the bottom `k` and the top `k` each in increasing order. Between the two gates, the
//! `k`-th smallest and the `k`-th largest value kept, a value cannot be among them and is dropped:
//! most values cost two comparisons. One beyond a gate takes its place in its end by insertion,
//! pushing that end's innermost value out, and the gate moves to the new `k`-th value at once, so
//! no value enters that the values before it already rule out. Every value dropped lies between
//! the gates, and the gates only move outwards, so a threshold `above t` with `t >= ` the `k`-th
//! largest value (or `below t` with `t <=` the `k`-th smallest) is counted exactly from the values
//! kept.
//!
//! Until `2k` values have come, every value enters: the bottom is padded above its values with
//! `+inf`, the top below its values with `-inf`, so each gate is infinite until its end is full,
//! and the value a full bottom pushes out moves to the top. No list is gathered and sorted.
//!
//! What is kept ([`Tails::values`]) is the bottom and top `k` of all values: a multiset of them,
//! whatever order they arrived in and however they were split and merged, so it serialises and
//! compares to the bit (`-0.0` is kept as `0.0`, which no threshold tells apart).
//!
//! Memory: `2k` floats per accumulator; [`keep_for_bins`] bounds `k` by the number of bins, so a
//! job's kept values stay within a fixed budget per metric and group.

use super::sketch::PositiveExtremes;
use super::threshold::Threshold;
use crate::lanes::{Mask, Real, lane_bits};
use std::ops::Range;

/// The most values kept at each end of one accumulator.
pub const MAX_KEEP: u32 = 64;

/// The fewest values kept at each end: with more bins than `KEEP_BUDGET / MIN_KEEP` (a wear
/// curve, not a tail study) nothing is kept. Four values at each end of 1000 bins of 62 values
/// cost 30 % more time and 25 % more memory (2000 devices x 1000 operations, one a bin).
pub const MIN_KEEP: u32 = 4;

/// Values kept at each end of one metric and group, summed over its bins, before [`MIN_KEEP`].
pub const KEEP_BUDGET: u64 = 256;

/// Values kept at each end of each bin's accumulator in a job of `bins` bins:
/// `KEEP_BUDGET / bins` up to [`MAX_KEEP`] (64 up to 4 bins, 25 at the default 10, 4 at 64), and
/// none below [`MIN_KEEP`] (more than 64 bins).
pub fn keep_for_bins(bins: u64) -> Option<u32> {
    let keep = (KEEP_BUDGET / bins.max(1)).min(u64::from(MAX_KEEP));
    u32::try_from(keep).ok().filter(|&keep| keep >= MIN_KEEP)
}

/// The `keep` smallest and `keep` largest values seen.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(from = "Stored")]
pub struct Tails {
    keep: u32,
    /// The bottom `keep` and then the top `keep`, each in increasing order (empty before the
    /// first value): while fewer than `2 keep` values have come, the bottom's values followed by
    /// `+inf`, the top's preceded by `-inf`.
    values: Vec<f64>,
    /// The values that have come, up to `2 keep` (beyond, every slot holds a value).
    seen: usize,
    /// A value `x` with `low <= x <= high` is not among the ends: the `keep`-th smallest and the
    /// `keep`-th largest value kept, the bottom's and the top's innermost slots (infinite until
    /// their end is full). Every value dropped lies between them.
    low: f64,
    high: f64,
}

/// The serialised form: the values kept, in increasing order, by their bits.
#[derive(serde::Serialize, serde::Deserialize)]
struct Stored {
    keep: u32,
    #[serde(with = "super::bits::list")]
    kept: Vec<f64>,
}

/// [`Stored`] as [`Tails`] writes it: the same fields and bytes, its list written from the bottom's
/// and the top's slots where they are, not gathered into a vector first ([`Tails::values`]): a
/// copy and an allocation for each of a small job's 3,680 accumulators.
#[derive(serde::Serialize)]
#[serde(rename = "Stored")]
struct StoredEnds<'a> {
    keep: u32,
    #[serde(serialize_with = "joined")]
    kept: (&'a [f64], &'a [f64]),
}

fn joined<S: serde::Serializer>(ends: &(&[f64], &[f64]), serializer: S) -> Result<S::Ok, S::Error> {
    super::bits::list::serialize_joined(ends.0, ends.1, serializer)
}

impl serde::Serialize for Tails {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        StoredEnds {
            keep: self.keep,
            kept: self.kept(),
        }
        .serialize(serializer)
    }
}

impl From<Stored> for Tails {
    /// The values arrive as pushed values do, so a list stored in any order (or holding more than
    /// its ends) reads back as the ends of its values. A list as [`Tails`] writes it (finite, in
    /// increasing order, at most `2 keep`) is laid out at once ([`Tails::from_ends`]).
    fn from(stored: Stored) -> Self {
        Tails::from_ends(stored.keep, &stored.kept).unwrap_or_else(|| {
            let mut tails = Tails::new(stored.keep);
            stored.kept.iter().for_each(|&x| tails.push(x));
            tails
        })
    }
}

impl PartialEq for Tails {
    fn eq(&self, other: &Self) -> bool {
        let bits =
            |tails: &Tails| -> Vec<u64> { tails.values().iter().map(|x| x.to_bits()).collect() };
        self.keep == other.keep && bits(self) == bits(other)
    }
}

impl Tails {
    /// An empty list keeping `keep` (at least 1) values at each end.
    pub fn new(keep: u32) -> Self {
        Self {
            keep: keep.max(1),
            values: Vec::new(),
            seen: 0,
            low: f64::INFINITY,
            high: f64::NEG_INFINITY,
        }
    }

    /// The list that pushing `kept` in order leaves, laid out without pushing, when `kept` is
    /// finite, in increasing order and at most `2 keep` long: its first `keep` values are the
    /// bottom, the rest the top's last slots. `None` for any other list (a merge reads 3,680
    /// lists of the scale-out job's groups, each entered value by value before).
    fn from_ends(keep: u32, kept: &[f64]) -> Option<Self> {
        let mut tails = Tails::new(keep);
        let k = tails.keep as usize;
        let ends = kept.len() <= 2 * k
            && kept.iter().all(|x| x.is_finite())
            && kept.is_sorted_by(|a, b| a <= b);
        if !ends {
            return None;
        }
        if kept.is_empty() {
            return Some(tails);
        }
        // As `enter` takes them: `-0.0` as `0.0`.
        let value = |x: &f64| x + 0.0;
        let (bottom, top) = kept.split_at(kept.len().min(k));
        let mut values = Vec::with_capacity(2 * k);
        values.extend(bottom.iter().map(value));
        values.resize(k, f64::INFINITY);
        values.resize(2 * k - top.len(), f64::NEG_INFINITY);
        values.extend(top.iter().map(value));
        tails.seen = kept.len();
        tails.low = values[k - 1];
        tails.high = values[k];
        tails.values = values;
        Some(tails)
    }

    /// The values kept at each end.
    pub fn keep(&self) -> u32 {
        self.keep
    }

    /// The bottom and top `keep` of the values seen (all of them while there are at most
    /// `2 keep`), in increasing order.
    pub fn values(&self) -> Vec<f64> {
        let (bottom, top) = self.kept();
        [bottom, top].concat()
    }

    /// The values of the bottom and of the top, without their padding.
    fn kept(&self) -> (&[f64], &[f64]) {
        let k = self.keep as usize;
        if self.values.is_empty() {
            return (&[], &[]);
        }
        let (bottom, top) = self.values.split_at(k);
        (
            &bottom[..self.seen.min(k)],
            &top[k - self.seen.saturating_sub(k)..],
        )
    }

    /// Adds one finite value.
    #[inline(always)]
    pub fn push(&mut self, x: f64) {
        if x < self.low || x > self.high {
            self.enter(x);
        }
    }

    /// Adds the lanes `lanes` of `column`, in lane order: one vector comparison with each gate,
    /// then each lane beyond a gate enters, or is dropped when the lanes entering before it have
    /// moved the gate past it, as [`Tails::push`] would drop it.
    #[inline(always)]
    pub fn push_lanes<L: Real>(&mut self, column: &L, lanes: Range<usize>) {
        let beyond = column.lt(L::splat(self.low)) | column.gt(L::splat(self.high));
        let mut entering = beyond.bits() & lane_bits(lanes);
        while entering != 0 {
            self.enter(column.lane(entering.trailing_zeros() as usize));
            entering &= entering - 1;
        }
    }

    /// [`Tails::push_lanes`] of a batch whose extremes the sketch found (`positive`, when every
    /// value is positive): a batch within the gates has no value beyond them, and costs two
    /// comparisons instead of a pass over its lanes. In a service run of the 10^7-operation
    /// scale-out job three batches in four are within.
    #[inline(always)]
    pub(crate) fn push_bounded_lanes<L: Real>(
        &mut self,
        column: &L,
        lanes: Range<usize>,
        positive: Option<PositiveExtremes>,
    ) {
        let within = |e: PositiveExtremes| self.low <= e.least && e.greatest <= self.high;
        if !positive.is_some_and(within) {
            self.push_lanes(column, lanes);
        }
    }

    /// Adds `x`, which was beyond a gate when the caller compared: it takes its place in its end
    /// and that end's gate moves to the new `keep`-th value, or it is dropped when the gates have
    /// moved past it since. A value the bottom pushes out moves to the top, where it enters while
    /// the top has room and is dropped after (it lies at or below the top's gate).
    #[inline(always)]
    fn enter(&mut self, x: f64) {
        // `-0.0 + 0.0` is `0.0`: equal values have equal bits, so what is kept is a multiset.
        let x = x + 0.0;
        let k = self.keep as usize;
        if self.values.is_empty() {
            // Room for every value kept, taken once.
            self.values.reserve_exact(2 * k);
            self.values.resize(k, f64::INFINITY);
            self.values.resize(2 * k, f64::NEG_INFINITY);
        }
        let seen = self.seen;
        let bottom_full = seen >= k;
        self.seen = (seen + 1).min(2 * k);
        let (bottom, top) = self.values.split_at_mut(k);
        // An end that is not full takes a value into its values and the padding slot next to
        // them, the rest of its padding untouched: the slots an insertion would leave as they are.
        // A small group's accumulators (a few dozen values each) are filled and never full.
        let top_from = k.saturating_sub(seen.saturating_sub(k) + 1);
        // The first `keep` values go to the bottom whatever they are: an infinity among them,
        // which no gate tells from the padding, is kept as a value (a list read from the store
        // may hold one; the engine's values are finite).
        if !bottom_full || x < self.low {
            let out = bottom[k - 1];
            enter_bottom(&mut bottom[..(seen + 1).min(k)], x);
            self.low = bottom[k - 1];
            if bottom_full && out > self.high {
                enter_top(&mut top[top_from..], out);
                self.high = top[0];
            }
        } else if x > self.high {
            enter_top(&mut top[top_from..], x);
            self.high = top[0];
        }
    }

    /// Adds the values kept by `other`: what both would have kept of all their values. With a
    /// different `keep` the smaller one holds.
    pub fn merge(&mut self, other: &Tails) {
        if other.keep < self.keep {
            // Kept again, to the smaller `keep`.
            let values = self.values();
            *self = Tails::new(other.keep);
            values.into_iter().for_each(|x| self.push(x));
        }
        // `other`'s values arrive as pushed values do: those between this list's gates are not
        // among the ends and are dropped.
        let (bottom, top) = other.kept();
        for &x in bottom.iter().chain(top) {
            self.push(x);
        }
    }

    /// The exact number of the `count` values seen beyond `threshold`, when the values kept settle
    /// it: every value is kept; or the threshold lies at or beyond the `keep`-th value of its end,
    /// so that every value beyond it is kept; or (`above` in the bottom, `below` in the top)
    /// strictly within the `keep`-th value of the other end, so that every value not beyond it is
    /// kept and the others are the rest of the `count`.
    pub fn beyond(&self, threshold: Threshold, count: u64) -> Option<u64> {
        let kept = self.values();
        let k = self.keep as usize;
        let beyond = kept.iter().filter(|&&x| threshold.beyond(x)).count() as u64;
        if kept.len() as u64 == count {
            return Some(beyond);
        }
        if kept.len() < k {
            return None;
        }
        let (kth_least, kth_greatest) = (kept[k - 1], kept[kept.len() - k]);
        match threshold {
            Threshold::Above(t) if t >= kth_greatest => Some(beyond),
            Threshold::Below(t) if t <= kth_least => Some(beyond),
            Threshold::Above(t) if t < kth_least => {
                Some(count.saturating_sub(kept.len() as u64 - beyond))
            }
            Threshold::Below(t) if t > kth_greatest => {
                Some(count.saturating_sub(kept.len() as u64 - beyond))
            }
            _ => None,
        }
    }
}

/// Slots an insertion takes at a time: one vector of the widest kernel (AVX-512's eight doubles),
/// two of AVX2. Written as a loop over the list, LLVM vectorised 32 slots at a time and ran a
/// list of 25 (the default `keep`) one slot at a time.
const SLOTS: usize = 8;

/// Puts `x`, below the greatest value of `bottom` (in increasing order), in its place, and the
/// greatest value out. Each slot takes the least of its value and the greater of `x` and the value
/// before it, which keeps the values at or below `x`, puts `x` after them and moves the others
/// up one: no branch and no count, selections between neighbours. The slots go [`SLOTS`] at a
/// time from the last, so that every slot reads the value before it as it was.
#[inline(always)]
fn enter_bottom(bottom: &mut [f64], x: f64) {
    let mut end = bottom.len();
    while end > SLOTS {
        let start = end - SLOTS;
        let before: [f64; SLOTS] = bottom[start - 1..end - 1].try_into().expect("SLOTS values");
        for (slot, before) in bottom[start..end].iter_mut().zip(before) {
            *slot = least(*slot, greatest(x, before));
        }
        end = start;
    }
    for i in (0..end).rev() {
        let before = if i == 0 {
            x
        } else {
            greatest(x, bottom[i - 1])
        };
        bottom[i] = least(bottom[i], before);
    }
}

/// [`enter_bottom`] mirrored: puts `x`, above the least value of `top` (in increasing order), in
/// its place and the least value out, each slot taking the greater of its value and the lesser
/// of `x` and the value after it, [`SLOTS`] at a time from the first.
#[inline(always)]
fn enter_top(top: &mut [f64], x: f64) {
    let k = top.len();
    let mut start = 0;
    while k - start > SLOTS {
        let end = start + SLOTS;
        let after: [f64; SLOTS] = top[start + 1..end + 1].try_into().expect("SLOTS values");
        for (slot, after) in top[start..end].iter_mut().zip(after) {
            *slot = greatest(*slot, least(x, after));
        }
        start = end;
    }
    for i in start..k {
        let after = if i + 1 == k { x } else { least(x, top[i + 1]) };
        top[i] = greatest(top[i], after);
    }
}

/// The lesser of two values that are not NaN, as a comparison and a selection (`f64::min`, with
/// its NaN rule, does not vectorise).
#[inline(always)]
fn least(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

/// The greater of two values that are not NaN.
#[inline(always)]
fn greatest(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lanes::Lanes;
    use crate::stats::test_util::SplitMix;
    use proptest::prelude::*;

    fn kept(values: &[f64], keep: u32) -> Tails {
        let mut tails = Tails::new(keep);
        values.iter().for_each(|&x| tails.push(x));
        tails
    }

    /// The bottom and top `keep` of `values`, sorted: what the list must hold.
    fn ends_of(values: &[f64], keep: u32) -> Vec<f64> {
        let mut sorted: Vec<f64> = values.iter().map(|x| x + 0.0).collect();
        sorted.sort_by(f64::total_cmp);
        let k = keep as usize;
        if sorted.len() > 2 * k {
            sorted.drain(k..sorted.len() - k);
        }
        sorted
    }

    #[test]
    fn the_budget_bounds_the_values_kept_per_bin() {
        assert_eq!(keep_for_bins(1), Some(MAX_KEEP));
        assert_eq!(keep_for_bins(4), Some(MAX_KEEP));
        assert_eq!(keep_for_bins(10), Some(25));
        assert_eq!(keep_for_bins(64), Some(MIN_KEEP));
        assert_eq!(keep_for_bins(65), None);
        assert_eq!(keep_for_bins(1000), None);
        assert_eq!(keep_for_bins(0), Some(MAX_KEEP));
        assert_eq!(keep_for_bins(u64::MAX), None);
    }

    #[test]
    fn a_rising_run_keeps_its_first_and_last_values() {
        let values: Vec<f64> = (0..1000).map(f64::from).collect();
        let tails = kept(&values, 3);
        assert_eq!(tails.values(), [0.0, 1.0, 2.0, 997.0, 998.0, 999.0]);
        assert_eq!(tails.beyond(Threshold::Above(997.5), 1000), Some(2));
        assert_eq!(tails.beyond(Threshold::Above(997.0), 1000), Some(2));
        // Inside the gap the list cannot tell.
        assert_eq!(tails.beyond(Threshold::Above(996.0), 1000), None);
        assert_eq!(tails.beyond(Threshold::Below(2.0), 1000), Some(2));
        assert_eq!(tails.beyond(Threshold::Below(2.5), 1000), None);
        // The other end settles the complement: every value not beyond is kept there.
        assert_eq!(tails.beyond(Threshold::Above(1.0), 1000), Some(998));
        assert_eq!(tails.beyond(Threshold::Above(1.5), 1000), Some(998));
        assert_eq!(
            tails.beyond(Threshold::Above(2.0), 1000),
            None,
            "ties may lie beyond"
        );
        assert_eq!(tails.beyond(Threshold::Below(998.0), 1000), Some(998));
        assert_eq!(tails.beyond(Threshold::Below(997.0), 1000), None);
    }

    #[test]
    fn infinities_among_the_first_values_are_kept_as_values() {
        let inf = f64::INFINITY;
        for values in [
            vec![inf, 1.0, -inf, 2.0],
            vec![1.0, inf, inf, -inf, 3.0, -inf, 0.5],
            vec![inf; 5],
            vec![-inf, -inf, 1.0],
        ] {
            for keep in 1..5 {
                let tails = kept(&values, keep);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&tails.values()), bits(&ends_of(&values, keep)));
            }
        }
    }

    #[test]
    fn only_a_list_as_stored_is_laid_out_at_once() {
        assert!(Tails::from_ends(2, &[1.0, 2.0, 3.0, 4.0]).is_some());
        assert!(Tails::from_ends(2, &[1.0, 2.0, 3.0, 4.0, 5.0]).is_none());
        assert!(Tails::from_ends(2, &[2.0, 1.0]).is_none());
        assert!(Tails::from_ends(2, &[1.0, f64::INFINITY]).is_none());
        assert!(Tails::from_ends(2, &[f64::NAN]).is_none());
        // The others are pushed: the ends of their values.
        let read: Tails = Stored {
            keep: 1,
            kept: vec![3.0, 1.0, 2.0],
        }
        .into();
        assert_eq!(read.values(), [1.0, 3.0]);
    }

    #[test]
    fn zeros_of_either_sign_are_one_value() {
        let a = kept(&[-0.0, 0.0, 1.0, -1.0, 0.0], 1);
        let b = kept(&[0.0, 1.0, -0.0, 0.0, -1.0], 1);
        assert_eq!(a, b);
        let zeros = kept(&[-0.0, 0.0, -0.0], 4);
        assert!(zeros.values().iter().all(|x| x.to_bits() == 0));
    }

    #[test]
    fn ten_million_values_in_lanes_keep_the_exact_extremes() {
        let mut rng = SplitMix(29);
        let mut lanes = Tails::new(MAX_KEEP);
        let mut all_high = Vec::new();
        for _ in 0..1_250_000 {
            let x = Lanes::<8>::from_fn(|_| rng.normal());
            lanes.push_lanes(&x, 0..8);
            all_high.extend((0..8).map(|k| x.lane(k)).filter(|&v| v > 3.0));
        }
        all_high.sort_by(f64::total_cmp);
        let top = &all_high[all_high.len() - MAX_KEEP as usize..];
        assert_eq!(&lanes.values()[MAX_KEEP as usize..], top);
        assert_eq!(lanes.values.capacity(), 2 * MAX_KEEP as usize);
        let t = top[0];
        assert_eq!(
            lanes.beyond(Threshold::Above(t), 10_000_000),
            Some(MAX_KEEP as u64 - 1)
        );
    }

    /// Every field of `tails`, floats by their bits.
    fn state(tails: &Tails) -> (u32, Vec<u64>, usize, u64, u64) {
        let bits = tails.values.iter().map(|x| x.to_bits()).collect();
        let (low, high) = (tails.low.to_bits(), tails.high.to_bits());
        (tails.keep, bits, tails.seen, low, high)
    }

    proptest! {
        /// A list as `Tails` stores it, laid out at once, is the list its values pushed in order
        /// leave, field by field: values, count seen and gates.
        #[test]
        fn a_stored_list_laid_out_is_the_list_pushed(
            mut values in prop::collection::vec(
                prop_oneof![-3.0..3.0f64, (-4..4i32).prop_map(f64::from), Just(-0.0), Just(0.0)],
                0..130,
            ),
            keep in 1..65u32,
        ) {
            values.truncate(2 * keep as usize);
            values.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
            let laid = Tails::from_ends(keep, &values).expect("finite, sorted, at most 2 keep");
            prop_assert_eq!(state(&laid), state(&kept(&values, keep)));
            let read: Tails = Stored { keep, kept: values.clone() }.into();
            prop_assert_eq!(state(&read), state(&laid));
        }

        /// A list writes what its values gathered into [`Stored`] write, byte for byte, in the
        /// store's binary format and in JSON: empty, filling, full and beyond.
        #[test]
        fn a_list_is_written_as_its_values_gathered(
            values in prop::collection::vec(-3.0..3.0f64, 0..130),
            keep in 1..65u32,
        ) {
            let tails = kept(&values, keep);
            let gathered = Stored { keep, kept: tails.values() };
            prop_assert_eq!(
                postcard::to_stdvec(&tails).unwrap(),
                postcard::to_stdvec(&gathered).unwrap()
            );
            prop_assert_eq!(
                serde_json::to_string(&tails).unwrap(),
                serde_json::to_string(&gathered).unwrap()
            );
        }

        /// However the values arrive (one by one, in lanes, split and merged, serialised), the list
        /// is the bottom and top `keep` of them, and it counts exactly every threshold it settles.
        #[test]
        fn the_list_is_the_ends_of_the_values_however_they_arrive(
            values in prop::collection::vec(
                prop_oneof![-3.0..3.0f64, (-4..4i32).prop_map(f64::from), Just(-0.0)],
                0..400,
            ),
            keep in 1..12u32,
            cut in 0..400usize,
            at in -3.5..3.5f64,
        ) {
            let expected = ends_of(&values, keep);
            let pushed = kept(&values, keep);
            let mut lanes = Tails::new(keep);
            for chunk in values.chunks(4) {
                let x = Lanes::<4>::from_fn(|k| chunk.get(k).copied().unwrap_or(f64::NAN));
                lanes.push_lanes(&x, 0..chunk.len());
            }
            let (a, b) = values.split_at(cut.min(values.len()));
            let mut merged = kept(a, keep);
            merged.merge(&kept(b, keep));
            // In many pieces, as a summary merges its groups, some keeping more at each end.
            let mut pieces = Tails::new(keep);
            for (i, piece) in values.chunks(cut % 37 + 1).enumerate() {
                pieces.merge(&kept(piece, keep + (i % 3) as u32));
            }
            let text = serde_json::to_string(&merged).unwrap();
            let restored: Tails = serde_json::from_str(&text).unwrap();
            let n = values.len() as u64;
            for tails in [&pushed, &lanes, &merged, &restored, &pieces] {
                prop_assert_eq!(
                    tails.values().iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    expected.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
                );
                for threshold in [Threshold::Above(at), Threshold::Below(at)] {
                    if let Some(count) = tails.beyond(threshold, n) {
                        let truth = values.iter().filter(|&&x| threshold.beyond(x)).count();
                        prop_assert_eq!(count, truth as u64);
                    }
                }
            }
        }

        /// A batch the sketch found positive and within the gates by its extremes is skipped,
        /// others pushed: the list is what pushing every value makes, with values close to the
        /// gates, equal to them (whole numbers) and drifting through them.
        #[test]
        fn batches_skipped_by_their_extremes_keep_the_same_ends(
            noise in prop::collection::vec(
                prop_oneof![
                    16 => 1.0..1.04f64,
                    4 => (1..6u8).prop_map(f64::from),
                    1 => Just(0.0),
                    1 => -1.0..1.0f64,
                ],
                0..700,
            ),
            drift in prop_oneof![Just(0.0), -1e-3..1e-3f64],
            keep in 1..30u32,
            positive in any::<bool>(),
        ) {
            let values: Vec<f64> = noise
                .iter()
                .filter(|&&x| !positive || x > 0.0)
                .enumerate()
                .map(|(i, x)| x * (1.0 + drift * i as f64))
                .collect();
            let mut sketch = crate::stats::Sketch::new();
            let mut bounded = Tails::new(keep);
            for chunk in values.chunks(8) {
                let x = Lanes::<8>::from_fn(|k| chunk[k.min(chunk.len() - 1)]);
                let positive = sketch.push_filled_lanes(&x, 0..chunk.len());
                bounded.push_bounded_lanes(&x, 0..chunk.len(), positive);
            }
            prop_assert_eq!(bounded, kept(&values, keep));
        }

        /// Values that drift (every new one beyond a gate, on one side or, with noise, both)
        /// keep their ends through full lists, stored and restored, and merged, also
        /// into a list keeping more at each end: each new value is inserted at its end, whatever
        /// the list's length against the slots an insertion takes at a time.
        #[test]
        fn drifting_values_keep_their_ends_through_full_lists(
            noise in prop::collection::vec(-1.0..1.0f64, 0..600),
            drift in prop_oneof![Just(0.0), -0.1..0.1f64],
            // Lists shorter than an insertion's slots at a time, and longer, up to the most kept.
            keep in prop_oneof![1..12u32, 12..=MAX_KEEP],
            cut in 0..600usize,
        ) {
            let values: Vec<f64> =
                noise.iter().enumerate().map(|(i, x)| x + drift * i as f64).collect();
            let (a, b) = values.split_at(cut.min(values.len()));
            let text = serde_json::to_string(&kept(a, keep)).unwrap();
            let mut restored: Tails = serde_json::from_str(&text).unwrap();
            b.iter().for_each(|&x| restored.push(x));
            let mut merged = kept(a, keep);
            let mut narrowed = kept(a, keep + 2);
            narrowed.merge(&Tails::new(keep));
            for (i, piece) in b.chunks(cut % 23 + 1).enumerate() {
                merged.merge(&kept(piece, keep + (i % 2) as u32));
                narrowed.merge(&kept(piece, keep));
            }
            let expected: Vec<u64> = ends_of(&values, keep).iter().map(|x| x.to_bits()).collect();
            for tails in [&restored, &merged, &narrowed] {
                let got: Vec<u64> = tails.values().iter().map(|x| x.to_bits()).collect();
                prop_assert_eq!(&got, &expected);
            }
        }
    }
}
