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
    /// `SRC_i`, in input order.
    pub coefficients: Vec<f64>,
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
    /// that does not vary, or inputs that are linearly dependent (one of them constant, say).
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
        let sxx: Vec<Vec<f64>> = (0..k).map(|r| (0..k).map(|s| c(r, s)).collect()).collect();
        // Inputs that are (near) linear combinations of each other have no coefficients of their
        // own: their correlation matrix is singular to working precision.
        let correlation: Vec<Vec<f64>> = (0..k)
            .map(|r| {
                (0..k)
                    .map(|s| sxx[r][s] / (sxx[r][r] * sxx[s][s]).sqrt())
                    .collect()
            })
            .collect();
        if smallest_pivot(&correlation) < 1e-12 {
            return None;
        }
        let sxy: Vec<f64> = (0..k).map(|r| c(r, k)).collect();
        let beta = solve(sxx, sxy)?;
        let explained: f64 = beta.iter().enumerate().map(|(r, b)| b * c(r, k)).sum();
        Some(StandardisedRegression {
            coefficients: beta
                .iter()
                .enumerate()
                .map(|(r, b)| b * (c(r, r) / syy).sqrt())
                .collect(),
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
            assert!((x - y).abs() < 1e-12);
        }
    }

    #[test]
    fn too_few_samples_a_constant_output_or_a_constant_input_give_nothing() {
        let mut regression = RegressionAccumulator::new(&[0.0], 0.0);
        regression.push(&[1.0], 1.0);
        assert_eq!(regression.standardised(), None);
        let mut constant = RegressionAccumulator::new(&[0.0, 0.0], 0.0);
        for i in 0..10 {
            constant.push(&[f64::from(i), 1.0], f64::from(i));
        }
        assert_eq!(constant.standardised(), None);
    }
}
