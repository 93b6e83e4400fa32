//! A log-linear bucket histogram of f64 values, indexed by the IEEE-754 bit pattern.
//!
//! For `|x| > 0` the bucket key is the biased exponent followed by the top [`SUB_BITS`] mantissa
//! bits, `key = (|x|.to_bits() >> (52 - SUB_BITS))`: a shift, no logarithm, no division. Each
//! binade `[2^e, 2^(e+1))` is split into `2^SUB_BITS = 256` buckets of equal width `2^(e-8)`, so a
//! bucket `[lo, lo + w)` has `w / lo <= 2^-8` and its midpoint `lo + w/2` (the bit pattern of `lo`
//! with the next mantissa bit set) is within `2^-9 = 0.195 %` of every value in it. Keys increase
//! with `|x|`, so the buckets are ordered like the values (this is HdrHistogram's log-linear layout,
//! and DDSketch's relative-error guarantee, read straight off the bits). Subnormal values (below
//! `2.2e-308`) fall into linear buckets of absolute width `2^-1030` and lose the relative bound.
//!
//! Exact zeros (`0.0` and `-0.0`) have their own count, so a quantile that falls on them is exactly
//! 0; negative values use a second, mirrored store keyed by `|x|`.
//!
//! Memory: each store is a dense array of counts over the keys between the smallest and largest
//! seen, plus growth slack of at most a quarter of its length, in the narrowest integer the
//! sketch's count allows (`u16` below 65,536 values, then `u32`, then `u64`, so no job overflows
//! them): 2 bytes x 256 buckets per binade spanned, e.g. 10 kB (x 1.25) for values spanning 6
//! decades (20 binades) while a sketch holds fewer than 65,536 values, whatever the values, and at
//! most 4 MiB per store for the whole f64 range. Where that range is wider than 16 binades and
//! than 16 keys per value of the sketch (a few values over many decades), the store keeps its
//! non-empty buckets only, in a B-tree: about 16 to 24 bytes a bucket, so memory follows the
//! values. Serialised, every count is a `u64`, from the first non-empty bucket to the last,
//! whatever the form in memory.

use crate::lanes::{MAX_LANES, Real, fill_lanes, within_lanes};
use std::collections::BTreeMap;
use std::ops::Range;

/// Mantissa bits in the bucket key: 256 buckets per binade, relative bucket width `2^-8`.
pub const SUB_BITS: u32 = 8;

/// Shift from a bit pattern to its bucket key.
const KEY_SHIFT: u32 = 52 - SUB_BITS;

/// One past the largest key of a non-negative bit pattern (sign bit clear: 63 bits).
const KEY_END: u32 = 1 << (63 - KEY_SHIFT);

/// The smallest growth of a store, so that the first few pushes do not each reallocate.
const MIN_SLACK: u32 = 32;

const SIGN_MASK: u64 = 1 << 63;

/// Bucket key of `|x|`.
#[inline]
fn key(x: f64) -> u32 {
    // At most 19 significant bits remain after the shift, so the cast is lossless.
    ((x.to_bits() & !SIGN_MASK) >> KEY_SHIFT) as u32
}

/// The least and greatest value of a batch of positive values, which
/// [`Sketch::push_filled_lanes`] finds on its way (a positive value's bits, read as an integer,
/// order as the values do): what a test of every value against two bounds needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PositiveExtremes {
    pub(crate) least: f64,
    pub(crate) greatest: f64,
}

/// Midpoint of the bucket `key`: its lower bound with the next mantissa bit set, which is exactly
/// `lo + w/2` because the mantissa is linear within a binade.
fn midpoint(key: u32) -> f64 {
    f64::from_bits((u64::from(key) << KEY_SHIFT) | (1 << (KEY_SHIFT - 1)))
}

/// The rank (1-based) of quantile level `q` among `n` sorted values: `k = ceil(q n)`, clamped to
/// `[1, n]` (the "inverted CDF", numpy's `method="inverted_cdf"`, Hyndman & Fan type 1). `q = 0`
/// is the minimum, `q = 1` the maximum, `q = 0.5` with even `n` the lower median. The product
/// `q n` is computed in f64, so a product within 4 ulps of an integer counts as that integer
/// (`0.1 x 30` is rank 3, not 4). Returns 0 when `n = 0`.
pub fn rank(q: f64, n: u64) -> u64 {
    if n == 0 {
        return 0;
    }
    let x = q * n as f64;
    let nearest = x.round();
    let k = if (x - nearest).abs() <= 4.0 * f64::EPSILON * nearest {
        nearest
    } else {
        x.ceil()
    };
    // The float-to-int cast saturates (and maps NaN to 0); the clamp does the rest.
    (k as u64).clamp(1, n)
}

/// An unsigned integer a store counts in.
trait Count: Copy + Default + Into<u64> + TryFrom<u64> + std::ops::AddAssign {
    fn wide(self) -> u64 {
        self.into()
    }

    /// `n`, which the caller has checked fits.
    fn of(n: u64) -> Self {
        Self::try_from(n).unwrap_or_else(|_| unreachable!("{n} counted in a store too narrow"))
    }
}

impl Count for u16 {}
impl Count for u32 {}
impl Count for u64 {}

/// A store's counts in the narrowest integer that holds every count it may reach: no bucket
/// holds more than its sketch's count, so two bytes a bucket while a sketch holds fewer than
/// 65,536 values (a group's bin in most jobs), four, then eight. The memory a job touches for its
/// sketches is a quarter of what eight bytes would take.
#[derive(Debug, Clone)]
enum Counts {
    U16(Vec<u16>),
    U32(Vec<u32>),
    U64(Vec<u64>),
}

impl Default for Counts {
    fn default() -> Self {
        Counts::U16(Vec::new())
    }
}

/// Runs `$body` with `$c` bound to the counts, whatever their width.
macro_rules! with_counts {
    ($counts:expr, $c:ident => $body:expr) => {
        match $counts {
            Counts::U16($c) => $body,
            Counts::U32($c) => $body,
            Counts::U64($c) => $body,
        }
    };
}

/// Counts `[offset, offset + old.len())` moved into `new_lo .. new_hi` of a new vector.
fn regrown<T: Count>(old: &[T], offset: u32, new_lo: u32, new_hi: u32) -> Vec<T> {
    let mut counts = vec![T::default(); (new_hi - new_lo) as usize];
    let start = (offset - new_lo) as usize;
    counts[start..start + old.len()].copy_from_slice(old);
    counts
}

/// Adds `n` to `count` (which the caller has made wide enough).
#[inline(always)]
fn add<T: Count>(count: &mut T, n: u64) {
    *count += T::of(n);
}

/// Counts converted to a wider (or equal) integer.
fn widened<T: Count, U: Count>(counts: &[T]) -> Vec<U> {
    counts.iter().map(|&c| U::of(c.wide())).collect()
}

/// A dense store spans up to this many keys whatever it holds: 8 KiB of two-byte counts, 16
/// binades (4.8 decades).
const DENSE_UP_TO: u32 = 4096;

/// Beyond [`DENSE_UP_TO`], a store whose dense range would span more than this many keys per value
/// of its sketch keeps only its non-empty buckets ([`Store::Sparse`]), and it spans a dense range
/// again once that range holds at most half as many keys per non-empty bucket: a sparse bucket
/// takes about 16 to 24 bytes (a B-tree's key, count and share of its node), a dense one 2 to 8.
const KEYS_PER_VALUE: u64 = 16;

/// Whether a dense range of `len` keys is too wide for `values` values.
fn too_wide(len: u32, values: u64) -> bool {
    len > DENSE_UP_TO && u64::from(len) > KEYS_PER_VALUE.saturating_mul(values)
}

/// The counts of the keys of a sketch's values of one sign. Dense: an array over the keys between
/// the least and the greatest, an increment a value (the engine's hottest loop). Sparse: the
/// non-empty buckets only, for values few and spread over many decades, so that memory follows the
/// values rather than their range (velocities drawn over 32 decades, one operation a bin: 2.5 GB
/// of dense counts for 512 devices). Every mutating call is given `total`, an upper bound on any
/// count after it (the sketch's count). Which form a store takes changes no count, no answer and
/// no serialised byte.
#[derive(Debug, Clone)]
enum Store {
    Dense(Dense),
    Sparse(BTreeMap<u32, u64>),
}

impl Default for Store {
    fn default() -> Self {
        Store::Dense(Dense::default())
    }
}

/// Equal counts in every bucket, however each store grew: the range a store holds, and its form,
/// depend on the order its values came in.
impl PartialEq for Store {
    fn eq(&self, other: &Store) -> bool {
        self.buckets().eq(other.buckets())
    }
}

/// As `{offset, counts}` from the first non-empty bucket to the last, every count a u64: the same
/// bytes for the same counts, however the store grew, whatever its form and the width in memory (a
/// group's state is stored and sent between machines).
impl serde::Serialize for Store {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{SerializeSeq, SerializeStruct};
        struct Wide<'a>(&'a Store, u32, u32);
        impl serde::Serialize for Wide<'_> {
            fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                let Wide(store, lo, end) = *self;
                let mut seq = serializer.serialize_seq(Some((end - lo) as usize))?;
                let mut next = lo;
                for (key, count) in store.buckets() {
                    for _ in next..key {
                        seq.serialize_element(&0u64)?;
                    }
                    seq.serialize_element(&count)?;
                    next = key + 1;
                }
                seq.end()
            }
        }
        let (lo, end) = self.occupied().map_or((0, 0), |(lo, hi)| (lo, hi + 1));
        let mut state = serializer.serialize_struct("Store", 2)?;
        state.serialize_field("offset", &lo)?;
        state.serialize_field("counts", &Wide(self, lo, end))?;
        state.end()
    }
}

impl<'de> serde::Deserialize<'de> for Store {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        #[derive(serde::Deserialize)]
        #[serde(rename = "Store")]
        struct Wide {
            offset: u32,
            counts: Vec<u64>,
        }
        let Wide { offset, counts } = Wide::deserialize(deserializer)?;
        let end = u64::from(offset) + counts.len() as u64;
        if end > u64::from(KEY_END) {
            return Err(serde::de::Error::custom(format!(
                "a store's keys end at {end}, beyond {KEY_END}"
            )));
        }
        let wide = counts.len() > DENSE_UP_TO as usize;
        let mut store = Store::Dense(Dense {
            offset,
            counts: Counts::U64(counts),
        });
        // Only a range wider than any dense store spans whatever it holds may turn sparse: the
        // common store is read in one pass, as before there was a sparse form.
        if wide {
            let values = store
                .buckets()
                .fold(0u64, |sum, (_, count)| sum.saturating_add(count));
            store.settle(values);
        }
        if let Store::Dense(dense) = &mut store {
            dense.narrow();
        }
        Ok(store)
    }
}

impl Store {
    #[cfg(test)]
    fn len(&self) -> usize {
        match self {
            Store::Dense(dense) => dense.len(),
            Store::Sparse(buckets) => buckets.len(),
        }
    }

    #[cfg(test)]
    fn is_sparse(&self) -> bool {
        matches!(self, Store::Sparse(_))
    }

    /// Counts one value of key `key`.
    #[inline]
    fn add(&mut self, key: u32, total: u64) {
        if let Store::Dense(dense) = self {
            dense.fit(total);
            if dense.add_within(key) {
                return;
            }
        }
        self.add_outside(key, total);
    }

    #[cold]
    #[inline(never)]
    fn add_outside(&mut self, key: u32, total: u64) {
        // SAFETY: the one key lies in `key ..= key`.
        unsafe { self.add_beyond(key, key, &[key], total) }
    }

    /// Counts values of the keys `keys`: one addition when they share one key.
    ///
    /// # Safety
    ///
    /// Every key lies in `lo ..= hi`: a dense store's increments are not bounds-checked (the check
    /// was two of the loop's eight instructions, and the loop a tenth of the kernel's samples).
    #[inline(always)]
    unsafe fn add_all(&mut self, lo: u32, hi: u32, keys: &[u32], total: u64) {
        if let Store::Dense(dense) = self {
            dense.fit(total);
            if dense.covers(lo, hi + 1) {
                // SAFETY: the caller's promise, and the dense range holds `lo ..= hi`.
                unsafe { dense.add_all(lo, hi, keys) };
                return;
            }
        }
        // SAFETY: the caller's promise.
        unsafe { self.add_beyond(lo, hi, keys, total) }
    }

    /// [`Store::add_all`] where a dense store's range does not hold the keys, or the store is
    /// sparse: the range grows, or the store turns sparse (or dense again).
    ///
    /// # Safety
    ///
    /// As [`Store::add_all`].
    #[cold]
    #[inline(never)]
    unsafe fn add_beyond(&mut self, lo: u32, hi: u32, keys: &[u32], total: u64) {
        self.make_room(lo, hi + 1, total);
        match self {
            Store::Dense(dense) => {
                dense.fit(total);
                // SAFETY: the caller's promise, and the dense range now holds `lo ..= hi`.
                unsafe { dense.add_all(lo, hi, keys) }
            }
            Store::Sparse(buckets) => {
                for &key in keys {
                    *buckets.entry(key).or_default() += 1;
                }
                self.settle(total);
            }
        }
    }

    /// Makes a dense store's range include the keys `lo .. hi`, or turns it sparse where that
    /// range would be too wide for the `total` values of its sketch.
    fn make_room(&mut self, lo: u32, hi: u32, total: u64) {
        if let Store::Dense(dense) = self
            && !dense.covers(lo, hi)
        {
            let (new_lo, new_hi) = dense.grown(lo, hi);
            if too_wide(new_hi - new_lo, total) {
                *self = Store::Sparse(dense.buckets().collect());
            } else {
                dense.regrow(new_lo, new_hi);
            }
        }
    }

    /// A sparse store whose range is no longer wide for its non-empty buckets spans a dense range
    /// again (counts narrow enough for `total`); a dense one too wide for `total` turns sparse.
    fn settle(&mut self, total: u64) {
        let Some((lo, hi)) = self.occupied() else {
            return;
        };
        let span = hi - lo + 1;
        match self {
            Store::Sparse(buckets) if !too_wide(span, buckets.len() as u64 / 2) => {
                let mut dense = Dense::default();
                dense.fit(total);
                dense.regrow(lo, hi + 1);
                buckets
                    .iter()
                    .for_each(|(&key, &count)| dense.add_n(key, count));
                *self = Store::Dense(dense);
            }
            Store::Dense(dense) if too_wide(span, total) => {
                *self = Store::Sparse(dense.buckets().collect());
            }
            _ => {}
        }
    }

    fn merge(&mut self, other: &Store, total: u64) {
        let Some((lo, hi)) = other.occupied() else {
            return;
        };
        self.make_room(lo, hi + 1, total);
        match (&mut *self, other) {
            (Store::Dense(mine), Store::Dense(theirs)) => {
                mine.fit(total);
                mine.merge_covered(theirs, lo, hi);
            }
            (Store::Dense(mine), Store::Sparse(theirs)) => {
                mine.fit(total);
                theirs
                    .iter()
                    .for_each(|(&key, &count)| mine.add_n(key, count));
            }
            (Store::Sparse(mine), _) => {
                for (key, count) in other.buckets() {
                    *mine.entry(key).or_default() += count;
                }
                self.settle(total);
            }
        }
    }

    /// The keys of the first and the last non-empty bucket; `None` when every count is zero.
    fn occupied(&self) -> Option<(u32, u32)> {
        match self {
            Store::Dense(dense) => dense.occupied(),
            Store::Sparse(buckets) => {
                Some((*buckets.first_key_value()?.0, *buckets.last_key_value()?.0))
            }
        }
    }

    /// The sum of the counts of the keys `keys`.
    fn sum_keys(&self, keys: std::ops::Range<u32>) -> u64 {
        match self {
            Store::Dense(dense) => dense.sum_keys(keys),
            Store::Sparse(_) if keys.is_empty() => 0,
            Store::Sparse(buckets) => buckets.range(keys).map(|(_, &count)| count).sum(),
        }
    }

    /// The running totals of the counts, for sums of many ranges.
    fn cumulative(&self) -> Cumulative {
        match self {
            Store::Dense(dense) => dense.cumulative(),
            Store::Sparse(buckets) => {
                let mut total = 0;
                let below = std::iter::once(0)
                    .chain(buckets.values().map(|&count| {
                        total += count;
                        total
                    }))
                    .collect();
                Cumulative::Sparse {
                    keys: buckets.keys().copied().collect(),
                    below,
                }
            }
        }
    }

    /// Non-empty buckets as `(key, count)`, by increasing key.
    fn buckets(&self) -> impl DoubleEndedIterator<Item = (u32, u64)> + '_ {
        let (dense, sparse) = match self {
            Store::Dense(dense) => (Some(dense.buckets()), None),
            Store::Sparse(buckets) => (None, Some(buckets.iter().map(|(&k, &c)| (k, c)))),
        };
        dense
            .into_iter()
            .flatten()
            .chain(sparse.into_iter().flatten())
    }
}

/// Dense counts for the keys `offset .. offset + len`, in the narrowest integer that holds the
/// total each mutating caller states ([`Dense::fit`]).
#[derive(Debug, Clone, Default)]
struct Dense {
    offset: u32,
    counts: Counts,
}

impl Dense {
    fn len(&self) -> usize {
        with_counts!(&self.counts, c => c.len())
    }

    /// The count of slot `i` (key `offset + i`).
    #[inline]
    fn get(&self, i: usize) -> u64 {
        with_counts!(&self.counts, c => c[i].wide())
    }

    /// The most any count can reach in the current width.
    #[inline(always)]
    fn room(&self) -> u64 {
        match self.counts {
            Counts::U16(_) => u16::MAX.into(),
            Counts::U32(_) => u32::MAX.into(),
            Counts::U64(_) => u64::MAX,
        }
    }

    /// Widens the counts if `total` might not fit.
    #[inline(always)]
    fn fit(&mut self, total: u64) {
        if total > self.room() {
            self.widen(total);
        }
    }

    #[cold]
    #[inline(never)]
    fn widen(&mut self, total: u64) {
        self.counts = match &self.counts {
            Counts::U16(c) if total <= u32::MAX.into() => Counts::U32(widened(c)),
            Counts::U16(c) => Counts::U64(widened(c)),
            Counts::U32(c) => Counts::U64(widened(c)),
            Counts::U64(_) => return,
        };
    }

    /// The narrowest width that holds the largest count (after deserialising).
    fn narrow(&mut self) {
        let largest =
            with_counts!(&self.counts, c => c.iter().map(|&x| x.wide()).max().unwrap_or(0));
        self.counts = match &self.counts {
            Counts::U64(c) if largest <= u16::MAX.into() => {
                Counts::U16(c.iter().map(|&x| u16::of(x)).collect())
            }
            Counts::U64(c) if largest <= u32::MAX.into() => {
                Counts::U32(c.iter().map(|&x| u32::of(x)).collect())
            }
            _ => return,
        };
    }

    /// Counts one value of key `key` if the range holds it (the counts wide enough already).
    #[inline]
    fn add_within(&mut self, key: u32) -> bool {
        // Keys below `offset` wrap to huge indices, so one bounds check covers both sides.
        let i = key.wrapping_sub(self.offset) as usize;
        with_counts!(&mut self.counts, c => match c.get_mut(i) {
            Some(count) => {
                *count += 1;
                true
            }
            None => false,
        })
    }

    /// Adds `n` to the count of `key`, which the range holds (the counts wide enough already).
    fn add_n(&mut self, key: u32, n: u64) {
        let i = (key - self.offset) as usize;
        with_counts!(&mut self.counts, c => add(&mut c[i], n));
    }

    /// Counts values of the keys `keys`: one addition when they share one key.
    ///
    /// # Safety
    ///
    /// Every key lies in `lo ..= hi`, which the range holds (the counts wide enough already).
    #[inline(always)]
    unsafe fn add_all(&mut self, lo: u32, hi: u32, keys: &[u32]) {
        let offset = self.offset;
        with_counts!(&mut self.counts, c => {
            if lo == hi {
                add(&mut c[(lo - offset) as usize], keys.len() as u64);
            } else {
                // The keys' own span, a slice held in registers: indexing `c` itself reloaded the
                // vector's pointer and length after every increment, which might have changed them.
                let span = &mut c[(lo - offset) as usize..=(hi - offset) as usize];
                for &key in keys {
                    debug_assert!((lo..=hi).contains(&key), "key {key} beyond {lo} ..= {hi}");
                    // SAFETY: `lo <= key <= hi` (the caller's promise), so the index is below
                    // `span.len() = hi - lo + 1`.
                    unsafe { *span.get_unchecked_mut((key - lo) as usize) += 1 };
                }
            }
        });
    }

    /// Whether the range holds the keys `lo .. hi`.
    #[inline(always)]
    fn covers(&self, lo: u32, hi: u32) -> bool {
        let len = self.len();
        len != 0 && lo >= self.offset && hi <= self.offset + len as u32
    }

    /// The range that holds the keys `lo .. hi` besides those it holds: widened by at least a
    /// quarter of its length on the growing side, so that a long run of new extremes reallocates
    /// only `O(log(range))` times.
    fn grown(&self, lo: u32, hi: u32) -> (u32, u32) {
        let len = self.len() as u32;
        if len == 0 {
            return (
                lo.saturating_sub(MIN_SLACK / 2),
                (hi + MIN_SLACK / 2).min(KEY_END),
            );
        }
        let (old_lo, old_hi) = (self.offset, self.offset + len);
        let slack = (len / 4).max(MIN_SLACK);
        (
            if lo < old_lo {
                lo.saturating_sub(slack)
            } else {
                old_lo
            },
            if hi > old_hi {
                (hi + slack).min(KEY_END)
            } else {
                old_hi
            },
        )
    }

    /// Moves the counts into the range `new_lo .. new_hi`, which holds the present one.
    fn regrow(&mut self, new_lo: u32, new_hi: u32) {
        let offset = if self.len() == 0 { new_lo } else { self.offset };
        with_counts!(&mut self.counts, c => *c = regrown(c, offset, new_lo, new_hi));
        self.offset = new_lo;
    }

    /// Adds the counts of `other`'s keys `lo ..= hi`, which both ranges hold.
    fn merge_covered(&mut self, other: &Dense, lo: u32, hi: u32) {
        let span = (hi - lo) as usize;
        let (start, first) = ((lo - self.offset) as usize, (lo - other.offset) as usize);
        with_counts!(&other.counts, theirs => with_counts!(&mut self.counts, mine => {
            let theirs = &theirs[first..=first + span];
            for (mine, theirs) in mine[start..=start + span].iter_mut().zip(theirs) {
                add(mine, theirs.wide());
            }
        }));
    }

    /// The keys of the first and the last non-empty bucket; `None` when every count is zero.
    fn occupied(&self) -> Option<(u32, u32)> {
        with_counts!(&self.counts, c => {
            let first = c.iter().position(|&x| x.wide() != 0)?;
            let last = c.iter().rposition(|&x| x.wide() != 0)?;
            Some((self.offset + first as u32, self.offset + last as u32))
        })
    }

    /// The sum of the counts of the keys `keys` (those the range holds).
    fn sum_keys(&self, keys: std::ops::Range<u32>) -> u64 {
        let slots = slots(self.offset, self.len(), keys);
        with_counts!(&self.counts, c => c[slots].iter().map(|&x| x.wide()).sum())
    }

    /// The running totals of the counts, for sums of many ranges.
    fn cumulative(&self) -> Cumulative {
        let mut below = Vec::with_capacity(self.len() + 1);
        below.push(0);
        let mut total = 0;
        with_counts!(&self.counts, c => below.extend(c.iter().map(|&x| {
            total += x.wide();
            total
        })));
        Cumulative::Dense {
            offset: self.offset,
            below,
        }
    }

    /// Non-empty buckets as `(key, count)`, by increasing key.
    fn buckets(&self) -> impl DoubleEndedIterator<Item = (u32, u64)> + '_ {
        (0..self.len()).filter_map(move |i| {
            let count = self.get(i);
            (count != 0).then_some((self.offset + i as u32, count))
        })
    }
}

/// A quantile read off a sketch's counts ([`Sketch::interpolated`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interpolated {
    /// With each bucket's values spread evenly over its width.
    pub value: f64,
    /// Where in its bucket the exact quantile may lie, allowing for the density's slope.
    pub range: [f64; 2],
}

impl Interpolated {
    fn at(value: f64) -> Self {
        Self {
            value,
            range: [value, value],
        }
    }
}

/// How far the logarithm of the density may bend across three adjacent buckets for a quantile
/// to be read within the middle one to first order ([`Span::slope`]): a normal's bends by
/// `(w / sd)^2`, and its quantiles hold in the first-order range up to `w / sd = 0.7`.
const BENT: f64 = 0.5;

/// A non-empty bucket in value order: its lower and upper edge (equal for exact zeros) and count.
#[derive(Debug, Clone, Copy)]
struct Span(f64, f64, u64);

impl Span {
    fn density(self) -> f64 {
        self.2 as f64 / (self.1 - self.0)
    }

    /// `|rho|`, the share by which the density changes across this bucket, from the densities
    /// of the adjacent buckets `previous` and `next` (0 for either that is absent, not adjacent,
    /// or exact zeros); 0 for exact zeros, a point. With the density linear across the bucket, a
    /// quantile read with the values spread evenly, at the share `s` of them below it, is off by
    /// `w |rho| s (1 - s) / 2` to first order.
    ///
    /// `None` where that reading does not hold, and the values may lie anywhere in the bucket:
    /// where the logarithm of the density bends by more than [`BENT`] from one neighbour to the
    /// other (`|ln above - 2 ln here + ln below|`; an absent neighbour bends it without bound). A
    /// normal's bends by `(w / sd)^2` wherever it is read; with `w / sd` from 0.1 to 0.7 the
    /// exact quantile lies in the first-order range at every level and every offset of the
    /// buckets, from 0.85 on it does not at 8-86 % of them (`tools/sketch_reading.py`). A normal with `sd` 0.2 to 0.5 of a bucket spans a few buckets: its
    /// quantiles' exact values lay beyond that range in every one of 100 jobs (an outside check).
    fn slope(self, previous: Option<Span>, next: Option<Span>) -> Option<f64> {
        if self.1 <= self.0 {
            return Some(0.0);
        }
        let adjacent = |span: Option<Span>, edge: f64, at: fn(Span) -> f64| {
            span.filter(|s| at(*s) == edge && s.1 > s.0)
                .map_or(0.0, Span::density)
        };
        let (below, here, above) = (
            adjacent(previous, self.0, |s| s.1),
            self.density(),
            adjacent(next, self.1, |s| s.0),
        );
        let bend = (above.ln() - 2.0 * here.ln() + below.ln()).abs();
        (bend <= BENT).then(|| ((above - below) / (2.0 * here)).abs())
    }
}

/// The slots of a store of `len` slots from key `offset` that hold the keys `keys`.
fn slots(offset: u32, len: usize, keys: std::ops::Range<u32>) -> std::ops::Range<usize> {
    let end = offset + len as u32;
    let (lo, hi) = (keys.start.clamp(offset, end), keys.end.clamp(offset, end));
    (lo - offset) as usize..(hi.max(lo) - offset) as usize
}

/// A store's running totals ([`Store::cumulative`]): the sum of the counts of any keys in two
/// reads, where [`Store::sum_keys`] adds up each slot.
enum Cumulative {
    /// Over a dense range from key `offset`: the sum of the counts of the slots before each slot,
    /// and of all of them last.
    Dense { offset: u32, below: Vec<u64> },
    /// Over the non-empty buckets `keys`: the sum of the counts before each, and of all last.
    Sparse { keys: Vec<u32>, below: Vec<u64> },
}

impl Cumulative {
    /// The sum of the counts of the keys `keys`, as [`Store::sum_keys`] gives it.
    fn sum_keys(&self, keys: std::ops::Range<u32>) -> u64 {
        let (slots, below) = match self {
            Cumulative::Dense { offset, below } => (slots(*offset, below.len() - 1, keys), below),
            Cumulative::Sparse { keys: held, below } => {
                let at = |key: u32| held.partition_point(|&k| k < key);
                (at(keys.start)..at(keys.end).max(at(keys.start)), below)
            }
        };
        below[slots.end] - below[slots.start]
    }
}

/// The counts of a sketch around a value `t` ([`Sketch::around`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Around {
    /// Values in buckets wholly below `t`.
    pub below: u64,
    /// Values in the bucket that holds `t`.
    pub within: u64,
    /// Values in buckets wholly above `t`.
    pub above: u64,
    /// The value range `[lo, hi]` of the bucket that holds `t` (`[0, 0]` for `t = 0`).
    pub bucket: [f64; 2],
}

/// Bucket counts of f64 values with `2^-9` relative resolution; see the module documentation.
///
/// Values must be finite (checked in debug builds); a NaN counts as a zero and an infinity lands in
/// a bucket whose midpoint is not a number.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sketch {
    count: u64,
    zeros: u64,
    positive: Store,
    negative: Store,
}

impl Sketch {
    pub fn new() -> Self {
        Self::default()
    }

    /// Counts `x` in its bucket: a compare, a shift and an increment (a reallocation when `x` is a
    /// new extreme beyond the growth slack).
    #[inline]
    pub fn push(&mut self, x: f64) {
        // A value beyond f64 (a scenario whose magnitudes combine past it) has its bucket too, the
        // last (a NaN counts as zero); the run refuses such a Result (`montecarlo::check_in_range`).
        self.count += 1;
        if x > 0.0 {
            self.positive.add(key(x), self.count);
        } else if x < 0.0 {
            self.negative.add(key(x), self.count);
        } else {
            self.zeros += 1;
        }
    }

    /// [`Sketch::push`] on the lanes `lanes` of `x`. One pass over the lanes' bits gives every
    /// key, whether every lane is zero, whether every lane is positive and then the least and
    /// greatest value and key, by integer minima and maxima in vector registers (lanes outside
    /// `lanes` first take the value of its first). When every value is positive (the common
    /// case) the keys' range is covered once and the lanes are counted without the sign test and
    /// with the store already in place: an increment each. Lanes that all share one bucket (a
    /// whole-number metric, a constant) or are all zero are one addition: increments of one
    /// bucket in a row would each wait for the one before. Lanes of either sign, or a zero among
    /// others, go one by one.
    #[inline(always)]
    pub fn push_lanes<L: Real>(&mut self, x: &L, lanes: Range<usize>) {
        let within = within_lanes::<L>(&lanes);
        self.push_filled_lanes(&fill_lanes(x, &lanes, within), lanes);
    }

    /// [`Sketch::push_lanes`] on `x` whose lanes outside `lanes` hold values of lanes within
    /// ([`fill_lanes`]): a batch's extremes are then those of `lanes`. When every value is
    /// positive, their least and greatest.
    #[inline(always)]
    pub(crate) fn push_filled_lanes<L: Real>(
        &mut self,
        x: &L,
        lanes: Range<usize>,
    ) -> Option<PositiveExtremes> {
        debug_assert!(lanes.end <= L::LANES, "{lanes:?} of {} lanes", L::LANES);
        // Values beyond f64 are counted as [`Sketch::push`] counts them.
        if lanes.is_empty() {
            return None;
        }
        // Integer minima and maxima, which LLVM folds in vector registers: a float `min`, with
        // its NaN rule, it left one scalar instruction a lane (7 % of the 32-lane kernel's samples
        // at 48 V / 15 A went to a fold of the values by comparisons before the keys).
        debug_assert!(L::LANES <= MAX_LANES, "{} lanes", L::LANES);
        let mut keys = [0; MAX_LANES];
        let (mut least_bits, mut greatest_bits, mut magnitudes) = (i64::MAX, i64::MIN, 0);
        for (i, slot) in keys.iter_mut().enumerate().take(L::LANES) {
            let bits = x.lane(i).to_bits();
            *slot = key(x.lane(i));
            // A set sign bit reads as a negative integer, +0 as 0.
            least_bits = least_bits.min(bits as i64);
            greatest_bits = greatest_bits.max(bits as i64);
            magnitudes |= bits & !SIGN_MASK;
        }
        let n = lanes.len() as u64;
        if magnitudes == 0 {
            self.count += n;
            self.zeros += n;
            None
        } else if least_bits <= 0 {
            lanes.for_each(|k| self.push(x.lane(k)));
            None
        } else {
            // Every value positive: the extreme bits are the extreme values, their keys the
            // extreme keys.
            let least = f64::from_bits(least_bits as u64);
            let greatest = f64::from_bits(greatest_bits as u64);
            self.count += n;
            // SAFETY: every lane's bits lie between the least and the greatest, as integers, and
            // `key` keeps that order (a shift of bits with the sign bit clear), so every key lies
            // between theirs, whatever the bits (a NaN's too).
            unsafe {
                self.positive
                    .add_all(key(least), key(greatest), &keys[lanes], self.count)
            };
            Some(PositiveExtremes { least, greatest })
        }
    }

    /// Adds the counts of `other`: the result is the sketch of both sets of values, whatever the
    /// order of pushes and merges.
    pub fn merge(&mut self, other: &Sketch) {
        self.count += other.count;
        self.zeros += other.zeros;
        self.positive.merge(&other.positive, self.count);
        self.negative.merge(&other.negative, self.count);
    }

    /// Number of values pushed (and merged).
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Non-empty buckets as `(midpoint, count)` in increasing order of value; exact zeros are the
    /// bucket `(0.0, zeros)`.
    pub fn buckets(&self) -> impl Iterator<Item = (f64, u64)> + '_ {
        let negative = self
            .negative
            .buckets()
            .rev()
            .map(|(key, count)| (-midpoint(key), count));
        let zeros = (self.zeros != 0).then_some((0.0, self.zeros));
        let positive = self
            .positive
            .buckets()
            .map(|(key, count)| (midpoint(key), count));
        negative.chain(zeros).chain(positive)
    }

    /// The quantile of level `q`: the midpoint of the bucket holding the value of rank
    /// [`rank`]`(q, n)` in sorted order (0 exactly when that value is a zero). It is within
    /// `2^-9 = 0.195 %` of the exact sample quantile of the same definition (for normal, not
    /// subnormal, values). 0 for an empty sketch.
    pub fn quantile(&self, q: f64) -> f64 {
        self.quantiles(&[q])[0]
    }

    /// [`Sketch::quantile`] for several levels (in any order) in one pass over the buckets.
    pub fn quantiles(&self, levels: &[f64]) -> Vec<f64> {
        let mut values = vec![0.0; levels.len()];
        let ranks: Vec<u64> = levels.iter().map(|&q| rank(q, self.count)).collect();
        let mut order: Vec<usize> = (0..levels.len()).collect();
        order.sort_by_key(|&i| ranks[i]);
        let mut pending = order.into_iter().peekable();
        let mut seen = 0;
        for (value, count) in self.buckets() {
            seen += count;
            while let Some(i) = pending.next_if(|&i| ranks[i] <= seen) {
                values[i] = value;
            }
            if pending.peek().is_none() {
                break;
            }
        }
        values
    }

    /// The quantile of level `q` with each bucket's values spread evenly over its width (exact
    /// zeros stay a point at 0): the value where the linear interpolation of the counts reaches
    /// `q n`. Continuous in `q`, unlike [`Sketch::quantile`]'s midpoints, so it suits a reference
    /// built from many values; never outside the bucket that holds the exact quantile, but off it
    /// by up to `w |rho| / 8` where the density changes by a share `rho` across the bucket's width
    /// `w` (a curved density's values are not spread evenly): see [`Sketch::interpolated`] for
    /// the range that allows for it. 0 for an empty sketch.
    pub fn interpolated_quantile(&self, q: f64) -> f64 {
        self.interpolated(&[q], [f64::NEG_INFINITY, f64::INFINITY])[0].value
    }

    /// [`Sketch::interpolated_quantile`] for several levels (in any order) in one pass over the
    /// buckets, each with the range in its bucket where the exact quantile may lie: twice the
    /// first-order error of the even spread either side, `w |rho| s (1 - s)` at the share `s` of
    /// the bucket's values below it (exact at the bucket's edges, at most `w |rho| / 4`), with
    /// `rho` the relative change of the density across the bucket that its two neighbours show
    /// (a neighbour that is not adjacent counts as empty); the whole bucket where the density
    /// bends across it too much for that (`Span::slope`). Where the buckets hold many values the statistical spread of
    /// a quantile is far below a bucket's width and this error dominates: a p95 of 1e8 normal
    /// values with `sd / mean = 0.09` was off by up to 2.6 standard errors. `within` is where
    /// the values lie (their exact `[min, max]`, where known): the buckets at the ends spread
    /// their values over the part of their width inside it, so that a narrow distribution whose
    /// first or last bucket holds a quantile is not read as reaching beyond its values (a normal
    /// truncated to `[0.395, 0.41]`: its p01 read at 0.39502 with a range ending there, for
    /// 0.39515, when the bucket from 0.3947 was spread whole).
    pub fn interpolated(&self, levels: &[f64], within: [f64; 2]) -> Vec<Interpolated> {
        let n = self.count as f64;
        let targets: Vec<f64> = levels.iter().map(|q| q.clamp(0.0, 1.0) * n).collect();
        let mut order: Vec<usize> = (0..levels.len()).collect();
        order.sort_by(|&a, &b| targets[a].total_cmp(&targets[b]));
        let mut pending = order.into_iter().peekable();
        let mut found = vec![Interpolated::at(0.0); levels.len()];
        let edges = |key: u32| {
            let [lo, hi] = [key, key + 1].map(|k| f64::from_bits(u64::from(k) << KEY_SHIFT));
            [lo, hi.min(f64::MAX)]
        };
        let inside = |lo: f64, hi: f64, count| Span(lo.max(within[0]), hi.min(within[1]), count);
        let negative = self.negative.buckets().rev().map(|(key, count)| {
            let [lo, hi] = edges(key);
            inside(-hi, -lo, count)
        });
        let zeros = (self.zeros != 0).then_some(Span(0.0, 0.0, self.zeros));
        let positive = self.positive.buckets().map(|(key, count)| {
            let [lo, hi] = edges(key);
            inside(lo, hi, count)
        });
        let mut spans = negative.chain(zeros).chain(positive).peekable();
        let (mut before, mut last, mut previous) = (0.0, 0.0, None);
        while let Some(span @ Span(lo, hi, count)) = spans.next() {
            let count = count as f64;
            let within = |i: &usize| targets[*i] <= before + count;
            if pending.peek().is_some_and(within) {
                let slope = span.slope(previous, spans.peek().copied());
                while let Some(i) = pending.next_if(within) {
                    let share = ((targets[i] - before) / count).clamp(0.0, 1.0);
                    let value = lo + share * (hi - lo);
                    let range = match slope {
                        Some(slope) => {
                            let error = (hi - lo) * slope * share * (1.0 - share);
                            [(value - error).max(lo), (value + error).min(hi)]
                        }
                        None => [lo, hi],
                    };
                    found[i] = Interpolated { value, range };
                }
            }
            if pending.peek().is_none() {
                break;
            }
            (before, last, previous) = (before + count, hi, Some(span));
        }
        pending.for_each(|i| found[i] = Interpolated::at(last));
        found
    }

    /// For each of `values` (in any order), the number of values whose bucket midpoint is at or
    /// below it (exact zeros at 0): a sum over the slots below the value's key, no scan of the
    /// buckets.
    pub fn counts_at_or_below(&self, values: &[f64]) -> Vec<u64> {
        // The stores' running totals once, then a few reads a value: a summary asks this of
        // each group for every quantile, and summed slot by slot each took a scan of the store.
        let (negative, positive) = (self.negative.cumulative(), self.positive.cumulative());
        values
            .iter()
            .map(|&value| {
                if value < 0.0 {
                    // Negative buckets of midpoint `-m <= value`, i.e. `m >= |value|`.
                    let k = key(value);
                    negative.sum_keys(k + 1..KEY_END)
                        + if midpoint(k) >= -value {
                            negative.sum_keys(k..k + 1)
                        } else {
                            0
                        }
                } else if value > 0.0 {
                    let k = key(value);
                    negative.sum_keys(0..KEY_END)
                        + self.zeros
                        + positive.sum_keys(0..k)
                        + if midpoint(k) <= value {
                            positive.sum_keys(k..k + 1)
                        } else {
                            0
                        }
                } else {
                    negative.sum_keys(0..KEY_END) + self.zeros
                }
            })
            .collect()
    }

    /// The values around `t`: how many lie surely below it, how many share its bucket (below it,
    /// on it or above it: the sketch cannot tell) and how many surely above it, with that
    /// bucket's value range. Exact zeros are a bucket of their own: at `t = 0` none is unsure.
    pub fn around(&self, t: f64) -> Around {
        let negatives = self.negative.sum_keys(0..KEY_END);
        let positives = self.positive.sum_keys(0..KEY_END);
        let k = key(t);
        let bucket = Self::bucket_of(t);
        if t > 0.0 {
            let below = self.positive.sum_keys(0..k);
            let within = self.positive.sum_keys(k..k + 1);
            Around {
                below: negatives + self.zeros + below,
                within,
                above: positives - below - within,
                bucket,
            }
        } else if t < 0.0 {
            let above = self.negative.sum_keys(0..k);
            let within = self.negative.sum_keys(k..k + 1);
            Around {
                below: negatives - above - within,
                within,
                above: above + self.zeros + positives,
                bucket,
            }
        } else {
            Around {
                below: negatives,
                within: 0,
                above: positives,
                bucket,
            }
        }
    }

    /// The value range `[lo, hi]` of the bucket that holds `t` (`[0, 0]` for `t = 0`), as
    /// [`Self::around`] gives it, without counting: every sketch has the same buckets.
    pub fn bucket_of(t: f64) -> [f64; 2] {
        let k = key(t);
        let [lo, hi] = [k, k + 1].map(|k| f64::from_bits(u64::from(k) << KEY_SHIFT));
        if t > 0.0 {
            [lo, hi.min(f64::MAX)]
        } else if t < 0.0 {
            // The negative bucket `k` holds `x` with `|x|` in `[lo, hi)`.
            [-hi.min(f64::MAX), -lo]
        } else {
            [0.0, 0.0]
        }
    }

    /// Slots allocated in the dense stores, to check that memory follows the range, not the count.
    #[cfg(test)]
    fn allocated_buckets(&self) -> usize {
        self.positive.len() + self.negative.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lanes::Lanes;
    use crate::stats::QUANTILES;
    use crate::stats::test_util::{SplitMix, exact_quantile};
    use proptest::prelude::*;

    /// The bucket midpoint is within `2^-9` of any value in it.
    const BOUND: f64 = 1.0 / 512.0;

    fn sketch_of(values: &[f64]) -> Sketch {
        let mut sketch = Sketch::new();
        values.iter().for_each(|&x| sketch.push(x));
        sketch
    }

    fn levels() -> Vec<f64> {
        let mut levels: Vec<f64> = QUANTILES.iter().map(|&(_, q)| q).collect();
        levels.extend([0.0, 0.001, 0.3, 0.333, 0.999, 1.0]);
        levels
    }

    /// Checks every level against the exact sorted-sample quantile: within 0.5 % relative (the
    /// requirement) and in fact within the bucket bound; exactly 0 when the exact value is 0.
    fn assert_close_to_exact(values: &[f64]) {
        let sketch = sketch_of(values);
        for q in levels() {
            let exact = exact_quantile(values, q);
            let estimate = sketch.quantile(q);
            if exact == 0.0 {
                assert_eq!(estimate, 0.0, "q = {q}");
            } else {
                let relative = ((estimate - exact) / exact).abs();
                assert!(relative <= 0.005, "q = {q}: {estimate} vs {exact}");
                assert!(relative <= BOUND, "q = {q}: {estimate} vs {exact}");
            }
        }
    }

    #[test]
    fn rank_is_the_inverted_cdf() {
        assert_eq!(rank(0.0, 10), 1);
        assert_eq!(rank(1.0, 10), 10);
        assert_eq!(rank(0.5, 10), 5);
        assert_eq!(rank(0.5, 11), 6);
        assert_eq!(rank(0.5, 1), 1);
        assert_eq!(rank(0.99, 100), 99);
        assert_eq!(rank(0.991, 100), 100);
        // 0.1 * 30 and 0.07 * 100 round above the integer in f64.
        assert_eq!(rank(0.1, 30), 3);
        assert_eq!(rank(0.07, 100), 7);
        assert_eq!(rank(0.5, 0), 0);
        assert_eq!(rank(f64::NAN, 5), 1);
    }

    #[test]
    fn midpoint_is_within_the_relative_bound() {
        let mut rng = SplitMix(1);
        for _ in 0..100_000 {
            // Log-uniform over 1e-300 .. 1e300.
            let x = 10f64.powf(600.0 * rng.uniform() - 300.0);
            let mid = midpoint(key(x));
            assert!(((mid - x) / x).abs() <= BOUND, "{x} -> {mid}");
            assert_eq!(key(-x), key(x));
        }
        assert_eq!(midpoint(key(1.0)), 1.0 + 1.0 / 512.0);
        assert_eq!(key(f64::MAX) + 1, KEY_END - 256);
    }

    #[test]
    fn interpolated_quantile_is_continuous_and_close() {
        let mut rng = SplitMix(7);
        let values: Vec<f64> = (0..200_000).map(|_| 3.0 + 4.0 * rng.uniform()).collect();
        let sketch = sketch_of(&values);
        for q in [0.001, 0.1, 0.5, 0.9, 0.99, 0.999] {
            let exact = exact_quantile(&values, q);
            let interpolated = sketch.interpolated_quantile(q);
            // Well inside the midpoints' bound: about 600 values per bucket.
            assert!(
                ((interpolated - exact) / exact).abs() <= BOUND / 8.0,
                "q = {q}"
            );
        }
        let levels: Vec<f64> = (0..=1000).map(|i| f64::from(i) / 1000.0).collect();
        let quantiles: Vec<f64> = levels
            .iter()
            .map(|&q| sketch.interpolated_quantile(q))
            .collect();
        assert!(quantiles.windows(2).all(|w| w[0] <= w[1]));
        assert!(
            quantiles[0] >= values.iter().copied().fold(f64::INFINITY, f64::min) * (1.0 - BOUND)
        );
        let mixed = sketch_of(&[-2.0, -1.0, 0.0, 0.0, 1.0, 2.0]);
        assert_eq!(mixed.interpolated_quantile(0.5), 0.0);
        assert!(mixed.interpolated_quantile(0.1) < -1.0);
        assert!(mixed.interpolated_quantile(0.9) > 1.0);
        assert_eq!(Sketch::new().interpolated_quantile(0.5), 0.0);
    }

    /// A distribution narrower than a few buckets (a normal truncated to a narrow window): the
    /// end buckets are read over the part of their width that holds values, so every level's
    /// quantile and range hold the exact one; spread over the whole bucket, the first one's reach
    /// below the smallest value.
    #[test]
    fn interpolated_within_the_values_reads_narrow_distributions() {
        let mut rng = SplitMix(11);
        for sign in [1.0, -1.0] {
            let values: Vec<f64> = (0..100_000)
                .map(|_| sign * (1.001 + 0.005 * rng.uniform()))
                .collect();
            let sketch = sketch_of(&values);
            let min = values.iter().copied().fold(f64::INFINITY, f64::min);
            let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let levels = [0.001, 0.01, 0.05, 0.5, 0.95, 0.99, 0.999];
            for (q, read) in levels.iter().zip(sketch.interpolated(&levels, [min, max])) {
                let exact = exact_quantile(&values, *q);
                // A bucket is 0.0039 wide here; the values' own spread within it, 1e-4.
                assert!((read.value - exact).abs() <= 1e-4, "{sign} q = {q}");
                let [lo, hi] = read.range;
                assert!(lo - 1e-4 <= exact && exact <= hi + 1e-4, "{sign} q = {q}");
                assert!(min <= lo && hi <= max, "{sign} q = {q}");
            }
            let first = if sign > 0.0 { 0.01 } else { 0.99 };
            let whole = sketch.interpolated_quantile(first);
            assert!(whole < min || whole > max, "{sign}: {whole}");
        }
    }

    #[test]
    fn uniform() {
        let mut rng = SplitMix(2);
        let values: Vec<f64> = (0..20_000).map(|_| 3.0 + 4.0 * rng.uniform()).collect();
        assert_close_to_exact(&values);
    }

    #[test]
    fn lognormal_over_six_decades() {
        let mut rng = SplitMix(3);
        // sigma = 2 in ln: +-4 sigma spans 7 decades around 1e-3.
        let values: Vec<f64> = (0..20_000)
            .map(|_| 1e-3 * (2.0 * rng.normal()).exp())
            .collect();
        let (lo, hi) = values
            .iter()
            .fold((f64::MAX, 0.0f64), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        assert!(hi / lo > 1e6, "{lo} .. {hi}");
        assert_close_to_exact(&values);
        let sketch = sketch_of(&values);
        let binades = (hi / lo).log2().ceil() as usize + 1;
        assert!(sketch.allocated_buckets() <= 2 * 256 * binades);
    }

    #[test]
    fn many_exact_zeros() {
        let mut rng = SplitMix(4);
        let values: Vec<f64> = (0..20_000)
            .map(|_| {
                if rng.uniform() < 0.7 {
                    0.0
                } else {
                    2e-4 * rng.uniform()
                }
            })
            .collect();
        assert_close_to_exact(&values);
        let sketch = sketch_of(&values);
        assert_eq!(sketch.quantile(0.5), 0.0);
        assert_eq!(sketch.quantile(0.7), 0.0);
        assert!(sketch.quantile(0.71) > 0.0);
    }

    #[test]
    fn integer_counts() {
        let mut rng = SplitMix(5);
        let values: Vec<f64> = (0..20_000)
            .map(|_| (rng.next_u64() % 65).min(rng.next_u64() % 65) as f64)
            .collect();
        assert_close_to_exact(&values);
    }

    #[test]
    fn negative_and_mixed_signs() {
        let mut rng = SplitMix(6);
        let negative: Vec<f64> = (0..10_000).map(|_| -5.0 - rng.uniform()).collect();
        assert_close_to_exact(&negative);
        let mixed: Vec<f64> = (0..20_000)
            .map(|_| {
                if rng.uniform() < 0.1 {
                    0.0
                } else {
                    rng.normal() * 1e3
                }
            })
            .collect();
        assert_close_to_exact(&mixed);
        let sketch = sketch_of(&mixed);
        let values: Vec<f64> = sketch.buckets().map(|(value, _)| value).collect();
        assert!(values.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(sketch.buckets().map(|(_, c)| c).sum::<u64>(), 20_000);
    }

    #[test]
    fn empty_and_single() {
        let empty = Sketch::new();
        assert_eq!(empty.count(), 0);
        assert_eq!(empty.quantile(0.5), 0.0);
        assert_eq!(empty.buckets().count(), 0);
        let one = sketch_of(&[2.5]);
        assert_eq!(one.quantiles(&[0.0, 0.5, 1.0]), vec![midpoint(key(2.5)); 3]);
    }

    #[test]
    fn extreme_values() {
        let values = [
            1e-300,
            -1e-300,
            1e300,
            -1e300,
            0.0,
            f64::MAX,
            -f64::MAX,
            1.0,
        ];
        assert_close_to_exact(&values);
    }

    /// `push_lanes` at the ends of the keys: subnormals (key 0), the largest finite value, and
    /// zeros of either sign among them, on 8 and 32 lanes, count what `push` counts.
    #[test]
    fn push_lanes_counts_the_ends_of_the_range_as_push_does() {
        let ends = [
            5e-324,
            2.2e-308,
            f64::MAX,
            1.0,
            -0.0,
            0.0,
            f64::MIN_POSITIVE,
        ];
        let batches: Vec<Vec<f64>> = vec![
            vec![5e-324; 3],
            vec![5e-324, f64::MAX, 2.2e-308],
            vec![f64::MAX; 2],
            vec![-0.0, 0.0, -0.0],
            vec![-0.0, 1.0, f64::MAX],
            vec![0.0, 1.0, 5e-324],
            ends.iter().cycle().take(32).copied().collect(),
            ends.iter().cycle().skip(4).take(29).copied().collect(),
        ];
        for batch in &batches {
            let pushed = sketch_of(batch);
            let lane = |k: usize| batch[k % batch.len()];
            let mut eight = Sketch::new();
            for part in batch.chunks(8) {
                let lane = |k: usize| part[k % part.len()];
                eight.push_lanes(&Lanes::<8>::from_fn(lane), 0..part.len());
            }
            let mut all = Sketch::new();
            all.push_lanes(&Lanes::<32>::from_fn(lane), 0..batch.len());
            for sketch in [&eight, &all] {
                assert_eq!(sketch, &pushed, "{batch:?}");
                assert_eq!(sketch.count(), batch.len() as u64, "{batch:?}");
            }
        }
    }

    /// A sketch whose one bucket (the key of 1.0) holds `count` values, as a group's state
    /// arrives from another machine.
    fn one_bucket(count: u64) -> Sketch {
        let json = format!(
            r#"{{"count":{count},"zeros":0,"positive":{{"offset":{},"counts":[{count}]}},"negative":{{"offset":0,"counts":[]}}}}"#,
            key(1.0)
        );
        serde_json::from_str(&json).expect("a sketch")
    }

    #[test]
    fn counts_widen_past_two_and_four_bytes_without_losing_a_value() {
        for full in [u64::from(u16::MAX), u64::from(u32::MAX)] {
            let mut pushed = one_bucket(full);
            pushed.push(1.0);
            let mut lanes = one_bucket(full);
            lanes.push_lanes(&Lanes::<4>::splat(1.0), 0..3);
            let mut merged = one_bucket(full);
            merged.merge(&one_bucket(full));
            for (sketch, n) in [(pushed, full + 1), (lanes, full + 3), (merged, 2 * full)] {
                assert_eq!(sketch.count(), n);
                assert_eq!(
                    sketch.buckets().collect::<Vec<_>>(),
                    [(midpoint(key(1.0)), n)]
                );
                let json = serde_json::to_string(&sketch).expect("serialises");
                assert!(json.contains(&format!("[{n}]")), "{json}");
                assert_eq!(
                    serde_json::from_str::<Sketch>(&json).expect("reads back"),
                    sketch
                );
            }
        }
    }

    #[test]
    fn the_same_counts_serialise_to_the_same_bytes_whatever_the_order_of_the_values() {
        let values: Vec<f64> = (1..=400).map(|i| f64::from(i) * 0.37 - 60.0).collect();
        let forward = sketch_of(&values);
        let backward = sketch_of(&values.iter().rev().copied().collect::<Vec<_>>());
        let mut by_lanes = Sketch::new();
        for batch in values.chunks(8) {
            by_lanes.push_lanes(&Lanes::<8>::from_fn(|k| batch[k]), 0..8);
        }
        let bytes = |s: &Sketch| serde_json::to_string(s).expect("serialises");
        assert_eq!(bytes(&backward), bytes(&forward));
        assert_eq!(bytes(&by_lanes), bytes(&forward));
        assert!(
            !bytes(&forward).contains("[0"),
            "trimmed to the non-empty buckets"
        );
    }

    /// Values log-uniform over `decades` decades from 1e-30, from a fixed stream.
    fn spread(n: usize, decades: f64, seed: u64) -> Vec<f64> {
        let mut rng = SplitMix(seed);
        (0..n)
            .map(|_| 1e-30 * 10f64.powf(decades * rng.uniform()))
            .collect()
    }

    #[test]
    fn few_values_over_many_decades_keep_only_their_buckets() {
        // 16 values over 32 decades: a dense range of about 27,000 keys (54 kB), 16 buckets kept.
        let values = spread(16, 32.0, 5);
        let sketch = sketch_of(&values);
        assert!(sketch.positive.is_sparse());
        assert!(sketch.allocated_buckets() <= 16);
        assert_close_to_exact(&values);
        // Lanes take the same path: one batch spanning the decades turns the store sparse at once.
        let mut by_lanes = Sketch::new();
        for batch in values.chunks(8) {
            by_lanes.push_lanes(&Lanes::<8>::from_fn(|k| batch[k]), 0..8);
        }
        assert!(by_lanes.positive.is_sparse());
        assert_eq!(by_lanes, sketch);
        // The same bytes as a dense store of the same counts, and read back in the sparse form.
        let dense = Sketch {
            count: 16,
            zeros: 0,
            positive: Store::Dense(match &sketch.positive {
                Store::Sparse(buckets) => {
                    let mut dense = Dense::default();
                    let (lo, hi) = sketch.positive.occupied().expect("values");
                    dense.regrow(lo, hi + 1);
                    buckets.iter().for_each(|(&k, &c)| dense.add_n(k, c));
                    dense
                }
                Store::Dense(_) => unreachable!("sparse above"),
            }),
            negative: Store::default(),
        };
        let bytes = |s: &Sketch| postcard::to_stdvec(s).expect("serialises");
        assert_eq!(bytes(&dense), bytes(&sketch));
        assert_eq!(
            serde_json::to_string(&dense).expect("serialises"),
            serde_json::to_string(&sketch).expect("serialises")
        );
        let read: Sketch = postcard::from_bytes(&bytes(&dense)).expect("reads back");
        assert!(read.positive.is_sparse());
        assert_eq!(read, sketch);
        assert_eq!(read.quantiles(&levels()), sketch.quantiles(&levels()));
    }

    #[test]
    fn a_sparse_store_that_fills_its_range_turns_dense_again() {
        // 32 groups of 16 values over 32 decades, merged: sparse while the buckets are few, dense
        // again once the values fill the range; the counts those of pushing every value.
        let values = spread(200_000, 32.0, 9);
        let mut merged = Sketch::new();
        for (i, group) in values.chunks(16).enumerate() {
            let part = sketch_of(group);
            assert!(part.positive.is_sparse());
            merged.merge(&part);
            if i == 0 {
                assert!(merged.positive.is_sparse());
            }
        }
        assert!(!merged.positive.is_sparse());
        assert_eq!(merged, sketch_of(&values));
        assert_close_to_exact(&values);
        let read: Sketch = postcard::from_bytes(&postcard::to_stdvec(&merged).expect("serialises"))
            .expect("reads");
        assert!(!read.positive.is_sparse());
        assert_eq!(read, merged);
    }

    #[test]
    fn counts_at_or_below_and_around_read_a_sparse_store_as_a_dense_one() {
        let mut values = spread(40, 60.0, 13);
        values.extend(spread(40, 60.0, 14).iter().map(|x| -x));
        values.extend([0.0, 0.0]);
        let sketch = sketch_of(&values);
        assert!(sketch.positive.is_sparse() && sketch.negative.is_sparse());
        let mut probes: Vec<f64> = values
            .iter()
            .flat_map(|&x| [x, x * 1.001, x * 0.999])
            .collect();
        probes.extend([0.0, 1e-40, -1e-40, 1e40, -1e40]);
        let counted = sketch.counts_at_or_below(&probes);
        for (&t, &count) in probes.iter().zip(&counted) {
            let by_buckets: u64 = sketch
                .buckets()
                .filter(|&(mid, _)| mid <= t)
                .map(|(_, c)| c)
                .sum();
            assert_eq!(count, by_buckets, "at or below {t}");
            let around = sketch.around(t);
            let at_zero = if t == 0.0 { 2 } else { 0 };
            assert_eq!(
                around.below + around.within + around.above + at_zero,
                sketch.count()
            );
        }
    }

    #[test]
    fn serialised_counts_are_eight_byte_integers_whatever_the_width_in_memory() {
        let sketch = sketch_of(&[1.0, 1.0, 2.0, -3.0, 0.0]);
        let value = serde_json::to_value(&sketch).expect("serialises");
        let counts = value["positive"]["counts"].as_array().expect("counts");
        assert_eq!(counts.iter().filter_map(|c| c.as_u64()).sum::<u64>(), 3);
        assert_eq!(
            value["negative"]["counts"]
                .as_array()
                .expect("counts")
                .iter()
                .filter_map(|c| c.as_u64())
                .sum::<u64>(),
            1
        );
        assert_eq!(
            serde_json::from_value::<Sketch>(value).expect("reads back"),
            sketch
        );
        let beyond = r#"{"count":1,"zeros":0,"positive":{"offset":524287,"counts":[0,1]},"negative":{"offset":0,"counts":[]}}"#;
        assert!(
            serde_json::from_str::<Sketch>(beyond).is_err(),
            "keys beyond the f64 range"
        );
    }

    #[test]
    fn quantiles_in_any_order() {
        let values: Vec<f64> = (1..=100).map(f64::from).collect();
        let sketch = sketch_of(&values);
        let levels = [0.9, 0.1, 0.5, 0.1, 1.0];
        let together = sketch.quantiles(&levels);
        let apart: Vec<f64> = levels.iter().map(|&q| sketch.quantile(q)).collect();
        assert_eq!(together, apart);
    }

    proptest! {
        #[test]
        fn counts_at_or_below_match_a_scan_per_value(
            values in prop::collection::vec(finite_value(), 0..100),
            at in prop::collection::vec(finite_value(), 0..12),
        ) {
            let sketch = sketch_of(&values);
            // The non-empty buckets once: a store's slots span its range of keys densely, so a
            // walk of them per value made this test take 15 s.
            let buckets: Vec<(f64, u64)> = sketch.buckets().collect();
            let midpoints: Vec<f64> = buckets.iter().map(|&(m, _)| m).collect();
            // Also the values themselves, the buckets' midpoints (a value on a midpoint counts
            // its bucket), just beside them, and both zeros.
            let beside = midpoints.iter().flat_map(|&m| [m.next_up(), m.next_down()]);
            let at: Vec<f64> = at.iter().chain(&values).chain(&midpoints).copied().chain(beside)
                .chain([0.0, -0.0]).collect();
            let scanned: Vec<u64> = at
                .iter()
                .map(|&v| buckets.iter().filter(|&&(midpoint, _)| midpoint <= v).map(|(_, c)| c).sum())
                .collect();
            prop_assert_eq!(sketch.counts_at_or_below(&at), scanned);
        }
    }

    fn finite_value() -> impl Strategy<Value = f64> {
        prop_oneof![
            Just(0.0),
            Just(-0.0),
            -1e6..1e6f64,
            // Physical quantities: 1e-40 .. 1e40 (the full range costs 4 MiB of buckets per
            // store, slow in a property test; `extreme_values` covers it once).
            (-40.0..40.0f64, any::<bool>()).prop_map(|(e, negative)| {
                let x = 10f64.powf(e);
                if negative { -x } else { x }
            }),
        ]
    }

    proptest! {
        #[test]
        fn quantiles_match_sorted_values(values in prop::collection::vec(finite_value(), 1..300)) {
            assert_close_to_exact(&values);
        }

        #[test]
        fn merge_equals_pushing_everything(
            values in prop::collection::vec(finite_value(), 0..300),
            cuts in prop::collection::vec(0..300usize, 0..4),
        ) {
            let mut cuts: Vec<usize> = cuts.into_iter().map(|c| c.min(values.len())).collect();
            cuts.push(0);
            cuts.push(values.len());
            cuts.sort_unstable();
            let mut merged = Sketch::new();
            for part in cuts.windows(2) {
                merged.merge(&sketch_of(&values[part[0]..part[1]]));
            }
            let whole = sketch_of(&values);
            prop_assert_eq!(merged.count(), whole.count());
            prop_assert_eq!(merged.buckets().collect::<Vec<_>>(), whole.buckets().collect::<Vec<_>>());
        }

        /// A batch's extremes, when every value is positive, and only then: the least and the
        /// greatest value, to the bit.
        #[test]
        fn a_positive_batch_gives_its_extremes(
            values in prop::collection::vec(
                prop_oneof![
                    20 => (-300.0..300.0f64).prop_map(|e| 10f64.powf(e)),
                    20 => 0.999..1.001f64,
                    1 => Just(f64::MIN_POSITIVE / 4.0),
                    1 => Just(f64::MAX),
                    1 => finite_value(),
                ],
                1..33,
            ),
        ) {
            let lanes = Lanes::<32>::from_fn(|k| values[k.min(values.len() - 1)]);
            let extremes = Sketch::new().push_filled_lanes(&lanes, 0..values.len());
            let positive = values.iter().all(|&x| x > 0.0);
            prop_assert_eq!(extremes.is_some(), positive);
            if let Some(PositiveExtremes { least, greatest }) = extremes {
                let least_value = values.iter().copied().fold(f64::INFINITY, f64::min);
                let greatest_value = values.iter().copied().fold(0.0, f64::max);
                prop_assert_eq!(least.to_bits(), least_value.to_bits());
                prop_assert_eq!(greatest.to_bits(), greatest_value.to_bits());
            }
        }

        /// Every path of `push_lanes` (all zero, some not positive, one bucket, several), on one,
        /// four, eight and 32 lanes with spare lanes: the counts of `push` on each value, and a
        /// sketch equal to it however its stores grew.
        #[test]
        fn push_lanes_counts_what_push_counts(
            values in prop::collection::vec(finite_value(), 0..200),
            repeats in prop::collection::vec(any::<bool>(), 200),
            start in prop::collection::vec(finite_value(), 0..5),
        ) {
            // Runs of one value, so that whole batches share a bucket or are all zero.
            let values: Vec<f64> = values
                .iter()
                .zip(&repeats)
                .scan(None, |last, (&x, &repeat)| {
                    let x = if repeat { last.unwrap_or(x) } else { x };
                    *last = Some(x);
                    Some(x)
                })
                .collect();
            let pushed = sketch_of(&start.iter().chain(&values).copied().collect::<Vec<_>>());
            let by_lanes = |lanes: usize| {
                let mut sketch = sketch_of(&start);
                for batch in values.chunks(lanes) {
                    let lane = |k: usize| batch.get(k).copied().unwrap_or(f64::NAN);
                    match lanes {
                        1 => sketch.push_lanes(&batch[0], 0..1),
                        4 => sketch.push_lanes(&Lanes::<4>::from_fn(lane), 0..batch.len()),
                        8 => sketch.push_lanes(&Lanes::<8>::from_fn(lane), 0..batch.len()),
                        _ => sketch.push_lanes(&Lanes::<32>::from_fn(lane), 0..batch.len()),
                    }
                }
                sketch
            };
            for lanes in [1, 4, 8, 32] {
                let sketch = by_lanes(lanes);
                prop_assert_eq!(sketch.count(), pushed.count());
                prop_assert_eq!(sketch.buckets().collect::<Vec<_>>(), pushed.buckets().collect::<Vec<_>>());
                prop_assert_eq!(&sketch, &pushed);
            }
        }
    }
}
