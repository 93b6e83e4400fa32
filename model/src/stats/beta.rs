//! The regularised incomplete beta function `I_x(a, b)` and its inverse in `x`, for real `a, b > 0`:
//! what Clopper and Pearson's interval needs at a fractional (effective) count
//! ([`super::intervals::proportion_interval`]).
//!
//! `I_x` is Lentz's evaluation of the continued fraction (Numerical Recipes 6.4), always from the
//! smaller parameter's side and from `x`'s end up to three standard deviations past the mean:
//! Numerical Recipes' rule (`I_x(a, b) = 1 - I_{1-x}(b, a)` beyond `x = (a + 1) / (a + b + 2)`)
//! loses up to five digits just past the mean when `b` is huge, the fraction's terms cancelling.
//! `ln B(a, b)` is free of the cancellation between `ln Γ(b)` and `ln Γ(a + b)` when `b` is huge
//! and `a` small (an effective count of a few events among 10^9 values). Against mpmath, over
//! counts of 0.1 to 100 among 10 to 10^12 values, `I_x` is within about `1e-10` of it, and the
//! fraction takes at most about 120 terms.

/// Iterations of the continued fraction: it converges within a few times `sqrt(min(a, b))` terms
/// where it is used; a proportion interval asks for `min(a, b) <= 101`.
const MAX_TERMS: u32 = 10_000;

/// `ln B(a, b) = ln Γ(a) + ln Γ(b) - ln Γ(a + b)`.
///
/// Where the larger argument is at least 1000, `ln Γ(large) - ln Γ(large + small)` comes from
/// Stirling's series, `-(x - 1/2) ln(1 + s/x) - s ln(x + s) + s + c(x) - c(x + s)` with
/// `c(z) = 1/(12 z) - 1/(360 z^3) + 1/(1260 z^5)` (its next term is below `1e-24` there), instead
/// of the difference of two numbers near `x ln x`.
pub fn ln_beta(a: f64, b: f64) -> f64 {
    let (small, large) = if a <= b { (a, b) } else { (b, a) };
    if large < 1000.0 {
        return libm::lgamma(a) + libm::lgamma(b) - libm::lgamma(a + b);
    }
    let c = |z: f64| {
        let r = 1.0 / (z * z);
        (1.0 / 12.0 - r * (1.0 / 360.0 - r / 1260.0)) / z
    };
    let sum = large + small;
    libm::lgamma(small) - (large - 0.5) * (small / large).ln_1p() - small * sum.ln()
        + small
        + (c(large) - c(sum))
}

/// The regularised incomplete beta function `I_x(a, b)`: the probability that a Beta(a, b) value
/// is at most `x`. `a, b > 0`; 0 for `x <= 0`, 1 for `x >= 1`.
pub fn regularized(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    both_tails(a, b, x, ln_beta(a, b)).0
}

/// `I_x(a, b)` and `1 - I_x(a, b)` for `x` in `(0, 1)`, each to its own precision, with
/// `ln_b = ln B(a, b)`.
fn both_tails(a: f64, b: f64, x: f64, ln_b: f64) -> (f64, f64) {
    if a <= b {
        tails(a, b, x, 1.0 - x, ln_b)
    } else {
        // From the smaller parameter's side: I_x(a, b) = 1 - I_{1-x}(b, a), its upper tail, which
        // keeps its digits where it is tiny.
        let (lower, upper) = tails(b, a, 1.0 - x, x, ln_b);
        (upper, lower)
    }
}

/// `I_x(a, b)` and `1 - I_x(a, b)` for `a <= b` and `y = 1 - x`, each to its own precision where it
/// is the one computed (the other is `1 -` it).
fn tails(a: f64, b: f64, x: f64, y: f64, ln_b: f64) -> (f64, f64) {
    // ln x and ln y from whichever of x, y is exact near 0.
    let ln_x = if x < 0.5 { x.ln() } else { (-y).ln_1p() };
    let ln_y = if y < 0.5 { y.ln() } else { (-x).ln_1p() };
    // x^a y^b / B(a, b), the factor in front of either continued fraction.
    let front = (a * ln_x + b * ln_y - ln_b).exp();
    // The fraction from x's end keeps its digits up to about three standard deviations past the
    // mean (1e-11 there) where the other end's cancels (b huge); further on it cancels itself
    // and its front underflows, and the other end's is the one to take (I within 1e-3 of 1).
    let near_mean = x < 0.1 && x * (a + b) <= a + 3.0 * (a.sqrt() + 1.0);
    if near_mean || x < (a + 1.0) / (a + b + 2.0) {
        let value = (front * continued_fraction(a, b, x, y) / a).clamp(0.0, 1.0);
        (value, 1.0 - value)
    } else {
        let rest = (front * continued_fraction(b, a, y, x) / b).clamp(0.0, 1.0);
        (1.0 - rest, rest)
    }
}

/// The probability density of Beta(a, b) at `x` in `(0, 1)`, with `ln_b = ln B(a, b)`.
fn density(a: f64, b: f64, x: f64, ln_b: f64) -> f64 {
    ((a - 1.0) * x.ln() + (b - 1.0) * (-x).ln_1p() - ln_b).exp()
}

/// The continued fraction of `I_x(a, b)` (Numerical Recipes' `betacf`, modified Lentz), with
/// `y = 1 - x` as the caller knows it: the first term, `1 - (a + b) x / (a + 1)`, is formed as
/// `(a y + 1 - b x) / (a + 1)`, which keeps its digits where `a x` and `b y` are both near 1.
fn continued_fraction(a: f64, b: f64, x: f64, y: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let guard = |v: f64| if v.abs() < TINY { TINY } else { v };
    let mut c = 1.0;
    let mut d = 1.0 / guard((a * y + 1.0 - b * x) / (a + 1.0));
    let mut h = d;
    for m in 1..=MAX_TERMS {
        let m = f64::from(m);
        let m2 = 2.0 * m;
        // The even step, then the odd one.
        let even = m * (b - m) * x / ((a - 1.0 + m2) * (a + m2));
        d = 1.0 / guard(1.0 + even * d);
        c = guard(1.0 + even / c);
        h *= d * c;
        let odd = -(a + m) * (a + b + m) * x / ((a + m2) * (a + 1.0 + m2));
        d = 1.0 / guard(1.0 + odd * d);
        c = guard(1.0 + odd / c);
        let step = d * c;
        h *= step;
        if (step - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// The `x` in `(0, 1)` with `I_x(a, b) = p`, for `0 < p < 1`, starting from `guess` in `(0, 1)`.
///
/// Newton's method on `ln x` for `ln I = ln p` (or `ln(1 - I) = ln(1 - p)` above the median),
/// nearly straight lines in the tails where the ends of an interval lie, so that a start from
/// Wilson's end takes a few steps; kept inside a bracket that every step narrows, with bisection
/// of `ln x` wherever Newton would leave it; to a relative `1e-11` in `x`, about the rounding of
/// `ln I` itself.
pub fn inverse_regularized(a: f64, b: f64, p: f64, guess: f64) -> f64 {
    let ln_b = ln_beta(a, b);
    let upper = p > 0.5;
    let target = if upper { (-p).ln_1p() } else { p.ln() };
    let (mut lo, mut hi) = (f64::MIN_POSITIVE.ln(), 0.0_f64);
    let mut t = guess.clamp(1e-300, 1.0 - 1e-16).ln();
    for _ in 0..200 {
        let x = t.exp();
        let (below, above) = both_tails(a, b, x, ln_b);
        // g(t) rises with t; d ln I / d ln x = x f(x) / I, d ln(1 - I) / d ln x = -x f(x) / (1 - I).
        let x_density = x * density(a, b, x, ln_b);
        let (gap, slope) = if upper {
            (target - above.ln(), x_density / above)
        } else {
            (below.ln() - target, x_density / below)
        };
        if gap < 0.0 {
            lo = t;
        } else {
            hi = t;
        }
        let step = gap / slope;
        // I's own rounding (about 1e-12 of ln I) moves Newton by as much: closer is noise.
        if step.abs() <= 1e-11 {
            return (t - step).exp();
        }
        let newton = t - step;
        let next = if newton.is_finite() && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if hi - lo <= 1e-11 {
            return next.exp();
        }
        t = next;
    }
    t.exp()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    /// `I_x(a, b)` at 30 digits by mpmath (`tools/beta_reference.py`): `(a, b, x, I)`.
    const REGULARIZED: [(f64, f64, f64, f64); 12] = [
        (0.3, 5.0, 0.1, 0.8108493913870337),
        (2.5, 7.5, 0.6, 0.9894932474135352),
        (50.0, 50.0, 0.5, 0.5),
        (0.5, 0.5, 0.999, 0.9798649583666225),
        (1.0, 1000000000000.0, 1e-12, 0.6321205588287416),
        (3.0, 1000000000.0, 3e-09, 0.57680992055347),
        (3.0, 1000000000.0, 1.2e-08, 0.9994777419871272),
        (101.0, 10000000.0, 1.1e-05, 0.8168115451596301),
        (101.0, 10000000.0, 8e-06, 0.013171691551735358),
        (0.001, 1000.0, 1e-05, 0.9959689153397295),
        (7.25, 2000.5, 0.01, 0.9996899009638072),
        (40.0, 1000000000000000.0, 2e-14, 5.320202511249495e-05),
    ];

    #[test]
    fn the_inverse_finds_the_root_from_any_start() {
        for (a, b, p) in [
            (10.0, 1991.0, 0.025),
            (0.4, 3e9, 0.025),
            (101.0, 1e12, 0.975),
        ] {
            let root = inverse_regularized(a, b, p, 0.5 * a / b);
            assert_relative_eq!(regularized(a, b, root), p, max_relative = 1e-10);
            for guess in [1e-300, 1e-12, 1e-3, 0.5, 1.0 - 1e-12] {
                let x = inverse_regularized(a, b, p, guess);
                assert!(
                    (x - root).abs() <= 1e-10 * root,
                    "I^-1({p}; {a}, {b}) from {guess}: {x}, from near: {root}"
                );
            }
        }
    }

    proptest! {
        #[test]
        fn regularized_is_a_distribution_function(
            a in 0.05..150.0_f64,
            log_b in 0.0..12.0_f64,
            u in 0.0..1.0_f64,
            v in 0.0..1.0_f64,
        ) {
            let b = 10.0_f64.powf(log_b);
            // Points around the mean a / (a + b), from far below to far above.
            let mean = a / (a + b);
            let at = |w: f64| (mean * 10.0_f64.powf(6.0 * w - 4.0)).min(1.0 - 1e-12);
            // Both x and 1 - x exact, for the mirror below.
            let exact = |x: f64| 1.0 - (1.0 - x);
            let (x, y) = (exact(at(u.min(v))), exact(at(u.max(v))));
            let (ix, iy) = (regularized(a, b, x), regularized(a, b, y));
            prop_assert!((0.0..=1.0).contains(&ix) && (0.0..=1.0).contains(&iy));
            prop_assert!(ix <= iy + 1e-12, "I({x}) = {ix} > I({y}) = {iy}");
            // I_x(a, b) + I_{1-x}(b, a) = 1.
            let mirror = regularized(b, a, 1.0 - x);
            prop_assert!((ix + mirror - 1.0).abs() <= 1e-9, "{ix} + {mirror}");
        }
    }

    #[test]
    fn regularized_matches_the_reference() {
        for (a, b, x, want) in REGULARIZED {
            let got = regularized(a, b, x);
            assert!(
                (got - want).abs() <= 1e-9 * want.min(1.0 - want),
                "I_{x}({a}, {b}) = {got}, reference {want}"
            );
        }
    }
}
