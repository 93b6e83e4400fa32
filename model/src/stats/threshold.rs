//! Thresholds of a metric and the share of values beyond them: counted exactly as a job runs
//! ([`ThresholdCount`], kept by each [`Accumulator`](super::Accumulator)), or bounded after the
//! run by the sketch's buckets (`Beyond`).

use serde::{Deserialize, Serialize};

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
    #[inline(always)]
    pub fn beyond(self, x: f64) -> bool {
        match self {
            Threshold::Above(limit) => x > limit,
            Threshold::Below(limit) => x < limit,
        }
    }

    /// For whole-number values, the threshold half-way between two whole numbers that the same
    /// values lie beyond (`above:7` is `above:7.5`, `below:7` is `below:6.5`): below 256, where
    /// a sketch bucket holds one whole number, no value shares its bucket, so that it is answered
    /// exactly after the run (`above:7` of bounce counts read 1.0 where 13.9 % were 8: every 7
    /// in the bucket from 7 counted as spread above it; found from outside).
    pub fn between_whole_values(self) -> Threshold {
        match self {
            Threshold::Above(x) => Threshold::Above(x.floor() + 0.5),
            Threshold::Below(x) => Threshold::Below(x.ceil() - 0.5),
        }
    }

    /// The same side and value, to the bit (`-0.0` is not `0.0`).
    pub fn same(self, other: Threshold) -> bool {
        match (self, other) {
            (Threshold::Above(a), Threshold::Above(b))
            | (Threshold::Below(a), Threshold::Below(b)) => a.to_bits() == b.to_bits(),
            _ => false,
        }
    }
}

/// How a probability was counted: every value compared with the threshold, or some values known
/// only to lie in the sketch bucket that holds it.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
pub enum Resolution {
    /// Every value was compared with the threshold: the threshold was counted as the job ran, it
    /// lies in the far tail every group keeps exactly, or no value shares its bucket. The interval
    /// is the sampling interval alone.
    #[default]
    Exact,
    /// Some values share the threshold's bucket (`bucket`), so which side they lie on is unknown:
    /// the interval runs from the sampling interval's lower end with all of them on the near side
    /// to its upper end with all of them beyond, so it holds the truth whatever they are.
    Bucket,
}

/// The probability of a value beyond a threshold, with a 95 % confidence interval; serialised as
/// `{"above": x, "probability", "ci95", "resolution"[, "bucket"]}` (or `"below"`).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct ThresholdExceedance {
    /// `above` or `below`, and the threshold.
    #[serde(flatten)]
    pub threshold: Threshold,
    /// The share of values beyond the threshold. Bucket-limited, the values in the threshold's
    /// bucket count as spread evenly over its width (within each group's exact min and max).
    pub probability: f64,
    /// Its 95 % confidence interval: Wilson's (Clopper and Pearson's below 100 effective events),
    /// with the design effect of the groups; bucket-limited,
    /// widened to both ends of the bucket (see [`Resolution::Bucket`]).
    pub ci95: [f64; 2],
    /// `exact` or `bucket`.
    #[serde(default)]
    pub resolution: Resolution,
    /// Bucket-limited only: the value range `[lo, hi]` of the bucket that holds the threshold.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bucket: Option<[f64; 2]>,
}

/// One threshold and the exact number of values beyond it, counted as the values arrive.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct ThresholdCount {
    pub(super) threshold: Threshold,
    pub(super) beyond: u64,
}

impl ThresholdCount {
    pub(super) fn new(threshold: Threshold) -> Self {
        Self {
            threshold,
            beyond: 0,
        }
    }

    /// The threshold counted.
    pub fn threshold(&self) -> Threshold {
        self.threshold
    }

    /// The values beyond it so far.
    pub fn beyond(&self) -> u64 {
        self.beyond
    }
}

/// What one group says of the values beyond a threshold: at least `sure`, at most
/// `sure + unsure`, and `spread` as the best guess within that range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Beyond {
    pub(super) sure: u64,
    pub(super) unsure: u64,
    pub(super) spread: f64,
}

impl Beyond {
    pub(super) fn exact(count: u64) -> Self {
        Self {
            sure: count,
            unsure: 0,
            spread: count as f64,
        }
    }
}
