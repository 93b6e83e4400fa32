//! Mergeable, deterministic summaries of Monte Carlo results (the contract's `SUMMARY`).
//!
//! A job pushes tens of millions of values per second per core, one [`Accumulator`] per
//! (metric, bin, group). Memory does not grow with the number of values and a push costs a handful
//! of nanoseconds: no logarithm and no division, only integer work on the IEEE bit pattern
//! ([`Sketch`]) and a few additions. [`summarize`] merges the groups of one (metric, bin) into the
//! [`Summary`] that is serialised into the result.
//!
//! Groups are the independent unit: the operations of one device are correlated (wear carries from
//! one operation to the next), so each group holds a fixed set of devices and the confidence
//! intervals are built from the spread between groups (batch means for the mean, Woodruff for
//! quantiles, a design effect for exceedance), not from `n`.
//!
//! Determinism: integer counts do not depend on order; float sums do, so the caller fixes the order
//! of pushes and merges and gets the same summary to the bit.
//!
//! | module | what |
//! |---|---|
//! | [`sketch`] | log-linear bucket histogram from the f64 bit pattern; quantiles within 0.2 % |
//! | [`accumulator`] | count, min, max, shifted sums, exceedance count, sketch |
//! | [`intervals`] | Student t 0.975 quantile; Wilson's and Clopper-Pearson's for proportions |
//! | [`beta`] | the regularised incomplete beta function and its inverse |
//! | [`summary`] | the serialised `SUMMARY` and [`summarize`] |
//! | [`regression`] | standardised regression coefficients, mergeable |
//! | [`sobol`] | Sobol' first-order and total indices by pick-freeze, with delta-method intervals |
//! | [`tails`] | the most extreme values of each accumulator, kept exactly |
//! | [`threshold`] | thresholds counted exactly as values arrive, or bounded by the buckets after |
//! | [`query`](mod@query) | any quantile or threshold after the run, from the same groups |
//!
//! Accumulators serialise exactly, every float by its bits (infinities included), so a group's
//! state can cross machines and merge into the same numbers.

pub mod accumulator;
pub mod beta;
mod bits;
pub mod difference;
pub mod intervals;
pub mod query;
pub mod regression;
pub mod sketch;
pub mod sobol;
pub mod summary;
pub mod tails;
pub mod threshold;

pub use accumulator::{Accumulator, LaneSums};
pub use difference::{Difference, Estimate, difference};
pub use intervals::{Z_975, proportion_interval, satterthwaite_df, student_t_975, wilson_interval};
pub use query::{QueryAnswer, QueryQuantile, level_key, query};
pub use sketch::{Interpolated, Sketch};
pub use summary::{Exceedance, HISTOGRAM_BINS, Histogram, QuantileSummary, Summary, summarize};
pub use tails::Tails;
pub use threshold::{Resolution, Threshold, ThresholdExceedance};

/// The reported quantiles: the key in `SUMMARY.quantiles` and the level `q` (see
/// [`sketch::rank`] for the definition).
pub const QUANTILES: [(&str, f64); 9] = [
    ("p01", 0.01),
    ("p05", 0.05),
    ("p10", 0.10),
    ("p25", 0.25),
    ("p50", 0.50),
    ("p75", 0.75),
    ("p90", 0.90),
    ("p95", 0.95),
    ("p99", 0.99),
];

/// The reported quantile keyed `key` (`"p95"`): the key as [`QUANTILES`] holds it, and its level.
pub fn quantile_keyed(key: &str) -> Option<(&'static str, f64)> {
    QUANTILES.iter().find(|(known, _)| *known == key).copied()
}

/// splitmix64: a tiny deterministic generator, enough for test data and the synthetic
/// measurements of [`crate::calibration::study`].
pub(crate) struct SplitMix(pub u64);

impl SplitMix {
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform on [0, 1) with 53 random bits.
    pub(crate) fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal by Box-Muller (one of the pair).
    pub(crate) fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
pub(crate) mod test_util {
    pub(crate) use super::SplitMix;

    /// The exact quantile of the same definition as the sketch: the value of rank
    /// [`super::sketch::rank`] in sorted order.
    pub fn exact_quantile(values: &[f64], q: f64) -> f64 {
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        sorted[(super::sketch::rank(q, sorted.len() as u64) - 1) as usize]
    }
}
