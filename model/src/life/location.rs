//! The three-parameter Weibull: a failure-free life `gamma` before which no device fails, and a
//! two-parameter Weibull of the time after it,
//!
//! `F(t) = 1 - exp(-((t - gamma) / eta)^beta)` for `t > gamma`.
//!
//! Its likelihood is maximised over `gamma` in `[0, t_1)`, `t_1` the earliest life (failed or
//! censored), through the profile `ln L_p(gamma)`: at each `gamma` the two-parameter fit of the
//! shifted lives `t - gamma` ([`super::fit_weibull_lives`], exact to `f64`). By the envelope
//! theorem the profile's slope is the likelihood's partial derivative in `gamma` at that fit,
//!
//! `d ln L_p / d gamma = sum_all (beta / eta) ((t - gamma) / eta)^(beta - 1)
//!                       - sum_failures (beta - 1) / (t - gamma)`,
//!
//! so a maximum is where the slope falls through zero. The slope is scanned on a grid of `t_1 -
//! gamma` spaced evenly in its logarithm from `t_1` (`gamma = 0`) down to `t_1 e^-14`, and each
//! fall is bisected to the resolution of `f64`.
//!
//! The likelihood has no maximum at all when the shape near `t_1` is below 1: the first
//! failure's density `(t_1 - gamma)^(beta - 1)` then grows without bound as `gamma -> t_1` (Smith
//! 1985). Only local maxima inside `(0, t_1)` with `beta > 1` are fits (the `reliability`
//! package's bounded search returns the boundary there instead); without one, or where the best
//! `gamma` is 0 (the two-parameter Weibull itself), there is no three-parameter fit.

use super::{Lives, LivesAt, fit_weibull_lives};

/// The grid: `t_1 - gamma = t_1 e^(-SPAN j / STEPS)`, `j = 0..=STEPS`.
const SPAN: f64 = 14.0;
const STEPS: usize = 70;

/// A three-parameter Weibull fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weibull3 {
    pub beta: f64,
    pub eta: f64,
    /// The failure-free life.
    pub gamma: f64,
    pub log_likelihood: f64,
}

/// The maximum-likelihood three-parameter Weibull of `lives` (see the module documentation); none
/// with fewer than three distinct failure times or without a maximum inside `(0, t_1)`.
pub fn fit_weibull_3p(lives: &Lives) -> Option<Weibull3> {
    let at = lives.at();
    if at.iter().filter(|a| a.failures > 0).count() < 3 {
        return None;
    }
    let first = at.first()?.time;
    let grid: Vec<f64> = (0..=STEPS)
        .map(|j| {
            if j == 0 {
                0.0
            } else {
                first - first * (-SPAN * j as f64 / STEPS as f64).exp()
            }
        })
        .collect();
    let profile: Vec<Option<Weibull3>> = grid.iter().map(|&g| profile_at(at, g)).collect();
    let slope = |fit: &Option<Weibull3>| fit.as_ref().map(|w| slope(at, w));
    let mut best: Option<Weibull3> = None;
    for j in 0..STEPS {
        let (Some(rising), Some(falling)) = (slope(&profile[j]), slope(&profile[j + 1])) else {
            continue;
        };
        if !(rising > 0.0 && falling <= 0.0) {
            continue;
        }
        let Some(top) = bisect(at, grid[j], grid[j + 1]) else {
            continue;
        };
        if top.beta > 1.0 && best.is_none_or(|b| top.log_likelihood > b.log_likelihood) {
            best = Some(top);
        }
    }
    let two_parameter = profile[0]?.log_likelihood;
    best.filter(|b| b.gamma > 0.0 && b.log_likelihood > two_parameter)
}

/// The two-parameter fit of the lives shifted by `gamma`, as a three-parameter fit.
fn profile_at(at: &[LivesAt], gamma: f64) -> Option<Weibull3> {
    let shifted = Lives {
        at: at
            .iter()
            .map(|a| LivesAt {
                time: a.time - gamma,
                ..*a
            })
            .collect(),
    };
    if shifted.at.first()?.time <= 0.0 {
        return None;
    }
    let w = fit_weibull_lives(&shifted).ok()?;
    Some(Weibull3 {
        beta: w.beta,
        eta: w.eta,
        gamma,
        log_likelihood: w.log_likelihood,
    })
}

/// The profile's slope in `gamma` at `w` (the module documentation's formula).
fn slope(at: &[LivesAt], w: &Weibull3) -> f64 {
    at.iter()
        .map(|a| {
            let x = a.time - w.gamma;
            let hazard = w.beta / w.eta * (x / w.eta).powf(w.beta - 1.0);
            a.devices() * hazard - a.failures as f64 * (w.beta - 1.0) / x
        })
        .sum()
}

/// The profile's maximum between `rising` (slope above 0) and `falling` (at or below 0), by
/// bisection to the resolution of `f64`.
fn bisect(at: &[LivesAt], mut rising: f64, mut falling: f64) -> Option<Weibull3> {
    let mut top = profile_at(at, falling)?;
    for _ in 0..200 {
        let middle = 0.5 * (rising + falling);
        if middle <= rising || middle >= falling {
            break;
        }
        let fit = profile_at(at, middle)?;
        if slope(at, &fit) > 0.0 {
            rising = middle;
        } else {
            (falling, top) = (middle, fit);
        }
    }
    Some(top)
}

/// The CDF at `t`: 0 up to `gamma`.
pub(super) fn cdf(beta: f64, eta: f64, gamma: f64, t: f64) -> f64 {
    if t <= gamma {
        0.0
    } else {
        -(-((t - gamma) / eta).powf(beta)).exp_m1()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::SplitMix;
    use approx::assert_relative_eq;

    /// `n` lives of a Weibull(`beta`, `eta`) after a failure-free `gamma`, censored at `end`.
    fn lives(seed: u64, n: usize, gamma: f64, beta: f64, eta: f64, end: f64) -> Vec<(f64, bool)> {
        let mut rng = SplitMix(seed);
        (0..n)
            .map(|_| {
                let u = rng.uniform();
                let t = gamma + eta * (-(-u).ln_1p()).powf(1.0 / beta);
                if t <= end { (t, true) } else { (end, false) }
            })
            .collect()
    }

    fn fit(data: &[(f64, bool)]) -> Option<Weibull3> {
        fit_weibull_3p(&Lives::from_pairs(data).unwrap())
    }

    /// Shifting every life by `c` shifts `gamma` by `c`; scaling them by `k` scales `gamma` and
    /// `eta` by `k`; the shape stays. The grid moves with the lives, so this checks the maximum,
    /// not the grid.
    #[test]
    fn the_fit_moves_with_the_lives() {
        let data = lives(7, 200, 800.0, 2.5, 400.0, 1500.0);
        let base = fit(&data).unwrap();
        assert!(base.gamma > 600.0 && base.gamma < 900.0, "{base:?}");
        let shifted: Vec<_> = data.iter().map(|&(t, f)| (t + 250.0, f)).collect();
        let moved = fit(&shifted).unwrap();
        assert_relative_eq!(moved.gamma, base.gamma + 250.0, max_relative = 1e-9);
        assert_relative_eq!(moved.beta, base.beta, max_relative = 1e-8);
        assert_relative_eq!(moved.eta, base.eta, max_relative = 1e-8);
        let scaled: Vec<_> = data.iter().map(|&(t, f)| (t * 1e-3, f)).collect();
        let small = fit(&scaled).unwrap();
        assert_relative_eq!(small.gamma, base.gamma * 1e-3, max_relative = 1e-9);
        assert_relative_eq!(small.eta, base.eta * 1e-3, max_relative = 1e-8);
        assert_relative_eq!(small.beta, base.beta, max_relative = 1e-8);
        // ln L gains n ln 1000 from the densities of the failures.
        let failures = data.iter().filter(|d| d.1).count() as f64;
        assert_relative_eq!(
            small.log_likelihood,
            base.log_likelihood + failures * 1e3_f64.ln(),
            max_relative = 1e-10
        );
    }

    /// At the maximum the slope in `gamma` vanishes against the size of its terms.
    #[test]
    fn the_slope_vanishes_at_the_maximum() {
        let data = lives(8, 500, 1e4, 3.0, 2e3, 1.3e4);
        let lives = Lives::from_pairs(&data).unwrap();
        let w = fit_weibull_3p(&lives).unwrap();
        let scale: f64 = lives
            .at()
            .iter()
            .map(|a| a.failures as f64 * (w.beta - 1.0) / (a.time - w.gamma))
            .sum();
        assert!(slope(lives.at(), &w).abs() < 1e-9 * scale, "{w:?}");
    }

    /// No fit where the likelihood has no maximum inside: shapes below 1 (it grows without bound
    /// towards the first life), fewer than three failure times, no failures.
    #[test]
    fn no_fit_without_a_maximum_inside() {
        assert_eq!(fit(&lives(9, 200, 0.0, 0.7, 1e3, 1e9)), None);
        assert_eq!(fit(&[(5.0, true), (7.0, true), (9.0, false)]), None);
        assert_eq!(
            fit(&[(5.0, true), (7.0, true), (7.0, true), (9.0, false)]),
            None
        );
        assert_eq!(fit(&[(5.0, false), (7.0, false)]), None);
    }

    #[test]
    fn cdf_is_zero_up_to_the_failure_free_life() {
        assert_eq!(cdf(2.0, 100.0, 50.0, 50.0), 0.0);
        assert_eq!(cdf(2.0, 100.0, 50.0, 10.0), 0.0);
        assert_relative_eq!(
            cdf(2.0, 100.0, 50.0, 150.0),
            1.0 - (-1.0f64).exp(),
            max_relative = 1e-15
        );
    }
}
