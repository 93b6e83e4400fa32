//! Which distribution the lives follow: the two- and three-parameter Weibull, the lognormal, the
//! gamma and the exponential, each fitted by maximum likelihood with right censoring to the same
//! lives, and ranked by AICc (then BIC). The likelihoods are densities in time for all five, so
//! they compare.
//!
//! - Exponential: `lambda = r / T`, `r` the failures and `T` the total time on test.
//! - Lognormal (`mu`, `sigma` of `ln t`): Newton's method on `(mu, ln sigma)` with the analytic
//!   gradient and Hessian, a step halved until the likelihood rises; the survival terms go through
//!   `erfc` and the hazard `phi / (1 - Phi)`, both finite in the far tail.
//! - Gamma (`shape` k, `scale` theta): Nelder-Mead on `(ln k, ln theta)` from the failures'
//!   moments, restarted at its own optimum until it stays, then Newton's steps in `(ln k, ln
//!   mean)` (`newton_polish`) for the parameters on a flat ridge; the survival terms are
//!   `ln Q(k, t / theta)`, the regularised upper incomplete gamma function in logs
//!   (`weibayes::regularized_gamma`).
//! - Weibull: the fit of [`super::fit_weibull_lives`], with the log-likelihood it reports.
//! - Three-parameter Weibull (`beta`, `eta` and the failure-free life `gamma`): the profile
//!   likelihood's maximum in `gamma` ([`super::location`]); absent where the likelihood has no
//!   maximum inside `(0, t_1)`.
//!
//! `AICc = 2k - 2 ln L + 2k(k + 1)/(n - k - 1)`, `BIC = k ln n - 2 ln L`, `n` the devices; and
//! each fit's goodness of fit, the adjusted Anderson-Darling statistic ([`anderson_darling`]).

use super::{Lives, LivesAt, Weibull};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A candidate distribution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Family {
    Weibull,
    #[serde(rename = "weibull_3p")]
    Weibull3p,
    Lognormal,
    Gamma,
    Exponential,
}

impl Family {
    pub fn name(self) -> &'static str {
        match self {
            Family::Weibull => "weibull",
            Family::Weibull3p => "weibull_3p",
            Family::Lognormal => "lognormal",
            Family::Gamma => "gamma",
            Family::Exponential => "exponential",
        }
    }

    /// The parameters it has.
    fn parameters(self) -> f64 {
        match self {
            Family::Exponential => 1.0,
            Family::Weibull | Family::Lognormal | Family::Gamma => 2.0,
            Family::Weibull3p => 3.0,
        }
    }
}

/// One distribution fitted to the lives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fit {
    pub distribution: Family,
    /// By name: `beta` and `eta` (Weibull; with `gamma`, the failure-free life, for the
    /// three-parameter Weibull), `mu` and `sigma` of the log of the life (lognormal),
    /// `shape` and `scale` (gamma, mean `shape * scale`), `lambda` failures per operation
    /// (exponential).
    pub parameters: BTreeMap<String, f64>,
    /// The maximised log-likelihood, a density in time.
    pub log_likelihood: f64,
    /// Akaike's criterion with the small-sample correction (lower is better); `None` with fewer
    /// than `k + 2` devices.
    pub aicc: Option<f64>,
    /// The Bayesian information criterion (lower is better).
    pub bic: f64,
    /// The Anderson-Darling statistic of the failures against the fitted CDF, adjusted for
    /// censoring as Minitab and the `reliability` package compute it ([`anderson_darling`]): lower
    /// fits better; `None` when it is not finite.
    #[serde(default)]
    pub anderson_darling: Option<f64>,
}

impl Fit {
    /// The fitted CDF at `t > 0`.
    pub fn cdf(&self, t: f64) -> f64 {
        let parameters: Vec<(&str, f64)> = self
            .parameters
            .iter()
            .map(|(n, &v)| (n.as_str(), v))
            .collect();
        cdf(self.distribution, &parameters, t)
    }
}

/// How much lower another distribution's AICc must be than the Weibull's for the analysis to
/// warn that the Weibull fits worse (Burnham & Anderson: a difference above 2 is support).
pub const AICC_SUPPORT: f64 = 2.0;

/// Every candidate that can be fitted, best first by AICc (BIC where AICc is undefined, then the
/// name). The Weibull's is `weibull` as already fitted.
pub fn fits(lives: &Lives, weibull: Option<&Weibull>) -> Vec<Fit> {
    let devices = (lives.failures() + lives.censored()) as f64;
    let mut found = Vec::new();
    let positions = failure_positions(lives);
    let failures = lives.failures();
    let mut add = |family: Family, parameters: Vec<(&str, f64)>, log_likelihood: f64| {
        if !log_likelihood.is_finite() {
            return;
        }
        let anderson_darling =
            anderson_darling(&positions, failures, |t| cdf(family, &parameters, t));
        let k = family.parameters();
        let aicc = (devices - k - 1.0 > 0.0)
            .then(|| 2.0 * k - 2.0 * log_likelihood + 2.0 * k * (k + 1.0) / (devices - k - 1.0));
        found.push(Fit {
            distribution: family,
            parameters: parameters
                .into_iter()
                .map(|(n, v)| (n.to_owned(), v))
                .collect(),
            log_likelihood,
            aicc,
            bic: k * devices.ln() - 2.0 * log_likelihood,
            anderson_darling,
        });
    };
    if let Some(w) = weibull {
        add(
            Family::Weibull,
            vec![("beta", w.beta), ("eta", w.eta)],
            w.log_likelihood,
        );
    }
    if let Some(w) = super::location::fit_weibull_3p(lives) {
        add(
            Family::Weibull3p,
            vec![("beta", w.beta), ("eta", w.eta), ("gamma", w.gamma)],
            w.log_likelihood,
        );
    }
    if let Some((mu, sigma, ll)) = fit_lognormal(lives.at()) {
        add(Family::Lognormal, vec![("mu", mu), ("sigma", sigma)], ll);
    }
    if let Some((shape, scale, ll)) = fit_gamma(lives.at()) {
        add(Family::Gamma, vec![("shape", shape), ("scale", scale)], ll);
    }
    if let Some((lambda, ll)) = fit_exponential(lives.at()) {
        add(Family::Exponential, vec![("lambda", lambda)], ll);
    }
    found.sort_by(|a, b| {
        let key = |f: &Fit| f.aicc.unwrap_or(f.bic);
        key(a)
            .total_cmp(&key(b))
            .then(a.distribution.cmp(&b.distribution))
    });
    found
}

/// The CDF of `family` with `parameters` (named as in [`Fit::parameters`]) at `t > 0`.
fn cdf(family: Family, parameters: &[(&str, f64)], t: f64) -> f64 {
    let get = |name: &str| {
        parameters
            .iter()
            .find(|(n, _)| *n == name)
            .map_or(f64::NAN, |&(_, v)| v)
    };
    match family {
        Family::Weibull => -(-(t / get("eta")).powf(get("beta"))).exp_m1(),
        Family::Weibull3p => super::location::cdf(get("beta"), get("eta"), get("gamma"), t),
        Family::Lognormal => {
            let z = (t.ln() - get("mu")) / get("sigma");
            0.5 * libm::erfc(-z / std::f64::consts::SQRT_2)
        }
        Family::Gamma => super::weibayes::regularized_gamma(get("shape"), t / get("scale")).0,
        Family::Exponential => -(-get("lambda") * t).exp_m1(),
    }
}

/// Each distinct failure time, in order, with the median-rank plotting position of its last
/// failure: Johnson's adjusted rank `j = j' + (n + 1 - j') / (1 + r)` (`r` still at risk, the
/// failure included; the failures at a time before the devices censored then), failure by
/// failure, and Bernard's `(j - 0.3) / (n + 0.4)` (as `super::median_ranks`). One entry a time,
/// not a failure: a job of 10^8 devices failing at a few hundred distinct operations keeps a few
/// hundred (a failure each took 32 bytes and more, 90 MB for 2 million devices).
fn failure_positions(lives: &Lives) -> Vec<(f64, f64)> {
    let n = (lives.failures() + lives.censored()) as f64;
    let mut at_risk = n;
    let mut rank = 0.0;
    let mut positions = Vec::new();
    for a in lives.at() {
        for k in 0..a.failures {
            rank += (n + 1.0 - rank) / (1.0 + at_risk - k as f64);
        }
        if a.failures > 0 {
            positions.push((a.time, (rank - 0.3) / (n + 0.4)));
        }
        at_risk -= a.devices();
    }
    positions
}

/// The adjusted Anderson-Darling statistic of Minitab and the `reliability` package (its
/// `Utils.anderson_darling`): with `Z_i` the fitted CDF at the `n` failures in order, `Z_{n+1} =
/// 1 - 1e-12`, `Z_0 = 0`, and `F_i` the plotting positions (`F_0 = 0`),
///
/// `AD = n sum_{i=1}^{n+1} [-Z_i - ln(1 - Z_i) + Z_{i-1} + ln(1 - Z_{i-1})
///       + 2 F_{i-1} (ln(1 - Z_i) - ln(1 - Z_{i-1}))
///       + F_{i-1}^2 (ln Z_i - ln(1 - Z_i) - ln Z_{i-1} + ln(1 - Z_{i-1}))]`
///
/// with `ln Z_0` taken as 0. `None` without failures or when the CDF is not a number. The
/// `failures` come as `positions`, one entry per distinct time with the position of its last
/// failure (`failure_positions`): the terms of a tie's later failures are zero (`Z_i =
/// Z_{i-1}`), so each time adds one term, with the `F` of the failure before it.
pub fn anderson_darling(
    positions: &[(f64, f64)],
    failures: u64,
    cdf: impl Fn(f64) -> f64,
) -> Option<f64> {
    if positions.is_empty() {
        return None;
    }
    // A fit far off puts failures at `Z = 0` or `1`, where the logs are infinite: held inside
    // `[MIN_POSITIVE, 1 - 1e-12]`, the statistic stays finite and large.
    let mut z: Vec<f64> = positions
        .iter()
        .map(|&(t, _)| cdf(t).clamp(f64::MIN_POSITIVE, 1.0 - 1e-12))
        .collect();
    z.sort_by(f64::total_cmp);
    z.push(1.0 - 1e-12);
    let mut f: Vec<f64> = positions.iter().map(|&(_, p)| p).collect();
    f.sort_by(f64::total_cmp);
    let (mut previous_z, mut previous_ln_z, mut previous_f) = (0.0f64, 0.0f64, 0.0f64);
    let mut sum = 0.0;
    for (i, &zi) in z.iter().enumerate() {
        let (ln_survival, previous_ln_survival) = ((-zi).ln_1p(), (-previous_z).ln_1p());
        let ln_z = zi.ln();
        sum += -zi - ln_survival
            + previous_z
            + previous_ln_survival
            + 2.0 * previous_f * (ln_survival - previous_ln_survival)
            + previous_f * previous_f * (ln_z - ln_survival - previous_ln_z + previous_ln_survival);
        (previous_z, previous_ln_z) = (zi, ln_z);
        if let Some(&fi) = f.get(i) {
            previous_f = fi;
        }
    }
    let ad = failures as f64 * sum;
    ad.is_finite().then_some(ad)
}

/// The distribution that fits the lives clearly better than the Weibull by AICc (by more than
/// [`AICC_SUPPORT`]), with its AICc's lead, if one does. The exponential is never that one: it is
/// the Weibull of shape 1, so it wins by AICc only through its one parameter fewer (by up to about
/// 2.04, when the Weibull's shape comes out near 1, in 16 % of exponential samples), and the
/// Weibull's B-lives then have the very shape the lives have.
pub fn better_than_weibull(fits: &[Fit]) -> Option<(&Fit, f64)> {
    let best = fits
        .iter()
        .find(|fit| fit.distribution != Family::Exponential)?;
    let weibull = fits.iter().find(|f| f.distribution == Family::Weibull)?;
    let difference = weibull.aicc? - best.aicc?;
    (difference > AICC_SUPPORT).then_some((best, difference))
}

/// The warning that [`better_than_weibull`] found a better fit.
pub fn weibull_warning(fits: &[Fit]) -> Option<String> {
    better_than_weibull(fits).map(|(best, difference)| {
        format!(
            "the {} fits these lives better than the two-parameter Weibull (AICc lower by {difference:.1}): \
             the Weibull's B-lives extrapolate a shape the lives do not have",
            best.distribution.name()
        )
    })
}

/// The exponential's maximum: `lambda = r / T` and `r ln lambda - lambda T`; none without failures.
fn fit_exponential(at: &[LivesAt]) -> Option<(f64, f64)> {
    let failures: f64 = at.iter().map(|a| a.failures as f64).sum();
    let time_on_test: f64 = at.iter().map(|a| a.devices() * a.time).sum();
    (failures > 0.0 && time_on_test > 0.0).then(|| {
        let lambda = failures / time_on_test;
        (lambda, failures * lambda.ln() - failures)
    })
}

/// The gamma log-likelihood of the lives at shape `e^u` and scale `e^v`.
fn gamma_log_likelihood(at: &[LivesAt], u: f64, v: f64) -> f64 {
    let (shape, scale) = (u.exp(), v.exp());
    let ln_gamma = libm::lgamma(shape);
    at.iter()
        .map(|a| {
            let x = a.time / scale;
            let mut ll = 0.0;
            if a.failures > 0 {
                ll += a.failures as f64 * ((shape - 1.0) * a.time.ln() - x - shape * v - ln_gamma);
            }
            if a.censored > 0 {
                ll += a.censored as f64 * super::weibayes::regularized_gamma(shape, x).1;
            }
            ll
        })
        .sum()
}

/// The gamma's maximum `(shape, scale, ln L)`; none with fewer than two distinct failure times
/// or if the search does not settle.
fn fit_gamma(at: &[LivesAt]) -> Option<(f64, f64, f64)> {
    // Start from the failures' moments: shape mean^2 / variance, scale variance / mean.
    let (mean, variance) = failure_moments(at, |t| t)?;
    let variance = variance.max(1e-12 * mean * mean);
    let start = [(mean * mean / variance).ln(), (variance / mean).ln()];
    let negative = |x: &[f64; 2]| {
        let ll = gamma_log_likelihood(at, x[0], x[1]);
        if ll.is_finite() { -ll } else { f64::INFINITY }
    };
    let mut best = nelder_mead(&negative, start, 0.5);
    for _ in 0..10 {
        let again = nelder_mead(&negative, best.0, 0.05);
        let settled = (again.1 - best.1).abs() <= 1e-13 * best.1.abs().max(1.0);
        best = again;
        if settled {
            break;
        }
    }
    // On a flat ridge (a few failures close together: a large shape) the simplex settles on the
    // log-likelihood's last digits while the parameters are still 1e-6 off its maximum; Newton's
    // steps finish the search in the parameters, in `(ln shape, ln mean)`, where the ridge runs
    // along the first axis and the mean, sharply determined, along the second.
    let [u, v] = best.0;
    let ll = |y: [f64; 2]| gamma_log_likelihood(at, y[0], y[1] - y[0]);
    let [u, w] = newton_polish(&ll, [u, u + v]);
    let v = w - u;
    let value = -gamma_log_likelihood(at, u, v);
    (value.is_finite() && u.abs() < 700.0 && v.abs() < 700.0).then(|| (u.exp(), v.exp(), -value))
}

/// Newton's method for the maximum of `ll` from `x`, near it already: gradient and Hessian by
/// central differences, each axis's step sized to its curvature (a change of `ll` of about
/// 1e-8 across it, so that neither the rounding of `ll` nor its third derivative blurs the
/// slope); a step is taken while it shrinks the gradient without lowering `ll` beyond its
/// rounding. Where the Hessian is not negative definite, `x` as it is.
fn newton_polish(ll: &dyn Fn([f64; 2]) -> f64, mut x: [f64; 2]) -> [f64; 2] {
    let centre = ll(x);
    let steps = [0, 1].map(|i| {
        let probe = 1e-4;
        let at = |d: f64| {
            let mut y = x;
            y[i] += d;
            ll(y)
        };
        let curvature = ((at(probe) - 2.0 * centre + at(-probe)) / (probe * probe)).abs();
        (1e-8 / curvature.max(1e-8)).sqrt().clamp(1e-7, 1e-3)
    });
    let derivatives = |x: [f64; 2]| {
        let at = |a: f64, b: f64| ll([x[0] + a * steps[0], x[1] + b * steps[1]]);
        let centre = at(0.0, 0.0);
        let g = [
            (at(1.0, 0.0) - at(-1.0, 0.0)) / (2.0 * steps[0]),
            (at(0.0, 1.0) - at(0.0, -1.0)) / (2.0 * steps[1]),
        ];
        let uu = (at(1.0, 0.0) - 2.0 * centre + at(-1.0, 0.0)) / (steps[0] * steps[0]);
        let vv = (at(0.0, 1.0) - 2.0 * centre + at(0.0, -1.0)) / (steps[1] * steps[1]);
        let uv = (at(1.0, 1.0) - at(1.0, -1.0) - at(-1.0, 1.0) + at(-1.0, -1.0))
            / (4.0 * steps[0] * steps[1]);
        (centre, g, [[uu, uv], [uv, vv]])
    };
    let norm = |g: [f64; 2]| g[0].hypot(g[1]);
    let (mut value, mut g, mut h) = derivatives(x);
    for _ in 0..8 {
        let det = h[0][0] * h[1][1] - h[0][1] * h[1][0];
        if !(det.is_finite() && det > 0.0 && h[0][0] < 0.0) {
            break;
        }
        let step = [
            -(h[1][1] * g[0] - h[0][1] * g[1]) / det,
            -(h[0][0] * g[1] - h[1][0] * g[0]) / det,
        ];
        let next = [x[0] + step[0], x[1] + step[1]];
        let (next_value, next_g, next_h) = derivatives(next);
        let rounding = 1e-12 * value.abs().max(1.0);
        if !(norm(next_g) < norm(g) && next_value >= value - rounding) {
            break;
        }
        (x, value, g, h) = (next, next_value, next_g, next_h);
    }
    x
}

/// The mean and variance of `of(t)` over the failures; none with fewer than two distinct failure
/// times, where neither two-parameter fit has a maximum.
fn failure_moments(at: &[LivesAt], of: fn(f64) -> f64) -> Option<(f64, f64)> {
    let failed: Vec<&LivesAt> = at.iter().filter(|a| a.failures > 0).collect();
    if failed.len() < 2 {
        return None;
    }
    let r: f64 = failed.iter().map(|a| a.failures as f64).sum();
    let mean = failed
        .iter()
        .map(|a| a.failures as f64 * of(a.time))
        .sum::<f64>()
        / r;
    let variance = failed
        .iter()
        .map(|a| a.failures as f64 * (of(a.time) - mean).powi(2))
        .sum::<f64>()
        / r;
    Some((mean, variance))
}

/// The minimum of `f` by Nelder-Mead (standard coefficients) from `start` with a simplex of
/// `step` along each axis, until the simplex is within `1e-12` across: `(x, f(x))`.
fn nelder_mead(f: &dyn Fn(&[f64; 2]) -> f64, start: [f64; 2], step: f64) -> ([f64; 2], f64) {
    let mut simplex = [
        start,
        [start[0] + step, start[1]],
        [start[0], start[1] + step],
    ];
    let mut values = simplex.map(|x| f(&x));
    for _ in 0..20_000 {
        let mut order = [0, 1, 2];
        order.sort_by(|&i, &j| values[i].total_cmp(&values[j]));
        simplex = order.map(|i| simplex[i]);
        values = order.map(|i| values[i]);
        let size = (1..3)
            .map(|i| {
                (simplex[i][0] - simplex[0][0])
                    .abs()
                    .max((simplex[i][1] - simplex[0][1]).abs())
            })
            .fold(0.0, f64::max);
        if size <= 1e-12 {
            break;
        }
        let centroid = [
            0.5 * (simplex[0][0] + simplex[1][0]),
            0.5 * (simplex[0][1] + simplex[1][1]),
        ];
        let along = |t: f64| {
            [
                centroid[0] + t * (simplex[2][0] - centroid[0]),
                centroid[1] + t * (simplex[2][1] - centroid[1]),
            ]
        };
        let reflected = along(-1.0);
        let fr = f(&reflected);
        if fr < values[0] {
            let expanded = along(-2.0);
            let fe = f(&expanded);
            (simplex[2], values[2]) = if fe < fr {
                (expanded, fe)
            } else {
                (reflected, fr)
            };
        } else if fr < values[1] {
            (simplex[2], values[2]) = (reflected, fr);
        } else {
            let contracted = if fr < values[2] {
                along(-0.5)
            } else {
                along(0.5)
            };
            let fc = f(&contracted);
            if fc < values[2].min(fr) {
                (simplex[2], values[2]) = (contracted, fc);
            } else {
                for i in 1..3 {
                    simplex[i] = [
                        simplex[0][0] + 0.5 * (simplex[i][0] - simplex[0][0]),
                        simplex[0][1] + 0.5 * (simplex[i][1] - simplex[0][1]),
                    ];
                    values[i] = f(&simplex[i]);
                }
            }
        }
    }
    (simplex[0], values[0])
}

/// `ln(1 - Phi(z))`, finite for every finite `z` (the asymptotic series where `erfc` underflows).
fn ln_survival(z: f64) -> f64 {
    if z < 37.0 {
        (0.5 * libm::erfc(z / std::f64::consts::SQRT_2)).ln()
    } else {
        let z2 = z * z;
        -0.5 * z2 - (z * (2.0 * std::f64::consts::PI).sqrt()).ln()
            + (1.0 - 1.0 / z2 + 3.0 / (z2 * z2)).ln()
    }
}

/// The standard normal hazard `phi(z) / (1 - Phi(z))`.
fn hazard(z: f64) -> f64 {
    (-0.5 * z * z - 0.5 * (2.0 * std::f64::consts::PI).ln() - ln_survival(z)).exp()
}

/// The lognormal log-likelihood of the lives at `(mu, ln sigma)`, its gradient and Hessian.
fn lognormal_terms(at: &[LivesAt], mu: f64, ln_sigma: f64) -> (f64, [f64; 2], [[f64; 2]; 2]) {
    let sigma = ln_sigma.exp();
    let (mut ll, mut g, mut h) = (0.0, [0.0; 2], [[0.0; 2]; 2]);
    for a in at {
        let y = a.time.ln();
        let z = (y - mu) / sigma;
        let (r, c) = (a.failures as f64, a.censored as f64);
        if r > 0.0 {
            ll += r * (-0.5 * z * z - ln_sigma - y - 0.5 * (2.0 * std::f64::consts::PI).ln());
            g[0] += r * z / sigma;
            g[1] += r * (z * z - 1.0);
            h[0][0] -= r / (sigma * sigma);
            h[0][1] -= r * 2.0 * z / sigma;
            h[1][1] -= r * 2.0 * z * z;
        }
        if c > 0.0 {
            let hz = hazard(z);
            let curvature = -hz * (hz - z); // d^2 ln S / dz^2
            ll += c * ln_survival(z);
            g[0] += c * hz / sigma;
            g[1] += c * hz * z;
            h[0][0] += c * curvature / (sigma * sigma);
            h[0][1] += c * (curvature * z - hz) / sigma;
            h[1][1] += c * (curvature * z * z - hz * z);
        }
    }
    h[1][0] = h[0][1];
    (ll, g, h)
}

/// The lognormal's maximum `(mu, sigma, ln L)`; none with fewer than two distinct failure times
/// (then `sigma` runs to 0) or if Newton's method does not settle.
fn fit_lognormal(at: &[LivesAt]) -> Option<(f64, f64, f64)> {
    // Start from the failures' log times: their mean and standard deviation.
    let (mean, variance) = failure_moments(at, f64::ln)?;
    let r: f64 = at.iter().map(|a| a.failures as f64).sum();
    let (mut mu, mut ln_sigma) = (mean, 0.5 * variance.max(1e-12).ln());
    let (mut ll, mut g, mut h) = lognormal_terms(at, mu, ln_sigma);
    for _ in 0..200 {
        let det = h[0][0] * h[1][1] - h[0][1] * h[1][0];
        // Newton where the Hessian is negative definite, else a gradient step.
        let step = if h[0][0] < 0.0 && det > 0.0 {
            [
                -(h[1][1] * g[0] - h[0][1] * g[1]) / det,
                -(h[0][0] * g[1] - h[1][0] * g[0]) / det,
            ]
        } else {
            let scale = 0.1 / (g[0].abs() + g[1].abs()).max(1.0);
            [g[0] * scale, g[1] * scale]
        };
        let mut length = 1.0;
        let moved = loop {
            let (m, s) = (mu + length * step[0], ln_sigma + length * step[1]);
            let next = lognormal_terms(at, m, s);
            if next.0.is_finite() && next.0 >= ll {
                break Some((m, s, next));
            }
            length *= 0.5;
            if length < 1e-12 {
                break None;
            }
        };
        let Some((m, s, next)) = moved else {
            break;
        };
        let settled = (m - mu).abs() <= 1e-13 * mu.abs().max(1.0) && (s - ln_sigma).abs() <= 1e-13;
        (mu, ln_sigma, (ll, g, h)) = (m, s, next);
        if settled {
            break;
        }
    }
    let converged =
        g[0].abs() * ln_sigma.exp() <= 1e-6 * r.max(1.0) && g[1].abs() <= 1e-6 * r.max(1.0);
    (converged && ll.is_finite()).then(|| (mu, ln_sigma.exp(), ll))
}

#[cfg(test)]
mod tests {
    use super::super::{Lives, fit_weibull_lives};
    use super::*;
    use approx::assert_relative_eq;

    /// A few failures close together and many devices censored just after make the gamma's
    /// likelihood a flat ridge: the manual's wear job at 887 operations (3 failures at 874, 881
    /// and 886 of 300 devices, 297 censored at 887; a shape near 2200), where the simplex stopped
    /// 1.9e-6 off the maximum (found by an audit). The maximum by `tools/gamma_ridge_reference.py`
    /// (mpmath, 40 digits, Newton on the exact score); Newton's steps after the simplex come to
    /// 3.7e-7 of it, where this module's log-likelihood, 4e-12 off mpmath's (its incomplete gamma
    /// at a shape of 2200), has its own maximum.
    #[test]
    fn the_gamma_on_a_flat_ridge_is_at_its_maximum() {
        let mut pairs = vec![(874.0, true), (881.0, true), (886.0, true)];
        pairs.extend(std::iter::repeat_n((887.0, false), 297));
        let lives = Lives::from_pairs(&pairs).unwrap();
        let (shape, scale, _) = fit_gamma(lives.at()).unwrap();
        assert_relative_eq!(shape, 2212.3732317487326, max_relative = 5e-7);
        assert_relative_eq!(scale, 0.4214802166799046, max_relative = 5e-7);
    }

    /// The lognormal's gradient and Hessian against central differences of its log-likelihood.
    #[test]
    fn the_lognormal_derivatives_are_those_of_its_likelihood() {
        let lives = Lives::from_pairs(&[
            (120.0, true),
            (190.0, true),
            (250.0, false),
            (310.0, true),
            (400.0, false),
            (900.0, false),
        ])
        .unwrap();
        let (mu, ln_sigma, step) = (5.4, -0.3, 1e-5);
        let ll = |m: f64, s: f64| lognormal_terms(lives.at(), m, s).0;
        let grad = |m: f64, s: f64| lognormal_terms(lives.at(), m, s).1;
        let (_, g, h) = lognormal_terms(lives.at(), mu, ln_sigma);
        let numeric_g = [
            (ll(mu + step, ln_sigma) - ll(mu - step, ln_sigma)) / (2.0 * step),
            (ll(mu, ln_sigma + step) - ll(mu, ln_sigma - step)) / (2.0 * step),
        ];
        for i in 0..2 {
            assert_relative_eq!(g[i], numeric_g[i], max_relative = 1e-6);
        }
        let numeric_h = [
            [
                (grad(mu + step, ln_sigma)[0] - grad(mu - step, ln_sigma)[0]) / (2.0 * step),
                (grad(mu, ln_sigma + step)[0] - grad(mu, ln_sigma - step)[0]) / (2.0 * step),
            ],
            [
                (grad(mu + step, ln_sigma)[1] - grad(mu - step, ln_sigma)[1]) / (2.0 * step),
                (grad(mu, ln_sigma + step)[1] - grad(mu, ln_sigma - step)[1]) / (2.0 * step),
            ],
        ];
        for i in 0..2 {
            for j in 0..2 {
                assert_relative_eq!(h[i][j], numeric_h[i][j], max_relative = 1e-5);
            }
        }
    }

    /// The far tail of the survival function: `ln(1 - Phi(z))` is continuous where the series
    /// takes over from `erfc`, and the hazard approaches `z`.
    #[test]
    fn the_survival_stays_finite_in_the_far_tail() {
        assert_relative_eq!(
            ln_survival(36.999_999),
            ln_survival(37.0),
            max_relative = 1e-6
        );
        assert_relative_eq!(ln_survival(0.0), 0.5f64.ln(), max_relative = 1e-15);
        assert!(ln_survival(1e3).is_finite());
        assert_relative_eq!(hazard(60.0), 60.0, max_relative = 1e-3);
        assert_relative_eq!(hazard(-40.0), 0.0, epsilon = 1e-300);
    }

    /// Without two distinct failure times the lognormal has no maximum; the exponential needs one
    /// failure; no candidate at all for no failures.
    #[test]
    fn too_few_failures_leave_candidates_out() {
        let one = Lives::from_pairs(&[(100.0, true), (200.0, false), (300.0, false)]).unwrap();
        let found: Vec<Family> = fits(&one, None).iter().map(|f| f.distribution).collect();
        assert_eq!(found, [Family::Exponential]);
        let none = Lives::from_pairs(&[(100.0, false), (200.0, false)]).unwrap();
        assert!(fits(&none, None).is_empty());
        let weibull = fit_weibull_lives(&one).ok();
        assert!(weibull.is_none() || fits(&one, weibull.as_ref()).len() <= 2);
    }

    /// A clearly lognormal sample (its log times evenly spread quantiles of a normal) ranks the
    /// lognormal first and warns that the Weibull fits worse; a Weibull sample does not warn.
    #[test]
    fn a_lognormal_sample_ranks_the_lognormal_first_and_warns() {
        let normal = |p: f64| crate::montecarlo::distribution::standard_normal_quantile(p);
        let lognormal: Vec<(f64, bool)> = (1..=200)
            .map(|i| ((5.0 + 1.2 * normal((i as f64 - 0.5) / 200.0)).exp(), true))
            .collect();
        let lives = Lives::from_pairs(&lognormal).unwrap();
        let weibull = fit_weibull_lives(&lives).unwrap();
        let ranked = fits(&lives, Some(&weibull));
        assert_eq!(ranked[0].distribution, Family::Lognormal);
        assert_relative_eq!(ranked[0].parameters["mu"], 5.0, max_relative = 1e-3);
        assert!(
            weibull_warning(&ranked)
                .unwrap()
                .contains("lognormal fits these lives better")
        );
        let weibull_sample: Vec<(f64, bool)> = (1..=200)
            .map(|i| {
                (
                    1000.0 * (-(1.0 - (i as f64 - 0.5) / 200.0).ln()).powf(1.0 / 2.0),
                    true,
                )
            })
            .collect();
        let lives = Lives::from_pairs(&weibull_sample).unwrap();
        let weibull = fit_weibull_lives(&lives).unwrap();
        let ranked = fits(&lives, Some(&weibull));
        assert_eq!(ranked[0].distribution, Family::Weibull);
        assert_eq!(weibull_warning(&ranked), None);
    }

    /// Exponential lives fit a Weibull of shape 1: the exponential ranks first by its one
    /// parameter fewer, and that is no reason to warn (it warned that the Weibull's B-lives
    /// "extrapolate a shape the lives do not have").
    #[test]
    fn exponential_lives_rank_the_exponential_first_without_a_warning() {
        let exponential: Vec<(f64, bool)> = (1..=200)
            .map(|i| (-1000.0 * (1.0 - (i as f64 - 0.5) / 200.0).ln(), true))
            .collect();
        let lives = Lives::from_pairs(&exponential).unwrap();
        let weibull = fit_weibull_lives(&lives).unwrap();
        let ranked = fits(&lives, Some(&weibull));
        assert_eq!(ranked[0].distribution, Family::Exponential);
        let weibull_aicc = ranked
            .iter()
            .find(|fit| fit.distribution == Family::Weibull)
            .and_then(|fit| fit.aicc)
            .unwrap();
        assert!(weibull_aicc - ranked[0].aicc.unwrap() > AICC_SUPPORT);
        assert_eq!(weibull_warning(&ranked), None);
    }

    /// Failure by failure, the plotting positions end each time where `median_ranks` puts that
    /// time's point; the Anderson-Darling statistic of a perfect fit to evenly spread positions
    /// is small, of a bad one large.
    #[test]
    fn positions_follow_the_median_ranks_and_anderson_darling_tells_fits_apart() {
        let lives = Lives::from_pairs(&[
            (10.0, true),
            (10.0, true),
            (15.0, false),
            (20.0, true),
            (20.0, false),
            (30.0, true),
            (40.0, false),
        ])
        .unwrap();
        let positions = failure_positions(&lives);
        assert_eq!(positions.len(), 3);
        let km = super::super::kaplan_meier_lives(&lives);
        let ranks = super::super::median_ranks(&km, 7);
        assert_eq!(ranks.len(), 3);
        for ((_, a), b) in positions.iter().zip(&ranks) {
            assert_relative_eq!(*a, *b, max_relative = 1e-15);
        }
        // One term a failure, as Minitab and `reliability` sum it, against one a time.
        let per_failure = |cdf: &dyn Fn(f64) -> f64| {
            let (n, mut rank, mut at_risk) = (7.0, 0.0, 7.0);
            let (mut z, mut f) = (Vec::new(), Vec::new());
            for a in lives.at() {
                for k in 0..a.failures {
                    rank += (n + 1.0 - rank) / (1.0 + at_risk - k as f64);
                    z.push(cdf(a.time));
                    f.push((rank - 0.3) / (n + 0.4));
                }
                at_risk -= a.devices();
            }
            z.push(1.0 - 1e-12);
            let (mut pz, mut pf, mut sum) = (0.0f64, 0.0f64, 0.0);
            for (i, &zi) in z.iter().enumerate() {
                let (ls, pls) = ((-zi).ln_1p(), (-pz).ln_1p());
                let pln = if pz > 0.0 { pz.ln() } else { 0.0 };
                sum += -zi - ls
                    + pz
                    + pls
                    + 2.0 * pf * (ls - pls)
                    + pf * pf * (zi.ln() - ls - pln + pls);
                pz = zi;
                pf = f.get(i).copied().unwrap_or(pf);
            }
            4.0 * sum
        };
        let exponential = |t: f64| -(-t / 30.0).exp_m1();
        assert_relative_eq!(
            anderson_darling(&positions, 4, exponential).unwrap(),
            per_failure(&exponential),
            max_relative = 1e-12
        );
        // Evenly spread exponential quantiles against the exponential they came from, and
        // against one ten times too short.
        let lives = Lives::from_pairs(
            &(1..=100)
                .map(|i| (-(1.0 - (i as f64 - 0.3) / 100.4).ln() * 1000.0, true))
                .collect::<Vec<_>>(),
        )
        .unwrap();
        let positions = failure_positions(&lives);
        let good = anderson_darling(&positions, 100, |t| -(-t / 1000.0).exp_m1()).unwrap();
        let bad = anderson_darling(&positions, 100, |t| -(-t / 100.0).exp_m1()).unwrap();
        assert!(good < 1.0 && bad > 100.0, "{good} {bad}");
        assert_eq!(anderson_darling(&[], 0, |t| t), None);
    }
}
