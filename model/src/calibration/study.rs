//! The coverage studies of the calibration's intervals: synthetic measurements from a known
//! truth, noise drawn per seed, fitted as a user's measurements would be. How often the 95 %
//! intervals hold the truth is the test of `docs/model.md` section 10's claim, run by the model's
//! tests and reported by `bouncewear bench`.

use super::{CalibrationSpec, Observation, Problem, calibrate, normal_equations, simulated};
use crate::linalg::invert;
use crate::scenario::ScenarioSpec;
use crate::stats::SplitMix;
use crate::stats::student_t_975;
use std::collections::BTreeMap;
use std::ops::Range;

/// One calibration case with a known truth.
#[derive(Debug, Clone, Copy)]
pub struct Case {
    /// What is fitted from what, in a few words.
    pub name: &'static str,
    /// Every fitted parameter's dotted path and its true value.
    pub truths: &'static [(&'static str, f64)],
    /// The case's measurements with the noise of `seed`.
    pub spec: fn(seed: u64) -> CalibrationSpec,
}

/// The cases of issue 29: kappa from the first and total bounce times of new contacts together
/// ([`together`]), and kappa with the roughening energy from one device's wear curve
/// ([`wear_curve`]).
pub const CASES: [Case; 2] = [
    Case {
        name: "kappa from first and total bounce times, 40 new contacts",
        truths: &[("material.kappa", 0.33)],
        spec: together,
    },
    Case {
        name: "kappa and roughening energy from a 48 V / 15 A wear curve",
        truths: &[
            ("material.kappa", 0.33),
            ("material.roughening_energy_j", 500.0),
        ],
        spec: wear_curve,
    },
];

/// How often a case's 95 % intervals held the truth over a range of noise draws, per fitted
/// parameter in the order of [`Case::truths`].
#[derive(Debug, Clone, PartialEq)]
pub struct Coverage {
    /// The share of fits whose profile-likelihood interval holds the truth. A fit that fails
    /// counts as not covering.
    pub profile: Vec<f64>,
    /// The share of the same draws on which the exact interval of the model linearised at the
    /// truth holds it (see [`linear_reference`]): 0.95 in expectation by construction, so its
    /// departure from 0.95 is the draws' own luck, which `profile` shares.
    pub linear_reference: Vec<f64>,
}

/// The coverage of `case`'s intervals over the noise draws of `seeds`.
pub fn coverage(case: &Case, seeds: Range<u64>) -> Coverage {
    let draws = seeds.end.saturating_sub(seeds.start).max(1) as f64;
    let mut profile = vec![0_u32; case.truths.len()];
    let mut linear = vec![0_u32; case.truths.len()];
    for seed in seeds {
        let spec = (case.spec)(seed);
        for (count, covers) in linear.iter_mut().zip(linear_reference(case, &spec)) {
            *count += u32::from(covers);
        }
        let Ok(fit) = calibrate(&spec) else {
            continue;
        };
        for (count, (name, truth)) in profile.iter_mut().zip(case.truths) {
            let [lower, upper] = fit.estimates[*name].ci95;
            *count += u32::from(lower <= *truth && *truth <= upper);
        }
    }
    let shares = |counts: Vec<u32>| counts.into_iter().map(|c| f64::from(c) / draws).collect();
    Coverage {
        profile: shares(profile),
        linear_reference: shares(linear),
    }
}

/// A coverage study in disjoint blocks of draws: how far a block's coverage strays from all
/// of them together by chance.
#[derive(Debug, Clone, PartialEq)]
pub struct Blocks {
    /// Each block's seeds and coverage, in order.
    pub blocks: Vec<(Range<u64>, Coverage)>,
    /// Every block's draws together.
    pub all: Coverage,
}

/// The coverage of `case`'s intervals over `count` disjoint blocks of `size` draws, seeds
/// `first` onwards, each block's and all together.
pub fn coverage_by_block(case: &Case, first: u64, size: u64, count: u64) -> Blocks {
    let blocks: Vec<(Range<u64>, Coverage)> = (0..count)
        .map(|b| first + b * size..first + (b + 1) * size)
        .map(|seeds| (seeds.clone(), coverage(case, seeds)))
        .collect();
    // Blocks of equal size: all the draws' share is the blocks' mean share.
    let mean = |share: fn(&Coverage) -> &Vec<f64>| -> Vec<f64> {
        (0..case.truths.len())
            .map(|i| blocks.iter().map(|(_, c)| share(c)[i]).sum::<f64>() / count.max(1) as f64)
            .collect()
    };
    let all = Coverage {
        profile: mean(|c| &c.profile),
        linear_reference: mean(|c| &c.linear_reference),
    };
    Blocks { blocks, all }
}

/// Whether the exact 95 % interval of the model linearised at the truth holds the truth, per
/// parameter, for the measurements `spec` of `case`.
///
/// Each measurement is the truth's simulated value times `1 + noise z`, so `e = measured /
/// simulated - 1` is exactly normal, independent and of equal variance. Regressed on the
/// residuals' Jacobian at the truth (fixed, whatever the noise), the coefficients' t statistics
/// follow Student's t with `n - k` degrees of freedom exactly, and the interval `estimate -+ t
/// se` holds the truth with probability 0.95 exactly. Run on the same draws as the fits, it
/// tells a block of draws that would fail any exact interval from an interval that claims too
/// much. Over seeds 1000 to 1999 the profile intervals agree with it on 997 and 998 of the 1000
/// draws of [`wear_curve`] (kappa, the roughening energy) and on 978 of [`together`], whose
/// total bounce time steps where a bounce appears or vanishes.
pub fn linear_reference(case: &Case, spec: &CalibrationSpec) -> Vec<bool> {
    let problem = Problem::new(spec).expect("a case's measurements are valid");
    let theta: Vec<f64> = case.truths.iter().map(|(_, value)| value.ln()).collect();
    let outcomes = problem.simulate_all(&theta).expect("the truth simulates");
    let noise: Vec<f64> = problem
        .terms
        .iter()
        .map(|&(i, quantity)| {
            let measured = problem.observations[i].measured(quantity).expect("a term");
            measured / simulated(&outcomes[i], quantity) - 1.0
        })
        .collect();
    let at = problem.residuals(&theta).expect("the truth simulates");
    let all: Vec<usize> = (0..theta.len()).collect();
    let jacobian = problem
        .jacobian(&theta, &at, &all)
        .expect("the truth's neighbourhood simulates");
    let (jtj, jte) = normal_equations(&jacobian, &noise);
    let covariance = invert(jtj).expect("a case's parameters are identifiable");
    let k = theta.len();
    let coefficients: Vec<f64> = covariance
        .iter()
        .map(|row| row.iter().zip(&jte).map(|(c, b)| c * b).sum())
        .collect();
    let rss: f64 = noise
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let fitted: f64 = (0..k).map(|a| jacobian[a][i] * coefficients[a]).sum();
            (e - fitted).powi(2)
        })
        .sum();
    let degrees_of_freedom = noise.len() - k;
    let variance = rss / degrees_of_freedom as f64;
    let t = student_t_975(degrees_of_freedom as u64);
    (0..k)
        .map(|a| coefficients[a].abs() <= t * (variance * covariance[a][a]).sqrt())
        .collect()
}

/// 40 new contacts at impact velocities evenly from 0.15 to 0.6 m/s, kappa 0.33, 2 % noise on
/// the first and the total bounce time (issue 29's case; fitted from the defaults).
pub fn together(seed: u64) -> CalibrationSpec {
    let mut truth = ScenarioSpec::default();
    truth.material.kappa = Some(0.33);
    let places: Vec<(u64, f64)> = (0..40)
        .map(|i| (0, 0.15 + 0.45 * f64::from(i) / 39.0))
        .collect();
    CalibrationSpec {
        scenario: ScenarioSpec::default(),
        fit: vec!["material.kappa".into()],
        observations: bounce_times(&truth, &places, 0.02, &mut SplitMix(seed)),
        bounds: BTreeMap::new(),
    }
}

/// One device's wear curve at 48 V / 15 A: the first and total bounce times at 20 points of a
/// 1000-operation test, at impact velocities cycling over 0.15 to 0.6 m/s, from kappa 0.33 and
/// the roughening energy 500 J, with 2 % noise. The early operations fix kappa, the fall of the
/// bounce times along the test the roughening energy. Started from eq. 8's kappa and 800 J.
pub fn wear_curve(seed: u64) -> CalibrationSpec {
    let velocities = [0.15, 0.25, 0.35, 0.45, 0.6];
    let places: Vec<(u64, f64)> = (0..20)
        .map(|i| (50 * i as u64, velocities[i % velocities.len()]))
        .collect();
    wear_curve_at(500.0, &places, seed)
}

/// A wear curve of one velocity, the rig's: the first and total bounce times every 25 operations
/// of 1000, from kappa 0.33 and the roughening energy 300 J (a probe's case, whose total bounce
/// time steps often), fitted as [`wear_curve`].
pub fn one_velocity_wear_curve(seed: u64) -> CalibrationSpec {
    let velocity = 0.223_985_471_683_820_82; // the rig's, derived from its drop
    let places: Vec<(u64, f64)> = (0..40).map(|i| (25 * i, velocity)).collect();
    wear_curve_at(300.0, &places, seed)
}

/// A wear curve at 48 V / 15 A from kappa 0.33 and `roughening_energy_j`, observed at `places`
/// with 2 % noise, fitted for both from eq. 8's kappa and 800 J.
fn wear_curve_at(roughening_energy_j: f64, places: &[(u64, f64)], seed: u64) -> CalibrationSpec {
    let mut truth = ScenarioSpec::default();
    truth.circuit.supply_voltage_v = 48.0;
    truth.circuit.current_a = 15.0;
    truth.material.kappa = Some(0.33);
    truth.material.roughening_energy_j = roughening_energy_j;
    let mut scenario = truth.clone();
    scenario.material.kappa = None;
    scenario.material.roughening_energy_j = 800.0;
    CalibrationSpec {
        scenario,
        fit: vec![
            "material.kappa".into(),
            "material.roughening_energy_j".into(),
        ],
        observations: bounce_times(&truth, places, 0.02, &mut SplitMix(seed)),
        bounds: BTreeMap::new(),
    }
}

/// Observations of `truth` at `places` (`(operation, impact velocity)`), the first and total
/// bounce times each scaled by `1 + noise z`, `z` standard normal from `rng`.
pub(super) fn bounce_times(
    truth: &ScenarioSpec,
    places: &[(u64, f64)],
    noise: f64,
    rng: &mut SplitMix,
) -> Vec<Observation> {
    // The truth's own curve, simulated by the fit's own path (wear included).
    let exact: Vec<Observation> = places
        .iter()
        .map(|&(operation, v)| Observation {
            operation: Some(operation),
            impact_velocity_m_s: Some(v),
            first_bounce_s: Some(1.0),
            total_bounce_s: Some(1.0),
            ..Observation::default()
        })
        .collect();
    let problem = Problem::new(&CalibrationSpec {
        scenario: truth.clone(),
        fit: vec!["material.kappa".into()],
        observations: exact.clone(),
        bounds: BTreeMap::new(),
    })
    .expect("the truth's own observations are valid");
    let kappa = truth.material.kappa.expect("the truth sets kappa");
    let outcomes = problem
        .simulate_all(&[kappa.ln()])
        .expect("the truth simulates");
    exact
        .into_iter()
        .zip(&outcomes)
        .map(|(observation, outcome)| Observation {
            first_bounce_s: Some(
                simulated(outcome, "first_bounce_s") * (1.0 + noise * rng.normal()),
            ),
            total_bounce_s: Some(
                simulated(outcome, "total_bounce_s") * (1.0 + noise * rng.normal()),
            ),
            ..observation
        })
        .collect()
}
