//! Two designs' lives compared: the difference and ratio of their B-lives with intervals, and the
//! probability that a device of the first outlasts one of the second.
//!
//! From two Weibull fits, `P(T_a > T_b) = int f_b(t) R_a(t) dt`; with `w = (t / eta_b)^beta_b`,
//!
//! `P = int_0^inf exp(-w - c w^r) dw`, `c = (eta_b / eta_a)^beta_a`, `r = beta_a / beta_b`,
//!
//! which is `1 / (1 + c)` when the shapes are equal. It is integrated on `s = ln w`, where the
//! integrand `exp(s - e^s - c e^(r s))` is smooth, log-concave and decays on both sides, by the
//! trapezoidal rule (spectrally accurate there) with a step fine enough for the peak and for `r`. Its interval is
//! the delta method on `logit P = ln P - ln P(T_b > T_a)`, each computed directly so that neither
//! loses digits near 0 or 1, with each fit's covariance of `(ln eta, ln beta)`.
//!
//! Without a model, the simulated devices themselves say in what share of pairs the first design
//! outlasts the second, as far as censoring lets it be known: a device censored at the end of its
//! test may or may not outlast one that failed later, or another censored one ([`observed_outlasts`]).

use serde::{Deserialize, Serialize};

use super::{LifeAnalysis, Lives, Weibull, likelihood_ratio};
use crate::stats::{Difference, Estimate, Z_975, difference};

/// `B_p` of two designs compared.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BLifeDifference {
    /// Fraction failed.
    pub p: f64,
    #[serde(flatten)]
    pub difference: Difference,
}

/// The probability that a device of the first design outlasts one of the second.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Outlasts {
    /// From the two Weibull fits, `P(T_a > T_b)`; `null` without both fits.
    pub weibull: Option<f64>,
    /// Its 95 % interval (delta method on the logit); `null` when a covariance is unusable.
    pub weibull_ci95: Option<[f64; 2]>,
    /// The share of pairs of simulated devices, one of each design, in which the first outlasts
    /// the second (ties count half), as far as censoring lets it be known: at least the first
    /// number, at most the second. No model.
    pub observed: [f64; 2],
    /// The 95 % interval of that share in the designs' populations: `observed` widened by the
    /// sampling error of the simulated devices ([`observed_outlasts_ci95`]).
    #[serde(default = "unit_interval")]
    pub observed_ci95: [f64; 2],
}

fn unit_interval() -> [f64; 2] {
    [0.0, 1.0]
}

/// Two designs' lives compared.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LifeComparison {
    /// Per fraction asked, `B_p` of each design from its Weibull fit, their difference and ratio.
    pub b_lives: Vec<BLifeDifference>,
    /// The same, each design's `B_p` read off its Kaplan-Meier curve with no distribution assumed
    /// ([`super::observed_b_life`]); a fraction either curve does not reach is left out, with a
    /// note.
    #[serde(default)]
    pub b_lives_observed: Vec<BLifeDifference>,
    pub outlasts: Outlasts,
    /// What limits the comparison: a design without a Weibull fit, or one that another
    /// distribution fits clearly better.
    pub notes: Vec<String>,
}

/// Below this many failures a design's B-life intervals are noted as approximate
/// (`intervals_cover_nearly_as_asked_with_few_devices`).
pub const FEW_FAILURES: usize = 10;

/// `a` against `b`: the B-lives at the fractions `ps` (each in `(0, 1)`) and who outlasts whom.
/// `lives_a` and `lives_b` are the lives each analysis was made from.
pub fn compare_lives(
    a: (&LifeAnalysis, &Lives),
    b: (&LifeAnalysis, &Lives),
    ps: &[f64],
) -> LifeComparison {
    let mut notes = Vec::new();
    for (name, life) in [("a", a.0), ("b", b.0)] {
        match (&life.weibull, &life.weibull_error) {
            (None, error) => notes.push(format!(
                "design {name} has no Weibull fit ({}): no B-lives, no modelled probability",
                error.as_deref().unwrap_or("no failures")
            )),
            (Some(weibull), _) => {
                if let Some(warning) = &life.fit_warning {
                    notes.push(format!("design {name}: {warning}"));
                }
                if weibull.failures < FEW_FAILURES {
                    notes.push(format!(
                        "design {name} has {} failures: with fewer than {FEW_FAILURES}, its \
                         B-lives' 95 % intervals (by likelihood ratio) and those built on them \
                         cover less than asked (about 91 % with 5 failures)",
                        weibull.failures
                    ));
                }
            }
        }
    }
    let fits = a.0.weibull.as_ref().zip(b.0.weibull.as_ref());
    let b_lives = match fits {
        Some((wa, wb)) => ps
            .iter()
            .filter_map(|&p| {
                Some(BLifeDifference {
                    p,
                    difference: difference(
                        b_life_estimate(wa, a.1, p)?,
                        b_life_estimate(wb, b.1, p)?,
                    ),
                })
            })
            .collect(),
        None => Vec::new(),
    };
    let mut b_lives_observed = Vec::new();
    for &p in ps {
        let [ea, eb] = [a.0, b.0].map(|life| observed_b_life_estimate(life, p));
        match ea.zip(eb) {
            Some((ea, eb)) => b_lives_observed.push(BLifeDifference {
                p,
                difference: difference(ea, eb),
            }),
            None => notes.push(format!(
                "the B-life at p = {p} read off the Kaplan-Meier curves: {} within the test",
                match (ea, eb) {
                    (None, None) => "neither design's reaches it",
                    (None, _) => "design a's does not reach it",
                    _ => "design b's does not reach it",
                }
            )),
        }
    }
    let modelled = fits.and_then(|(wa, wb)| weibull_outlasts(wa, wb));
    LifeComparison {
        b_lives,
        b_lives_observed,
        outlasts: Outlasts {
            weibull: modelled.map(|m| m.0),
            weibull_ci95: modelled.and_then(|m| m.1),
            observed: observed_outlasts(a.1, b.1),
            observed_ci95: observed_outlasts_ci95(a.1, b.1),
        },
        notes,
    }
}

/// `B_p` of the Weibull `w` fitted to `lives`, with its likelihood-ratio 95 % bounds: with few
/// failures the delta method's bounds on `ln B_p` are too narrow (B10 of 5 devices: 84 % of 200
/// seeds against 94.5 % by likelihood ratio), so a comparison built on them claimed more than
/// the data hold. The delta method's stand in where the profile cannot be crossed in finite
/// numbers.
pub fn b_life_estimate(w: &Weibull, lives: &Lives, p: f64) -> Option<Estimate> {
    let bounds = likelihood_ratio::b_life_lr_bounds(lives, w, p).or_else(|| w.quantile_bounds(p));
    Some(Estimate::new(w.quantile(p)?, bounds))
}

/// `B_p` read off `life`'s Kaplan-Meier curve, with its 95 % bounds where the test reached both;
/// `None` where the curve does not reach `p`. It enters MOVER at its value: over 200 pairs of
/// jobs of one design of 512 devices (lives 134-170 operations), the difference's interval held
/// 0 in 198 for B1 and for B10 (at the bounds' midpoint 199 and 188).
fn observed_b_life_estimate(life: &LifeAnalysis, p: f64) -> Option<Estimate> {
    let observed = super::observed_b_life(&life.kaplan_meier, p)?;
    let bounds = match observed.ci95 {
        [Some(lower), Some(upper)] => Some([lower, upper]),
        _ => None,
    };
    Some(Estimate::new(observed.value?, bounds))
}

/// `P(T_a > T_b)` of two Weibull fits and its 95 % interval; `None` when the numbers are not
/// finite.
pub fn weibull_outlasts(a: &Weibull, b: &Weibull) -> Option<(f64, Option<[f64; 2]>)> {
    let theta = [a.eta.ln(), a.beta.ln(), b.eta.ln(), b.beta.ln()];
    let logit = |t: &[f64; 4]| {
        let ln_p = ln_outlasts(t[0], t[1].exp(), t[2], t[3].exp());
        let ln_q = ln_outlasts(t[2], t[3].exp(), t[0], t[1].exp());
        (ln_p, ln_q)
    };
    let (ln_p, ln_q) = logit(&theta);
    let p = if ln_p < ln_q {
        ln_p.exp()
    } else {
        -ln_q.exp_m1()
    };
    if !(p.is_finite() && (0.0..=1.0).contains(&p)) {
        return None;
    }
    let centre = ln_p - ln_q;
    // Central differences of the logit: it is smooth in every parameter.
    let step = 1e-5;
    let mut gradient = [0.0; 4];
    for (i, g) in gradient.iter_mut().enumerate() {
        let (mut up, mut down) = (theta, theta);
        up[i] += step;
        down[i] -= step;
        let (pu, qu) = logit(&up);
        let (pd, qd) = logit(&down);
        *g = ((pu - qu) - (pd - qd)) / (2.0 * step);
    }
    let quadratic = |g: [f64; 2], c: &[[f64; 2]; 2]| {
        g[0] * g[0] * c[0][0] + 2.0 * g[0] * g[1] * c[0][1] + g[1] * g[1] * c[1][1]
    };
    let variance = quadratic([gradient[0], gradient[1]], &a.covariance_ln)
        + quadratic([gradient[2], gradient[3]], &b.covariance_ln);
    let logistic = |x: f64| 1.0 / (1.0 + (-x).exp());
    let ci95 = (variance.is_finite() && variance >= 0.0 && centre.is_finite()).then(|| {
        let half = Z_975 * variance.sqrt();
        [logistic(centre - half), logistic(centre + half)]
    });
    Some((p, ci95))
}

/// `ln P(T_a > T_b)` for Weibull lives `(ln eta_a, beta_a)` and `(ln eta_b, beta_b)`: the integral of
/// the module's documentation, `ln c = beta_a (ln eta_b - ln eta_a)`, `r = beta_a / beta_b`.
pub fn ln_outlasts(ln_eta_a: f64, beta_a: f64, ln_eta_b: f64, beta_b: f64) -> f64 {
    let ln_c = beta_a * (ln_eta_b - ln_eta_a);
    let r = beta_a / beta_b;
    let g = |s: f64| s - s.exp() - (ln_c + r * s).exp();
    let slope = |s: f64| 1.0 - s.exp() - r * (ln_c + r * s).exp();
    // The peak: the slope falls from 1 to -inf; bracket its zero, then bisect.
    let (mut lo, mut hi) = (-1.0, 1.0);
    while slope(lo) <= 0.0 && lo > -1e6 {
        lo *= 2.0;
    }
    while slope(hi) >= 0.0 && hi < 1e6 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if slope(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-12 * (1.0 + mid.abs()) {
            break;
        }
    }
    let peak = 0.5 * (lo + hi);
    let top = g(peak);
    let curvature = peak.exp() + r * r * (ln_c + r * peak).exp();
    let width = 1.0 / curvature.sqrt();
    // An eighth of the peak's width, and at most a tenth of `1 / r`: off the real line
    // `c e^(r s)` turns negative at `Im s = pi / (2 r)`, which bounds the strip where the
    // integrand stays small and so the trapezoid's error, `~ exp(-2 pi (pi / 2r) / h)`. Never
    // more than a million points each side of the peak, to `e^-40` of its height.
    let reach = 40.0;
    let h = (width / 8.0).min(0.1 / r.max(1.0)).max(1e-6);
    let mut sum = 1.0;
    for direction in [-1.0, 1.0] {
        let mut k = 1.0;
        loop {
            let term = g(peak + direction * k * h) - top;
            if term < -reach || !term.is_finite() || k > 1e6 {
                break;
            }
            sum += term.exp();
            k += 1.0;
        }
    }
    top + (h * sum).ln()
}

/// The share of pairs `(a, b)` of devices, one of each set of lives, in which `a` lives longer
/// (ties half), bounded as censoring allows: `[known, known + unknown]`. A device censored at `t`
/// lived beyond `t`. `[0, 1]` when either set is empty.
pub fn observed_outlasts(a: &Lives, b: &Lives) -> [f64; 2] {
    let (na, nb) = (a.failures() + a.censored(), b.failures() + b.censored());
    if na == 0 || nb == 0 {
        return [0.0, 1.0];
    }
    bounds(&against(a, b), na as f64)
}

/// `[known, known + unknown]` over `n` devices of the groups' side.
fn bounds(groups: &[Group], n: f64) -> [f64; 2] {
    let (wins, unknown) = groups.iter().fold((0.0, 0.0), |(w, u), g| {
        (w + g.devices * g.wins, u + g.devices * g.unknown)
    });
    // Each group's shares are of the other side's devices already: the mean over this side's,
    // a share of pairs, which the sums' rounding may not carry past 1.
    [(wins / n).min(1.0), ((wins + unknown) / n).min(1.0)]
}

/// The 95 % interval of the share of pairs in which a device of the population behind `a`
/// outlasts one behind `b`: the observed bounds widened by 1.96 standard errors of the
/// two-sample U-statistic (DeLong et al. 1988: the variance of each device's share against the
/// other set, over `n_a`, plus the same of the other side over `n_b`; a pair whose order
/// censoring hides counted half), within `[0, 1]`. Where that standard error is 0 or cannot be
/// had (one device a side), Newcombe's score interval; `[0, 1]` for a side without devices.
pub fn observed_outlasts_ci95(a: &Lives, b: &Lives) -> [f64; 2] {
    let (na, nb) = (
        (a.failures() + a.censored()) as f64,
        (b.failures() + b.censored()) as f64,
    );
    if na < 1.0 || nb < 1.0 {
        return [0.0, 1.0];
    }
    // The sample variance of each device's share of the other side it outlasts, unknown pairs
    // half (b's side counts b outlasting: `1 - share` of a outlasting has the same variance).
    let variance = |groups: &[Group], n: f64| {
        let share = |g: &Group| g.wins + 0.5 * g.unknown;
        let mean = groups.iter().map(|g| g.devices * share(g)).sum::<f64>() / n;
        groups
            .iter()
            .map(|g| g.devices * (share(g) - mean).powi(2))
            .sum::<f64>()
            / (n - 1.0)
    };
    let a_against_b = against(a, b);
    let [lower, upper] = bounds(&a_against_b, na);
    let z = crate::stats::Z_975;
    if na >= 2.0 && nb >= 2.0 {
        let se = (variance(&a_against_b, na) / na + variance(&against(b, a), nb) / nb).sqrt();
        if se > 0.0 {
            return [(lower - z * se).max(0.0), (upper + z * se).min(1.0)];
        }
    }
    // Every device's share the same (one design's devices all outlast the other's, say): the
    // U-statistic's variance estimate is 0 and its interval no wider than the observation, a
    // certainty a sample cannot give; with one device a side there is no spread to estimate it
    // from (the interval was `[0, 1]`, whatever the other side's devices said: an outside
    // check). Newcombe's score interval takes its place there (2006, method 5: the
    // Hanley-McNeil variance at the bound itself).
    let variance = |theta: f64| hanley_mcneil_variance(theta, na, nb);
    [
        score_bound(lower, -1.0, z, &variance),
        score_bound(upper, 1.0, z, &variance),
    ]
}

/// The Hanley-McNeil (1982) variance of the share of pairs in which one of `m` devices outlasts
/// one of `n`, at share `theta`, in Newcombe's (2006) form: `theta (1 - theta) [1 + (N - 1)
/// (1 - theta) / (2 - theta) + (N - 1) theta / (1 + theta)] / (m n)`, `N = (m + n) / 2`.
fn hanley_mcneil_variance(theta: f64, m: f64, n: f64) -> f64 {
    let big = 0.5 * (m + n) - 1.0;
    theta
        * (1.0 - theta)
        * (1.0 + big * (1.0 - theta) / (2.0 - theta) + big * theta / (1.0 + theta))
        / (m * n)
}

/// The end of the score interval beyond `at` on `side` (-1 below, 1 above): the `theta` between
/// `at` and 0 (or 1) where `|theta - at| = z sqrt(variance(theta))`, by bisection.
fn score_bound(at: f64, side: f64, z: f64, variance: &dyn Fn(f64) -> f64) -> f64 {
    let edge = if side < 0.0 { 0.0 } else { 1.0 };
    // Inside (between `at` and the bound) the distance falls short of z standard errors.
    let short = |theta: f64| (theta - at).abs() < z * variance(theta).sqrt();
    let (mut inside, mut outside) = (at, edge);
    if short(edge) {
        return edge;
    }
    for _ in 0..100 {
        let middle = 0.5 * (inside + outside);
        if short(middle) {
            inside = middle;
        } else {
            outside = middle;
        }
    }
    outside
}

/// The devices of one time of a set of lives, failed or censored, against the other set: the
/// share of the other set each outlasts for certain and the share whose order censoring hides.
struct Group {
    devices: f64,
    wins: f64,
    unknown: f64,
}

/// [`Group`]s of `a` against `b`, both non-empty.
fn against(a: &Lives, b: &Lives) -> Vec<Group> {
    let nb = (b.failures() + b.censored()) as f64;
    let times: Vec<f64> = b.at().iter().map(|x| x.time).collect();
    // Prefix sums of b's failures and censorings over its sorted times.
    let mut failed_before = vec![0u64; times.len() + 1];
    let mut censored_before = vec![0u64; times.len() + 1];
    for (i, x) in b.at().iter().enumerate() {
        failed_before[i + 1] = failed_before[i] + x.failures;
        censored_before[i + 1] = censored_before[i] + x.censored;
    }
    let (b_failed, b_censored) = (b.failures(), b.censored());
    let mut groups = Vec::new();
    for x in a.at() {
        let below = times.partition_point(|&s| s < x.time);
        let through = times.partition_point(|&s| s <= x.time);
        let failed_at = (failed_before[through] - failed_before[below]) as f64;
        if x.failures > 0 {
            // Failed at t: beats b's failures before t, ties b's at t; b's censored before t
            // may have lived longer or not; b's censored at or after t outlived it.
            groups.push(Group {
                devices: x.failures as f64,
                wins: (failed_before[below] as f64 + 0.5 * failed_at) / nb,
                unknown: censored_before[below] as f64 / nb,
            });
        }
        if x.censored > 0 {
            // Censored at t, so alive after t: beats b's failures up to t; against b's later
            // failures and every censored b, unknown.
            groups.push(Group {
                devices: x.censored as f64,
                wins: failed_before[through] as f64 / nb,
                unknown: ((b_failed - failed_before[through]) + b_censored) as f64 / nb,
            });
        }
    }
    groups
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::life::{analyse, fit_weibull};
    use approx::assert_relative_eq;

    /// `P(T_a > T_b)` by scipy.integrate.quad on `int_0^inf f_b(t) R_a(t) dt` at `epsabs=0,
    /// epsrel=1e-11` (tools/outlasts_reference.py): `(eta_a, beta_a, eta_b, beta_b, P)`.
    const REFERENCE: [(f64, f64, f64, f64, f64); 6] = [
        (1000.0, 2.0, 800.0, 3.5, 0.5955015213902726),
        (866.0, 26.4, 900.0, 1.3, 0.6033459013693635),
        (1.0, 0.5, 1.0, 8.0, 0.3810755667436181),
        (50000.0, 12.0, 10000.0, 12.0, 0.9999999959040002),
        (1000.0, 1.0, 2000.0, 40.0, 0.1394043527755961),
        (1000000.0, 3.0, 1.0, 0.3, 0.999999999996371),
    ];

    fn outlasts(eta_a: f64, beta_a: f64, eta_b: f64, beta_b: f64) -> f64 {
        ln_outlasts(eta_a.ln(), beta_a, eta_b.ln(), beta_b).exp()
    }

    #[test]
    fn equal_shapes_have_a_closed_form() {
        for (eta_a, eta_b, beta) in [
            (1000.0f64, 800.0f64, 2.0f64),
            (1.0, 1.0, 7.0),
            (3e5, 2e3, 0.7),
            (10.0, 1e4, 30.0),
        ] {
            let truth = eta_a.powf(beta) / (eta_a.powf(beta) + eta_b.powf(beta));
            let p = outlasts(eta_a, beta, eta_b, beta);
            let q = outlasts(eta_b, beta, eta_a, beta);
            assert_relative_eq!(p, truth, max_relative = 1e-12);
            assert_relative_eq!(q, 1.0 - truth, max_relative = 1e-12);
        }
    }

    #[test]
    fn the_two_directions_sum_to_one() {
        for &(ea, ba, eb, bb, _) in &REFERENCE {
            let sum = outlasts(ea, ba, eb, bb) + outlasts(eb, bb, ea, ba);
            assert_relative_eq!(sum, 1.0, max_relative = 1e-12);
        }
    }

    #[test]
    fn outlasts_matches_the_quadrature_reference() {
        for &(ea, ba, eb, bb, truth) in &REFERENCE {
            assert_relative_eq!(outlasts(ea, ba, eb, bb), truth, max_relative = 1e-9);
        }
    }

    /// Without censoring the interval is `share -+ 1.96 se` with DeLong's variance, here
    /// computed pair by pair from its definition: each device's share of the other side it
    /// outlasts (ties half), their sample variances over `n_a` and `n_b`.
    #[test]
    fn observed_interval_is_delongs_without_censoring() {
        let a_times = [3.0, 5.0, 5.0, 9.0, 12.0, 13.0, 20.0, 21.0];
        let b_times = [1.0, 2.0, 5.0, 6.0, 7.0, 8.0];
        let lives = |t: &[f64]| {
            Lives::from_pairs(&t.iter().map(|&t| (t, true)).collect::<Vec<_>>()).unwrap()
        };
        let beats = |x: f64, y: f64| match x.total_cmp(&y) {
            std::cmp::Ordering::Greater => 1.0,
            std::cmp::Ordering::Equal => 0.5,
            std::cmp::Ordering::Less => 0.0,
        };
        let v10: Vec<f64> = a_times
            .iter()
            .map(|&x| b_times.iter().map(|&y| beats(x, y)).sum::<f64>() / 6.0)
            .collect();
        let v01: Vec<f64> = b_times
            .iter()
            .map(|&y| a_times.iter().map(|&x| beats(x, y)).sum::<f64>() / 8.0)
            .collect();
        let share = v10.iter().sum::<f64>() / 8.0;
        let sample_variance = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64
        };
        let se = (sample_variance(&v10) / 8.0 + sample_variance(&v01) / 6.0).sqrt();
        let (a, b) = (lives(&a_times), lives(&b_times));
        assert_eq!(observed_outlasts(&a, &b), [share, share]);
        let [lo, hi] = observed_outlasts_ci95(&a, &b);
        assert_relative_eq!(lo, share - crate::stats::Z_975 * se, max_relative = 1e-12);
        assert_relative_eq!(
            hi,
            (share + crate::stats::Z_975 * se).min(1.0),
            max_relative = 1e-12
        );
        // Censoring widens it by the pairs it hides, at least.
        let mut censored: Vec<(f64, bool)> = a_times.iter().map(|&t| (t, true)).collect();
        censored[7].1 = false;
        censored[6] = (20.0, false);
        let c = Lives::from_pairs(&censored).unwrap();
        let [known, bound] = observed_outlasts(&c, &b);
        let [clo, chi] = observed_outlasts_ci95(&c, &b);
        assert!(clo < known && bound < chi, "{clo} {known} {bound} {chi}");
        // One device a side: no spread to estimate the variance from, the score interval.
        let [olo, ohi] = observed_outlasts_ci95(&lives(&[4.0]), &b);
        assert!(0.0 < olo && ohi < 1.0, "{olo} {ohi}");
    }

    /// The observed share is a share of pairs, within `[0, 1]` however its terms round: summed
    /// group by group, a design that outlasts every device it can be ordered against came to
    /// `1.0000000000000002` (found by a probe of the comparison).
    #[test]
    fn the_observed_share_stays_within_zero_and_one() {
        let mut state = 7_u64;
        let mut next = |below: u64| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) % below
        };
        for _ in 0..2000 {
            let (na, nb) = (1 + next(300), 1 + next(300));
            let late: Vec<(f64, bool)> = (0..na)
                .map(|_| (1000.0 + next(500) as f64, next(4) != 0))
                .collect();
            let early: Vec<(f64, bool)> = (0..nb)
                .map(|_| (1.0 + next(1500) as f64, next(3) != 0))
                .collect();
            let (a, b) = (
                Lives::from_pairs(&late).unwrap(),
                Lives::from_pairs(&early).unwrap(),
            );
            for [lo, hi] in [observed_outlasts(&a, &b), observed_outlasts(&b, &a)] {
                assert!(0.0 <= lo && lo <= hi && hi <= 1.0, "{lo} {hi}");
            }
        }
    }

    /// Where every device of one design outlasts every one of the other, DeLong's variance is
    /// 0 and its interval was the point `[1, 1]` (found by an audit): the score interval of
    /// Newcombe (2006, method 5) stands there, its bound where the distance to the observation is
    /// 1.96 Hanley-McNeil standard errors at the bound itself; narrower with more devices. So for
    /// devices that all fail at one time (every pair a tie, 0.5 each side).
    #[test]
    fn a_complete_separation_has_a_score_interval_not_a_point() {
        let lives = |t: std::ops::Range<u32>| {
            let pairs: Vec<(f64, bool)> = t.map(|t| (f64::from(t), true)).collect();
            Lives::from_pairs(&pairs).unwrap()
        };
        let z = crate::stats::Z_975;
        let (late, early) = (lives(10..30), lives(1..9));
        assert_eq!(observed_outlasts(&late, &early), [1.0, 1.0]);
        let [lo, hi] = observed_outlasts_ci95(&late, &early);
        assert_eq!(hi, 1.0);
        assert!(0.8 < lo && lo < 1.0, "{lo}");
        let distance = 1.0 - lo;
        let standard_error = hanley_mcneil_variance(lo, 20.0, 8.0).sqrt();
        assert_relative_eq!(distance, z * standard_error, max_relative = 1e-9);
        // The other way round, the mirror image; more devices, a narrower interval.
        let [rlo, rhi] = observed_outlasts_ci95(&early, &late);
        assert_eq!(rlo, 0.0);
        assert_relative_eq!(rhi, 1.0 - lo, max_relative = 1e-9);
        let [wide_lo, _] = observed_outlasts_ci95(&lives(100..300), &lives(1..81));
        assert!(lo < wide_lo && wide_lo < 1.0, "{lo} {wide_lo}");
        // All at one time: every pair a tie.
        let one_time = |n: usize| Lives::from_pairs(&vec![(5.0, true); n]).unwrap();
        let [tlo, thi] = observed_outlasts_ci95(&one_time(12), &one_time(9));
        assert!(tlo < 0.5 && thi > 0.5, "{tlo} {thi}");
        assert_relative_eq!(0.5 - tlo, thi - 0.5, max_relative = 1e-9);
        let standard_error = hanley_mcneil_variance(tlo, 12.0, 9.0).sqrt();
        assert_relative_eq!(0.5 - tlo, z * standard_error, max_relative = 1e-9);
    }

    /// One device against eight: no spread of a side to estimate DeLong's variance from, and the
    /// interval was `[0, 1]`; the score interval stands, each bound 1.96 Hanley-McNeil standard
    /// errors from the observation, either way round. (Normal lives, one device against 8 or 30,
    /// shifts of 0 to 2 sd, 20,000 draws each, NumPy: it held the truth in 93.7-100 % of them.)
    #[test]
    fn one_device_a_side_has_a_score_interval() {
        let z = crate::stats::Z_975;
        let one = Lives::from_pairs(&[(5.0, true)]).unwrap();
        let b = |n: u32| {
            let pairs: Vec<(f64, bool)> = (1..=n).map(|t| (f64::from(t), true)).collect();
            Lives::from_pairs(&pairs).unwrap()
        };
        // Outlasts the devices at 1 to 4, ties the one at 5: 4.5 of 8 pairs.
        assert_eq!(observed_outlasts(&one, &b(8)), [0.5625, 0.5625]);
        let [lo, hi] = observed_outlasts_ci95(&one, &b(8));
        assert!(
            0.0 < lo && lo < 0.5625 && 0.5625 < hi && hi < 1.0,
            "{lo} {hi}"
        );
        for bound in [lo, hi] {
            let standard_error = hanley_mcneil_variance(bound, 1.0, 8.0).sqrt();
            assert_relative_eq!(
                (bound - 0.5625).abs(),
                z * standard_error,
                max_relative = 1e-9
            );
        }
        let [mlo, mhi] = observed_outlasts_ci95(&b(8), &one);
        assert_relative_eq!(mlo, 1.0 - hi, max_relative = 1e-9);
        assert_relative_eq!(mhi, 1.0 - lo, max_relative = 1e-9);
    }

    #[test]
    fn observed_outlasts_counts_pairs_and_bounds_the_censored() {
        // a: failed at 1, 3, censored at 10; b: failed at 2, 3, censored at 5.
        let a = Lives::from_pairs(&[(1.0, true), (3.0, true), (10.0, false)]).unwrap();
        let b = Lives::from_pairs(&[(2.0, true), (3.0, true), (5.0, false)]).unwrap();
        // Known: (3 vs 2) win, (3 vs 3) half, (10c vs 2) win, (10c vs 3) win, (10c vs 5c) unknown;
        // (1 vs anything) lose, (3 vs 5c) lose.
        let [lo, hi] = observed_outlasts(&a, &b);
        assert_relative_eq!(lo, 3.5 / 9.0, max_relative = 1e-15);
        assert_relative_eq!(hi, 4.5 / 9.0, max_relative = 1e-15);
        // Without censoring it is the Mann-Whitney share, and the two directions sum to one.
        let a = Lives::from_pairs(&[(1.0, true), (4.0, true), (4.0, true)]).unwrap();
        let b = Lives::from_pairs(&[(2.0, true), (4.0, true)]).unwrap();
        let [lo, hi] = observed_outlasts(&a, &b);
        let [blo, _] = observed_outlasts(&b, &a);
        assert_eq!(lo, hi);
        assert_relative_eq!(lo, 3.0 / 6.0, max_relative = 1e-15);
        assert_relative_eq!(lo + blo, 1.0, max_relative = 1e-15);
    }

    #[test]
    fn b_lives_and_notes() {
        let weibull = |eta: f64, beta: f64| -> Vec<(f64, bool)> {
            (1..=40)
                .map(|k| {
                    let u = (k as f64 - 0.5) / 40.0;
                    let t = eta * (-(1.0 - u).ln()).powf(1.0 / beta);
                    if t > 1500.0 {
                        (1500.0, false)
                    } else {
                        (t, true)
                    }
                })
                .collect()
        };
        let (da, db) = (weibull(1000.0, 2.0), weibull(700.0, 3.0));
        let (la, lb) = (analyse(&da), analyse(&db));
        let (va, vb) = (
            Lives::from_pairs(&da).unwrap(),
            Lives::from_pairs(&db).unwrap(),
        );
        let c = compare_lives((&la, &va), (&lb, &vb), &[0.01, 0.1]);
        assert_eq!(c.b_lives.len(), 2);
        let b10 = &c.b_lives[1];
        assert_eq!(b10.difference.a, la.b10.as_ref().unwrap().value);
        assert_eq!(b10.difference.a_ci95, la.b10.as_ref().unwrap().lr_ci95);
        assert!(c.outlasts.weibull.unwrap() > 0.5);
        let [lo, hi] = c.outlasts.observed;
        assert!(lo <= hi && lo > 0.5, "{lo} {hi}");
        let [wl, wh] = c.outlasts.weibull_ci95.unwrap();
        assert!(wl < c.outlasts.weibull.unwrap() && c.outlasts.weibull.unwrap() < wh);
        // Read off the curves: each side the life analysis' own, B10 the fourth of 40 lives.
        assert_eq!(c.b_lives_observed.len(), 2);
        let observed = &c.b_lives_observed[1].difference;
        let b10 = la.b10_observed.as_ref().unwrap();
        let bounds = b10.ci95.map(Option::unwrap);
        assert_eq!(
            (observed.a, observed.a_ci95),
            (b10.value.unwrap(), Some(bounds))
        );
        assert_eq!(Some(observed.a), da.iter().map(|l| l.0).nth(3));
        // No failures: no fit, a note, still the observed share.
        let none: Vec<(f64, bool)> = (0..10).map(|_| (100.0, false)).collect();
        let ln = analyse(&none);
        let vn = Lives::from_pairs(&none).unwrap();
        let c = compare_lives((&ln, &vn), (&lb, &vb), &[0.1]);
        assert!(c.b_lives.is_empty());
        assert_eq!(c.outlasts.weibull, None);
        assert!(
            c.notes[0].starts_with("design a has no Weibull fit"),
            "{:?}",
            c.notes
        );
        assert!(c.b_lives_observed.is_empty());
        assert!(
            c.notes[1].contains("p = 0.1 read off the Kaplan-Meier curves: design a's does not"),
            "{:?}",
            c.notes
        );
        assert!(fit_weibull(&none).is_err());
    }

    /// Coverage with a known truth: two designs of Weibull lives with the same shape, so that
    /// `P(T_a > T_b) = eta_a^beta / (eta_a^beta + eta_b^beta)` and `B10_a / B10_b = eta_a / eta_b`;
    /// 2000 replicates (seed 1992) of 50 devices each, tested to 1500 operations (about 10 % of
    /// design a and 3 % of b censored). Each interval should cover its truth in 95 % of the
    /// replicates; the binomial standard error of a coverage over 2000 is 0.5 %.
    #[test]
    fn intervals_cover_a_known_truth() {
        for (what, c) in coverage(50, 1500.0, 2000) {
            eprintln!("{what}: coverage {c} over 2000 replicates of 50 devices");
            assert!((0.93..=0.965).contains(&c), "{what}: coverage {c}");
        }
    }

    /// As [`intervals_cover_a_known_truth`] with 5 devices a design, uncensored. A design's B10
    /// interval by likelihood ratio covers 0.910 (the delta method's covered 0.808), the
    /// difference and ratio built from them 0.927 and 0.923 (0.945 from the delta method's), the
    /// probability of outlasting 0.946: near 95 %, not at it, as the comparison's note says.
    #[test]
    fn intervals_cover_nearly_as_asked_with_few_devices() {
        for (what, c) in coverage(5, f64::INFINITY, 2000) {
            eprintln!("{what}: coverage {c} over 2000 replicates of 5 devices");
            assert!((0.9..=0.97).contains(&c), "{what}: coverage {c}");
        }
    }

    /// The coverage of each interval over `replicates` pairs of designs of `devices` each, tested
    /// to `end` operations.
    fn coverage(devices: usize, end: f64, replicates: usize) -> [(&'static str, f64); 4] {
        let (eta_a, eta_b, beta) = (1000.0f64, 800.0f64, 2.0f64);
        let truth_p = eta_a.powf(beta) / (eta_a.powf(beta) + eta_b.powf(beta));
        let k = (-(0.9f64).ln()).powf(1.0 / beta);
        let (truth_difference, truth_ratio) = ((eta_a - eta_b) * k, eta_a / eta_b);
        let mut rng = crate::stats::SplitMix(1992);
        let mut draw = |eta: f64| -> Vec<(f64, bool)> {
            (0..devices)
                .map(|_| {
                    let u = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
                    let t = eta * (-(1.0 - u).ln()).powf(1.0 / beta);
                    if t > end { (end, false) } else { (t, true) }
                })
                .collect()
        };
        let (mut p_in, mut a_in, mut d_in, mut r_in) = (0, 0, 0, 0);
        for _ in 0..replicates {
            let (da, db) = (draw(eta_a), draw(eta_b));
            let (wa, wb) = (fit_weibull(&da).unwrap(), fit_weibull(&db).unwrap());
            let (_, ci) = weibull_outlasts(&wa, &wb).unwrap();
            let [lo, hi] = ci.unwrap();
            p_in += usize::from(lo <= truth_p && truth_p <= hi);
            let estimate = |w: &Weibull, lives: &[(f64, bool)]| {
                b_life_estimate(w, &Lives::from_pairs(lives).unwrap(), 0.1).unwrap()
            };
            let d = difference(estimate(&wa, &da), estimate(&wb, &db));
            let [lo, hi] = d.a_ci95.unwrap();
            a_in += usize::from(lo <= eta_a * k && eta_a * k <= hi);
            let [lo, hi] = d.difference_ci95.unwrap();
            d_in += usize::from(lo <= truth_difference && truth_difference <= hi);
            let [lo, hi] = d.ratio_ci95.unwrap();
            r_in += usize::from(lo <= truth_ratio && truth_ratio <= hi);
        }
        let coverage = |hits: usize| hits as f64 / replicates as f64;
        [
            ("P(a outlasts b)", coverage(p_in)),
            ("B10 of a", coverage(a_in)),
            ("B10 difference", coverage(d_in)),
            ("B10 ratio", coverage(r_in)),
        ]
    }
}
