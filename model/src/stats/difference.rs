//! Two estimates compared, each with its own 95 % interval: their difference and their ratio with
//! intervals by the method of variance estimates recovery (MOVER; Zou & Donner, *Statistics in
//! Medicine* 27, 2008; Donner & Zou, *Stat. Methods Med. Res.* 21, 2012). Each side's interval keeps
//! its own shape (a Woodruff interval of a quantile, a log-Wald interval of a B-life, Wilson's or
//! Clopper and Pearson's of a probability), so the comparison claims no more than the two intervals do:
//!
//! `a - b`: `[d - sqrt((a - l_a)^2 + (u_b - b)^2), d + sqrt((u_a - a)^2 + (b - l_b)^2)]`,
//!
//! and `a / b` by the same on `ln a - ln b` when both intervals are positive. With symmetric
//! intervals this is the normal interval of a difference of independent estimates,
//! `d +- z sqrt(se_a^2 + se_b^2)`; the two estimates must come from independent samples (two jobs).
//!
//! A quantile's value is its sketch bucket's representative, while its interval resolves within
//! the bucket ([`Estimate::bucketed`]): the value can sit at one end of its interval, which MOVER
//! would read as no error on that side. Such an estimate enters MOVER at its interval's midpoint
//! (the interval then widened to hold `a - b`): two samples of one distribution with 10^5 values
//! had p50 and p95 differences whose intervals held 0 in 74 % and 84 % of 200 pairs measured from
//! the values, 96.5 % and 96 % from the midpoints (`montecarlo::compare`'s tests).

use serde::{Deserialize, Serialize};

/// An estimate and its 95 % interval, when it has one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    pub value: f64,
    pub ci95: Option<[f64; 2]>,
    /// Whether `value` is a bucket's representative that need not be the interval's centre.
    bucketed: bool,
}

impl Estimate {
    pub fn new(value: f64, ci95: Option<[f64; 2]>) -> Self {
        Self {
            value,
            ci95,
            bucketed: false,
        }
    }

    /// A quantile's estimate: `value` its bucket's representative, `ci95` resolved within the
    /// bucket, so that MOVER takes the interval's midpoint as its centre (see the module).
    pub fn bucketed(value: f64, ci95: Option<[f64; 2]>) -> Self {
        Self {
            bucketed: true,
            ..Self::new(value, ci95)
        }
    }

    /// Where MOVER measures the interval's arms from.
    fn centre(&self, [lo, hi]: [f64; 2]) -> f64 {
        if self.bucketed {
            0.5 * (lo + hi)
        } else {
            self.value
        }
    }

    /// The interval, if it is finite and holds the value.
    fn interval(&self) -> Option<[f64; 2]> {
        self.ci95.filter(|[lo, hi]| {
            lo.is_finite() && hi.is_finite() && *lo <= self.value && self.value <= *hi
        })
    }

    /// The estimate on a log scale, when it and its interval are positive.
    fn ln(&self) -> Option<Estimate> {
        let [lo, hi] = self.interval()?;
        (lo > 0.0).then(|| Estimate {
            value: self.value.ln(),
            ci95: Some([lo.ln(), hi.ln()]),
            bucketed: self.bucketed,
        })
    }
}

/// `a` against `b`: both values, `a - b` and `a / b`, with their intervals.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Difference {
    /// The first design's value.
    pub a: f64,
    /// Its 95 % interval; `null` when it has none.
    pub a_ci95: Option<[f64; 2]>,
    /// The second design's value.
    pub b: f64,
    /// Its 95 % interval; `null` when it has none.
    pub b_ci95: Option<[f64; 2]>,
    /// `a - b`.
    pub difference: f64,
    /// 95 % interval of `a - b` (MOVER); `null` unless both sides have an interval.
    pub difference_ci95: Option<[f64; 2]>,
    /// `a / b`; `null` unless both values are positive.
    pub ratio: Option<f64>,
    /// 95 % interval of `a / b` (MOVER on the log scale); `null` unless both sides have positive
    /// intervals.
    pub ratio_ci95: Option<[f64; 2]>,
}

/// `a` against `b`, see the module's documentation.
pub fn difference(a: Estimate, b: Estimate) -> Difference {
    let d = a.value - b.value;
    let ratio = (a.value > 0.0 && b.value > 0.0).then(|| a.value / b.value);
    let ratio_ci95 = ratio
        .and(a.ln().zip(b.ln()))
        .and_then(|(la, lb)| mover(la, lb))
        .map(|[lo, hi]| [lo.exp(), hi.exp()]);
    Difference {
        a: a.value,
        a_ci95: a.interval(),
        b: b.value,
        b_ci95: b.interval(),
        difference: d,
        difference_ci95: mover(a, b),
        ratio,
        ratio_ci95,
    }
}

/// The MOVER interval of `a - b`, holding `a - b`.
fn mover(a: Estimate, b: Estimate) -> Option<[f64; 2]> {
    let [la, ua] = a.interval()?;
    let [lb, ub] = b.interval()?;
    let (ca, cb) = (a.centre([la, ua]), b.centre([lb, ub]));
    let d = ca - cb;
    let lower = d - (ca - la).hypot(ub - cb);
    let upper = d + (ua - ca).hypot(cb - lb);
    let value = a.value - b.value;
    (lower.is_finite() && upper.is_finite()).then_some([lower.min(value), upper.max(value)])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::Z_975;
    use approx::assert_relative_eq;

    #[test]
    fn symmetric_intervals_give_the_normal_interval_of_a_difference() {
        // se 0.3 and 0.4: the difference's se is 0.5.
        let a = Estimate::new(10.0, Some([10.0 - Z_975 * 0.3, 10.0 + Z_975 * 0.3]));
        let b = Estimate::new(7.0, Some([7.0 - Z_975 * 0.4, 7.0 + Z_975 * 0.4]));
        let d = difference(a, b);
        assert_eq!(d.difference, 3.0);
        let [lo, hi] = d.difference_ci95.unwrap();
        assert_relative_eq!(lo, 3.0 - Z_975 * 0.5, max_relative = 1e-14);
        assert_relative_eq!(hi, 3.0 + Z_975 * 0.5, max_relative = 1e-14);
    }

    #[test]
    fn asymmetric_intervals_keep_their_shape() {
        // Zou & Donner's recipe by hand: a = 5 [4, 7], b = 2 [1.5, 3].
        let d = difference(
            Estimate::new(5.0, Some([4.0, 7.0])),
            Estimate::new(2.0, Some([1.5, 3.0])),
        );
        let [lo, hi] = d.difference_ci95.unwrap();
        assert_relative_eq!(lo, 3.0 - (1.0f64 + 1.0).sqrt(), max_relative = 1e-14);
        assert_relative_eq!(hi, 3.0 + (4.0f64 + 0.25).sqrt(), max_relative = 1e-14);
        // The ratio on the log scale: log-Wald intervals give ln a - ln b +- z sqrt(se^2 + se^2).
        let (sa, sb) = (0.1, 0.2);
        let a = Estimate::new(
            100.0,
            Some([100.0 * (-Z_975 * sa).exp(), 100.0 * (Z_975 * sa).exp()]),
        );
        let b = Estimate::new(
            50.0,
            Some([50.0 * (-Z_975 * sb).exp(), 50.0 * (Z_975 * sb).exp()]),
        );
        let d = difference(a, b);
        assert_eq!(d.ratio, Some(2.0));
        let [lo, hi] = d.ratio_ci95.unwrap();
        let se = sa.hypot(sb);
        assert_relative_eq!(lo, 2.0 * (-Z_975 * se).exp(), max_relative = 1e-13);
        assert_relative_eq!(hi, 2.0 * (Z_975 * se).exp(), max_relative = 1e-13);
    }

    #[test]
    fn missing_or_unusable_intervals_give_none() {
        let d = difference(
            Estimate::new(1.0, None),
            Estimate::new(2.0, Some([1.0, 3.0])),
        );
        assert_eq!(d.difference, -1.0);
        assert_eq!(d.difference_ci95, None);
        assert_eq!(d.ratio, Some(0.5));
        assert_eq!(d.ratio_ci95, None);
        // A negative value has no ratio; an interval that misses its value is not used.
        let d = difference(
            Estimate::new(-1.0, Some([-2.0, 0.0])),
            Estimate::new(2.0, Some([3.0, 4.0])),
        );
        assert_eq!(d.ratio, None);
        assert_eq!(d.b_ci95, None);
        assert_eq!(d.difference_ci95, None);
        // An interval touching zero has no log.
        let d = difference(
            Estimate::new(0.5, Some([0.0, 1.0])),
            Estimate::new(0.25, Some([0.1, 0.4])),
        );
        assert_eq!(d.ratio, Some(2.0));
        assert_eq!(d.ratio_ci95, None);
        assert!(d.difference_ci95.is_some());
    }
}
