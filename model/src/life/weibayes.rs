//! Weibayes: life demonstrated with few or no failures, the Weibull shape `beta` taken as known
//! (from experience with the design, not from these lives). With `r` failures among devices whose
//! lives (failed or censored) are `t_i`, the scale's estimate and its one-sided lower bound at
//! confidence `C` are (Nelson, *Applied Life Data Analysis*, ch. 8; Abernethy, *The New Weibull
//! Handbook*, ch. 6)
//!
//! `eta = (sum t_i^beta / r)^(1/beta)`, `eta_lower = (2 sum t_i^beta / chi2(C; 2r + 2))^(1/beta)`,
//!
//! and with no failures `chi2(C; 2) = -2 ln(1 - C)`: the zero-failure test. A B-life's lower bound
//! is `eta_lower (-ln(1 - p))^(1/beta)`.

use super::Lives;
use serde::{Deserialize, Serialize};

/// A Weibayes demonstration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Weibayes {
    /// The shape taken as known.
    pub beta: f64,
    /// The one-sided confidence of the lower bounds.
    pub confidence: f64,
    pub failures: u64,
    pub devices: u64,
    /// The scale's estimate; none without failures, or where it passes f64 (a shape near 0.01
    /// with few failures: an estimate is not lowered as a lower bound may be).
    pub eta: Option<f64>,
    /// The scale's lower bound at `confidence` (a bound beyond f64 reads as its largest value, a
    /// lower bound still, where JSON has no infinity).
    pub eta_lower: f64,
    /// B1's and B10's lower bounds at `confidence`, as `eta_lower` beyond f64.
    pub b1_lower: f64,
    pub b10_lower: f64,
}

/// Why no demonstration can be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WeibayesError {
    #[error("the shape must be a finite number from 0.01 to 100, got {}", crate::error::shown(*.0))]
    Shape(f64),
    #[error("the confidence must be between 0 and 1 (exclusive), got {}", crate::error::shown(*.0))]
    Confidence(f64),
    #[error("there are no lives to demonstrate from")]
    NoLives,
}

/// Whether a demonstration can take shape `beta` at `confidence`, whatever the lives: what
/// [`weibayes`] checks first, for a caller to refuse bad arguments before it has the lives.
pub fn check_arguments(beta: f64, confidence: f64) -> Result<(), WeibayesError> {
    if !(beta.is_finite() && (0.01..=100.0).contains(&beta)) {
        return Err(WeibayesError::Shape(beta));
    }
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(WeibayesError::Confidence(confidence));
    }
    Ok(())
}

/// The Weibayes demonstration of `lives` with shape `beta` at one-sided `confidence`.
pub fn weibayes(lives: &Lives, beta: f64, confidence: f64) -> Result<Weibayes, WeibayesError> {
    check_arguments(beta, confidence)?;
    let at = lives.at();
    let t_max = at.last().ok_or(WeibayesError::NoLives)?.time;
    // sum t^beta = t_max^beta sum (t / t_max)^beta: every term at most 1, nothing overflows.
    let scaled: f64 = at
        .iter()
        .map(|a| a.devices() * (a.time / t_max).powf(beta))
        .sum();
    let failures = lives.failures();
    // In logarithms, so that a B-life below f64's largest is kept where the scale is beyond it
    // (beta 0.01 at 95 %: eta_lower about 1e331, B1's about 1e131).
    let ln_scale_of = |divisor: f64| t_max.ln() + (scaled / divisor).ln() / beta;
    let ln_eta_lower = ln_scale_of(0.5 * chi_square_quantile(confidence, failures + 1));
    let b_lower = |p: f64| {
        (ln_eta_lower + (-(-p).ln_1p()).ln() / beta)
            .exp()
            .min(f64::MAX)
    };
    Ok(Weibayes {
        beta,
        confidence,
        failures,
        devices: lives.failures() + lives.censored(),
        eta: (failures > 0)
            .then(|| ln_scale_of(failures as f64).exp())
            .filter(|eta| eta.is_finite()),
        eta_lower: ln_eta_lower.exp().min(f64::MAX),
        b1_lower: b_lower(0.01),
        b10_lower: b_lower(0.10),
    })
}

/// The `p` quantile of chi-square with `2 m` degrees of freedom: twice the `p` quantile of the
/// gamma distribution of shape `m`, found by bisection in `ln y` on whichever tail of the gamma
/// CDF keeps its digits there, in logarithms: `ln P(m, y)` against `ln p` at or below the median,
/// `ln Q(m, y)` against `ln(1 - p)` above it. Near `p = 1` a CDF formed as `1 - Q` has lost the
/// digits that set the quantile (`1 - 1e-16`: 1 % off), and a bisection from 0 in `y` stops short
/// of a quantile near 1e-150 (`p = 1e-300`).
fn chi_square_quantile(p: f64, m: u64) -> f64 {
    let m = m as f64;
    if m == 1.0 {
        return -2.0 * (-p).ln_1p();
    }
    let below = |ln_y: f64| {
        let (ln_lower, ln_upper) = gamma_tails_ln(m, ln_y.exp());
        if p <= 0.5 {
            ln_lower < p.ln()
        } else {
            ln_upper > (-p).ln_1p()
        }
    };
    // `P(m, y) <= y^m / m!`, so the quantile is at least `(p m!)^(1/m)`.
    let mut lo = (p.ln() + libm::lgamma(m + 1.0)) / m - 1.0;
    let mut hi = (m + 10.0 * m.sqrt() + 50.0).ln();
    while below(hi) {
        hi += std::f64::consts::LN_2;
    }
    while hi - lo > 1e-16 * hi.abs().max(1.0) {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if below(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    2.0 * (0.5 * (lo + hi)).exp()
}

/// `(P(a, x), ln Q(a, x))`, the regularised lower incomplete gamma function and the log of its
/// complement: the series of `P` below `x = a + 1`, the continued fraction of `Q` above (Numerical
/// Recipes 6.2, Lentz's method), so that `ln Q` keeps its digits far in the upper tail, where `Q`
/// itself would underflow. `x <= 0` gives `(0, 0)`.
pub(crate) fn regularized_gamma(a: f64, x: f64) -> (f64, f64) {
    if x <= 0.0 {
        return (0.0, 0.0);
    }
    let ln_front = ln_prefactor(a, x);
    if x < a + 1.0 {
        let p = lower_series(a, x) * ln_front.exp();
        (p, (-p).ln_1p())
    } else {
        let ln_q = upper_fraction(a, x).ln() + ln_front;
        (-ln_q.exp_m1(), ln_q)
    }
}

/// `(ln P(a, x), ln Q(a, x))` for `x > 0`: each tail in logarithms, the one computed directly
/// keeping its digits where it is far below 1 (`P` near 0 and `Q` near 1 below `x = a + 1`).
fn gamma_tails_ln(a: f64, x: f64) -> (f64, f64) {
    let ln_front = ln_prefactor(a, x);
    if x < a + 1.0 {
        let ln_p = lower_series(a, x).ln() + ln_front;
        (ln_p, (-ln_p.exp()).ln_1p())
    } else {
        let ln_q = upper_fraction(a, x).ln() + ln_front;
        ((-ln_q.exp()).ln_1p(), ln_q)
    }
}

/// `ln(x^a e^-x / Gamma(a))`, the factor both tails' expansions share.
fn ln_prefactor(a: f64, x: f64) -> f64 {
    a * x.ln() - x - libm::lgamma(a)
}

/// `P(a, x) x^-a e^x Gamma(a)`: the series `sum x^n / (a (a + 1) ... (a + n))`.
fn lower_series(a: f64, x: f64) -> f64 {
    let (mut term, mut sum, mut n) = (1.0 / a, 1.0 / a, a);
    for _ in 0..100_000 {
        n += 1.0;
        term *= x / n;
        sum += term;
        if term.abs() < sum.abs() * 1e-17 {
            break;
        }
    }
    sum
}

/// `Q(a, x) x^-a e^x Gamma(a)`: the continued fraction, by Lentz's method.
fn upper_fraction(a: f64, x: f64) -> f64 {
    let tiny = 1e-300;
    let mut b = x + 1.0 - a;
    let mut c = 1.0 / tiny;
    let mut d = 1.0 / b;
    let mut h = d;
    for i in 1..100_000 {
        let an = -(i as f64) * (i as f64 - a);
        b += 2.0;
        d = an * d + b;
        if d.abs() < tiny {
            d = tiny;
        }
        c = b + an / c;
        if c.abs() < tiny {
            c = tiny;
        }
        d = 1.0 / d;
        let delta = d * c;
        h *= delta;
        if (delta - 1.0).abs() < 1e-16 {
            break;
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// Zero failures: 20 devices through 1000 operations each, beta 2, 90 %: `eta_lower =
    /// 1000 sqrt(20 / ln 10)`, the textbook zero-failure test.
    #[test]
    fn zero_failures_give_the_zero_failure_test() {
        let lives = Lives::from_pairs(&[(1000.0, false); 20]).unwrap();
        let w = weibayes(&lives, 2.0, 0.9).unwrap();
        assert_eq!((w.failures, w.devices, w.eta), (0, 20, None));
        let eta_lower = 1000.0 * (20.0 / 10f64.ln()).sqrt();
        assert_relative_eq!(w.eta_lower, eta_lower, max_relative = 1e-14);
        assert_relative_eq!(
            w.b10_lower,
            eta_lower * (-(0.9f64).ln()).sqrt(),
            max_relative = 1e-14
        );
    }

    /// A shape of 0.01 and 5 % confidence, no failures among 100 devices through 200 operations:
    /// the scale's bound, `200 (100 / -ln 0.95)^100`, is about 1e331, beyond f64; the B-lives' are
    /// not, `200 (100 (-ln(1 - p)) / -ln 0.95)^100` (B1 about 3e131), and are kept. The scale's
    /// reads as f64's largest, still a lower bound (infinity was `null` in JSON).
    #[test]
    fn a_b_life_within_f64_is_kept_where_the_scale_is_beyond() {
        let lives = Lives::from_pairs(&[(200.0, false); 100]).unwrap();
        let w = weibayes(&lives, 0.01, 0.05).unwrap();
        assert_eq!(w.eta_lower, f64::MAX);
        // With a failure, the estimate beyond f64 too (4000^100 x 5, about 1e360): none (an
        // infinity before, which JSON wrote as null all the same).
        let mut one = vec![(5.0, false); 3999];
        one.push((5.0, true));
        let w1 = weibayes(&Lives::from_pairs(&one).unwrap(), 0.01, 0.05).unwrap();
        assert_eq!((w1.failures, w1.eta, w1.eta_lower), (1, None, f64::MAX));
        let zero_failure = -(0.95f64).ln();
        for (p, bound) in [(0.01, w.b1_lower), (0.10, w.b10_lower)] {
            let expected = 200.0 * (100.0 * -(1.0f64 - p).ln() / zero_failure).powf(100.0);
            assert!(expected.is_finite() && expected > 1e100, "{expected:e}");
            assert_relative_eq!(bound, expected, max_relative = 1e-12);
        }
    }

    /// Chi-square quantiles against scipy's `chi2.ppf` (scipy 1.17.1).
    #[test]
    fn chi_square_quantiles_are_scipys() {
        for (p, m, scipy) in [
            (0.9, 2, 7.779440339734858),
            (0.9, 4, 13.36156613651173),
            (0.95, 11, 33.92443847144381),
            (0.5, 1, 1.386294361119891),
            (0.99, 51, 138.13447114967263),
            (0.9, 501, 1059.781202550823),
        ] {
            assert_relative_eq!(chi_square_quantile(p, m), scipy, max_relative = 1e-12);
        }
    }

    /// Far in either tail, against a 60-digit reference (`tools/chi_square_reference.py`, mpmath's
    /// regularised incomplete gamma of the tail that keeps its digits): near `p = 1` the quantile
    /// was 1 % low, a scale's lower bound 1 % high (the CDF as `1 - Q` loses the digits there), and
    /// at `p = 1e-300` 1e91 times too large.
    #[test]
    fn chi_square_quantiles_hold_far_in_both_tails() {
        for (p, m, reference) in [
            (0.9999999999999999, 2, 80.92313496617493),
            (0.999999999999, 2, 62.19979205810759),
            (0.99999999, 4, 53.16947819326714),
            (0.9999999999999999, 301, 932.6016458260909),
            (1e-300, 2, 2.8284271247461904e-150),
            (1e-300, 4, 4.426727678801287e-75),
            (1e-100, 4, 4.426727678801286e-25),
            (5e-324, 2, 6.286911138810515e-162),
            (0.5, 3, 5.348120627447121),
            (0.75, 1000, 2042.2873758143949),
        ] {
            let got = chi_square_quantile(p, m);
            assert_relative_eq!(got, reference, max_relative = 1e-13);
        }
    }

    /// With failures: the estimate is `(sum t^beta / r)^(1/beta)`; the bound lies below it and
    /// falls as the confidence rises; bad arguments are refused.
    #[test]
    fn failures_give_an_estimate_above_its_bound() {
        let lives =
            Lives::from_pairs(&[(300.0, true), (500.0, true), (800.0, false), (800.0, false)])
                .unwrap();
        let w = weibayes(&lives, 1.5, 0.9).unwrap();
        let sum = 300f64.powf(1.5) + 500f64.powf(1.5) + 2.0 * 800f64.powf(1.5);
        assert_relative_eq!(
            w.eta.unwrap(),
            (sum / 2.0).powf(1.0 / 1.5),
            max_relative = 1e-14
        );
        assert!(w.eta_lower < w.eta.unwrap());
        assert!(weibayes(&lives, 1.5, 0.99).unwrap().eta_lower < w.eta_lower);
        assert_eq!(weibayes(&lives, 0.0, 0.9), Err(WeibayesError::Shape(0.0)));
        assert_eq!(
            weibayes(&lives, 2.0, 1.0),
            Err(WeibayesError::Confidence(1.0))
        );
        assert_eq!(
            weibayes(&Lives::default(), 2.0, 0.9),
            Err(WeibayesError::NoLives)
        );
    }
}
