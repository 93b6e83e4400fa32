//! Likelihood-ratio bounds on a Weibull B-life (Meeker & Escobar, *Statistical Methods for
//! Reliability Data*, 8.3; Weibull++'s "likelihood ratio bounds"): the times `t` at which the
//! profile log-likelihood of `B_p`,
//!
//! `l_p(t) = max_beta ln L(beta, eta = t / k^(1/beta))`, `k = -ln(1 - p)`,
//!
//! lies `chi2(0.95; 1) / 2` below the maximum. Unlike the Fisher-matrix bounds they need no
//! normal approximation of `ln B_p`, so they stay honest with few failures and heavy censoring,
//! where the likelihood is far from quadratic; with many failures the two agree.
//!
//! The inner maximum is found by golden-section search on `ln beta` (the profile is unimodal
//! there), each crossing by doubling a step away from `ln B_p` until the profile falls below the
//! level, then bisection on `ln t`.

use super::{Lives, LivesAt, Weibull, log_likelihood};

/// Half the 95 % quantile of chi-square with one degree of freedom: the drop of the
/// log-likelihood at the bounds.
const HALF_CHI2_95_1: f64 = 3.841_458_820_694_124 / 2.0;

/// 95 % likelihood-ratio bounds `[lower, upper]` on `B_p` of the Weibull `w` fitted to `lives`;
/// `None` when `p` is not in `(0, 1)` or a crossing cannot be found in finite numbers.
pub fn b_life_lr_bounds(lives: &Lives, w: &Weibull, p: f64) -> Option<[f64; 2]> {
    if !(p > 0.0 && p < 1.0) {
        return None;
    }
    let at = lives.at();
    let ln_k = (-(-p).ln_1p()).ln();
    let ln_beta = w.beta.ln();
    let top = log_likelihood(at, w.beta, w.eta);
    let level = top - HALF_CHI2_95_1;
    let centre = w.eta.ln() + ln_k / w.beta;
    if !(top.is_finite() && centre.is_finite()) {
        return None;
    }
    let profile = |ln_t: f64| profile(at, ln_t, ln_k, ln_beta);
    let mut bounds = [0.0; 2];
    for (bound, side) in bounds.iter_mut().zip([-1.0, 1.0]) {
        let mut step = 0.01;
        let mut far = centre + side * step;
        while profile(far) > level {
            step *= 2.0;
            far = centre + side * step;
            if step > 200.0 {
                return None;
            }
        }
        // `near` above the level, `far` below it.
        let mut near = centre;
        for _ in 0..200 {
            let mid = 0.5 * (near + far);
            if profile(mid) > level {
                near = mid;
            } else {
                far = mid;
            }
            if (far - near).abs() <= 1e-13 * (1.0 + mid.abs()) {
                break;
            }
        }
        *bound = (0.5 * (near + far)).exp();
    }
    bounds
        .iter()
        .all(|b| b.is_finite() && *b > 0.0)
        .then_some(bounds)
}

/// `l_p` at `ln t`: the log-likelihood maximised over `ln beta` within 6 of the fit's, by
/// golden-section search.
fn profile(at: &[LivesAt], ln_t: f64, ln_k: f64, ln_beta: f64) -> f64 {
    let at_shape = |u: f64| {
        let beta = u.exp();
        let value = log_likelihood(at, beta, (ln_t - ln_k / beta).exp());
        if value.is_nan() {
            f64::NEG_INFINITY
        } else {
            value
        }
    };
    let ratio = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (ln_beta - 6.0, ln_beta + 6.0);
    let mut c = b - ratio * (b - a);
    let mut d = a + ratio * (b - a);
    let (mut fc, mut fd) = (at_shape(c), at_shape(d));
    for _ in 0..200 {
        if fc >= fd {
            b = d;
            d = c;
            fd = fc;
            c = b - ratio * (b - a);
            fc = at_shape(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + ratio * (b - a);
            fd = at_shape(d);
        }
        if b - a <= 1e-12 {
            break;
        }
    }
    fc.max(fd)
}
