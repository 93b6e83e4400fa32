//! Standardised regression coefficients: the cheap first look at which input drives an output.
//!
//! Least squares of the output `y` on the inputs `x` (with an intercept) over independent samples;
//! the coefficient of input `i`, scaled by the spreads, `SRC_i = beta_i sd(x_i) / sd(y)`, is the
//! change of `y` in its standard deviations per standard deviation of `x_i`. Where the relation is
//! near linear (`r_squared` near 1) and the inputs are independent, `SRC_i^2` is input `i`'s share of
//! the variance, the first-order Sobol' index; where it is not, the Sobol' indices
//! ([`super::sobol`]) are the answer.
//!
//! The accumulator keeps sums of the shifted values and of their products, so groups merge by
//! addition, in an order the caller fixes.

use crate::linalg::{smallest_pivot, solve};
use serde::{Deserialize, Serialize};

/// An input whose centred sum of squares is at most this share of its raw one does not vary:
/// rounding leaves a few ulps of the raw sum where every sample is the same.
const CONSTANT: f64 = 1e-9;

/// Sums for the regression of one output on `k` inputs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegressionAccumulator {
    /// Subtracted from each input and from the output before summing (values near their means),
    /// so that the centred sums are not small differences of large ones.
    shifts: Vec<f64>,
    n: u64,
    /// Sums of `w = (x - shift_x, y - shift_y)`, `k + 1` values.
    sums: Vec<f64>,
    /// Sums of `w_r w_s`, row-major `(k + 1)^2`.
    products: Vec<f64>,
}

/// What the regression found.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StandardisedRegression {
    /// `SRC_i`, in input order; `None` for an input that does not vary (a fixed draw), which
    /// has no standard deviation to scale by and is left out of the fit.
    pub coefficients: Vec<Option<f64>>,
    /// The share of the output's variance the linear fit explains.
    pub r_squared: f64,
}

impl RegressionAccumulator {
    /// For inputs shifted by `input_shifts` (one per input) and the output by `output_shift`.
    pub fn new(input_shifts: &[f64], output_shift: f64) -> Self {
        let width = input_shifts.len() + 1;
        let mut shifts = input_shifts.to_vec();
        shifts.push(output_shift);
        Self {
            shifts,
            n: 0,
            sums: vec![0.0; width],
            products: vec![0.0; width * width],
        }
    }

    /// One sample.
    ///
    /// # Panics
    /// If `x` does not hold one value per input.
    pub fn push(&mut self, x: &[f64], y: f64) {
        let width = self.sums.len();
        assert_eq!(x.len() + 1, width, "one value per input");
        self.n += 1;
        let k = width - 1;
        let w = |r: usize| {
            if r < k {
                x[r] - self.shifts[r]
            } else {
                y - self.shifts[k]
            }
        };
        for r in 0..width {
            let w_r = w(r);
            self.sums[r] += w_r;
            for s in 0..width {
                self.products[r * width + s] += w_r * w(s);
            }
        }
    }

    /// Forgets every sample, keeping the inputs and shifts.
    pub fn clear(&mut self) {
        self.n = 0;
        self.sums.fill(0.0);
        self.products.fill(0.0);
    }

    /// Adds another accumulator's samples (same inputs and shifts).
    ///
    /// # Panics
    /// If the two differ in shape or shifts.
    pub fn merge(&mut self, other: &RegressionAccumulator) {
        assert_eq!(self.shifts, other.shifts, "the same inputs and shifts");
        self.n += other.n;
        self.sums
            .iter_mut()
            .zip(&other.sums)
            .for_each(|(m, t)| *m += t);
        self.products
            .iter_mut()
            .zip(&other.products)
            .for_each(|(m, t)| *m += t);
    }

    /// The standardised coefficients; `None` with no more samples than coefficients, an output
    /// that does not vary, or inputs that are linearly dependent. An input that does not vary at
    /// all (every sample the same value: a fixed draw) is left out of the fit, with no
    /// coefficient, and the others are fitted without it.
    pub fn standardised(&self) -> Option<StandardisedRegression> {
        let width = self.sums.len();
        let k = width - 1;
        let n = self.n as f64;
        if self.n <= width as u64 {
            return None;
        }
        // Centred cross products: C_rs = sum w_r w_s - sum w_r sum w_s / n.
        let c = |r: usize, s: usize| self.products[r * width + s] - self.sums[r] * self.sums[s] / n;
        let syy = c(k, k);
        if syy.is_nan() || syy <= 0.0 {
            return None;
        }
        // A constant input's centred sum of squares is rounding of its raw one (the shift need
        // not be its value), a varying input's about the raw one (the shift is near its mean).
        let varies = |r: usize| c(r, r) > CONSTANT * self.products[r * width + r];
        let inputs: Vec<usize> = (0..k).filter(|&r| varies(r)).collect();
        let sxx: Vec<Vec<f64>> = inputs
            .iter()
            .map(|&r| inputs.iter().map(|&s| c(r, s)).collect())
            .collect();
        // Inputs that are (near) linear combinations of each other have no coefficients of their
        // own: their correlation matrix is singular to working precision.
        let correlation: Vec<Vec<f64>> = (0..inputs.len())
            .map(|r| {
                (0..inputs.len())
                    .map(|s| sxx[r][s] / (sxx[r][r] * sxx[s][s]).sqrt())
                    .collect()
            })
            .collect();
        if !inputs.is_empty() && smallest_pivot(&correlation) < 1e-12 {
            return None;
        }
        let sxy: Vec<f64> = inputs.iter().map(|&r| c(r, k)).collect();
        let beta = if inputs.is_empty() {
            Vec::new()
        } else {
            solve(sxx, sxy)?
        };
        let explained: f64 = beta.iter().zip(&inputs).map(|(b, &r)| b * c(r, k)).sum();
        let mut coefficients = vec![None; k];
        for (b, &r) in beta.iter().zip(&inputs) {
            coefficients[r] = Some(b * (c(r, r) / syy).sqrt());
        }
        Some(StandardisedRegression {
            coefficients,
            r_squared: explained / syy,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::test_util::SplitMix;

    /// `y = 3 x1 - 2 x2 + 0.5 x3 + noise`, with `sd(x) = (1, 2, 4)` and noise sd 1: the SRCs are
    /// `beta_i sd_i / sd(y)` with `var(y) = 9 + 16 + 4 + 1 = 30`.
    #[test]
    fn a_linear_model_gives_its_coefficients() {
        let mut rng = SplitMix(11);
        let mut regression = RegressionAccumulator::new(&[10.0, 0.0, -5.0], 20.0);
        for _ in 0..200_000 {
            let x = [
                10.0 + rng.normal(),
                2.0 * rng.normal(),
                -5.0 + 4.0 * rng.normal(),
            ];
            let y = 3.0 * x[0] - 2.0 * x[1] + 0.5 * x[2] + rng.normal();
            regression.push(&x, y);
        }
        let fit = regression.standardised().unwrap();
        let sd_y = 30.0_f64.sqrt();
        for (got, want) in fit
            .coefficients
            .iter()
            .zip([3.0 / sd_y, -4.0 / sd_y, 2.0 / sd_y])
        {
            let got = got.expect("every input varies");
            assert!((got - want).abs() < 0.01, "{got} {want}");
        }
        assert!(
            (fit.r_squared - 29.0 / 30.0).abs() < 0.005,
            "{}",
            fit.r_squared
        );
    }

    /// Groups merged in order give the whole's coefficients to rounding.
    #[test]
    fn merged_groups_give_the_whole() {
        let mut rng = SplitMix(3);
        let samples: Vec<([f64; 2], f64)> = (0..5000)
            .map(|_| {
                let x = [rng.uniform(), rng.normal()];
                (x, x[0] * x[0] + 0.3 * x[1])
            })
            .collect();
        let mut whole = RegressionAccumulator::new(&[0.5, 0.0], 0.3);
        let mut merged = RegressionAccumulator::new(&[0.5, 0.0], 0.3);
        for chunk in samples.chunks(777) {
            let mut group = RegressionAccumulator::new(&[0.5, 0.0], 0.3);
            for (x, y) in chunk {
                whole.push(x, *y);
                group.push(x, *y);
            }
            merged.merge(&group);
        }
        let (a, b) = (
            whole.standardised().unwrap(),
            merged.standardised().unwrap(),
        );
        for (x, y) in a.coefficients.iter().zip(&b.coefficients) {
            assert!((x.unwrap() - y.unwrap()).abs() < 1e-12);
        }
    }

    #[test]
    fn too_few_samples_a_constant_output_or_dependent_inputs_give_nothing() {
        let mut regression = RegressionAccumulator::new(&[0.0], 0.0);
        regression.push(&[1.0], 1.0);
        assert_eq!(regression.standardised(), None);
        let mut flat = RegressionAccumulator::new(&[0.0], 0.0);
        let mut dependent = RegressionAccumulator::new(&[0.0, 0.0], 0.0);
        for i in 0..10 {
            flat.push(&[f64::from(i)], 2.0);
            dependent.push(&[f64::from(i), 3.0 * f64::from(i)], f64::from(i));
        }
        assert_eq!(flat.standardised(), None);
        assert_eq!(dependent.standardised(), None);
    }

    /// An input that does not vary (shifted by another value than its own, so that its centred
    /// sums are rounding) is left out: the others' coefficients are those of the fit without it.
    #[test]
    fn a_constant_input_is_left_out_of_the_fit() {
        let mut rng = SplitMix(5);
        let mut with = RegressionAccumulator::new(&[0.1, 0.0, 0.0], 0.0);
        let mut without = RegressionAccumulator::new(&[0.0, 0.0], 0.0);
        for _ in 0..5000 {
            let x = [rng.normal(), rng.uniform()];
            let y = 2.0 * x[0] - x[1] + 0.1 * rng.normal();
            with.push(&[0.3, x[0], x[1]], y);
            without.push(&x, y);
        }
        let (with, without) = (
            with.standardised().unwrap(),
            without.standardised().unwrap(),
        );
        assert_eq!(with.coefficients[0], None);
        for (a, b) in with.coefficients[1..].iter().zip(&without.coefficients) {
            assert!((a.unwrap() - b.unwrap()).abs() < 1e-12, "{a:?} {b:?}");
        }
        assert!((with.r_squared - without.r_squared).abs() < 1e-12);
        // Nothing that varies explains nothing.
        let mut none = RegressionAccumulator::new(&[1.0], 0.0);
        for i in 0..10 {
            none.push(&[3.0], f64::from(i));
        }
        let none = none.standardised().unwrap();
        assert_eq!((none.coefficients, none.r_squared), (vec![None], 0.0));
    }
}
