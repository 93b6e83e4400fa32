//! Correlated scatter (docs/contract.md "Job", `correlation`): a Gaussian copula over scatter entries
//! of the same `per`. Independent standard normals `z` (drawn, or LHS-stratified uniforms mapped
//! through `Phi^-1`) become `y = L z`, `L` the Cholesky factor of the matrix, and each `y_i` becomes a
//! draw `F_i^-1(Phi(y_i))` of its own (truncated) marginal.

use super::scatter::{Parameter, Per, ScatterSpec};
use crate::error::{FieldError, Pointer, shown};
use crate::linalg::cholesky_above;
use serde::{Deserialize, Serialize};

/// The smallest pivot the Cholesky factorisation accepts: below it the matrix is singular to
/// rounding (a correlation of exactly 1, or rows that repeat one another).
const MIN_PIVOT: f64 = 1e-10;

/// A correlation matrix over scattered parameters, as the user writes it.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorrelationSpec {
    /// The scattered parameters the matrix is over, in its row order: at least two, each scattered
    /// and listed once, all with the same `per`.
    pub parameters: Vec<Parameter>,
    /// The correlation matrix (of the normal scores): square, one row per parameter, symmetric,
    /// 1 on the diagonal, entries from -1 to 1, positive definite.
    pub matrix: Vec<Vec<f64>>,
}

/// A validated correlation: the scatter entries it ties together and its Cholesky factor.
#[derive(Debug, Clone, PartialEq)]
pub struct Correlation {
    per: Per,
    /// Indices into the job's scatter, in the matrix's row order.
    members: Vec<usize>,
    /// The lower-triangular factor `L` with `L L^T` the matrix, row by row.
    cholesky: Vec<Vec<f64>>,
}

impl Correlation {
    /// Checks `spec` against the job's scatter, every fault named below `at` (the `correlation`
    /// member of the job).
    pub fn new(
        spec: &CorrelationSpec,
        scatter: &[ScatterSpec],
        at: &Pointer,
    ) -> Result<Self, Vec<FieldError>> {
        let mut errors = Vec::new();
        let mut fail = |pointer: Pointer, detail: String| {
            errors.push(FieldError {
                pointer: pointer.to_string(),
                detail,
            })
        };
        let names = at.child("parameters");
        if spec.parameters.len() < 2 {
            fail(
                names.clone(),
                format!(
                    "must name at least two scattered parameters, got {}",
                    spec.parameters.len()
                ),
            );
        }
        let mut members = Vec::new();
        for (i, parameter) in spec.parameters.iter().enumerate() {
            let name = parameter.name();
            let Some(index) = scatter.iter().position(|s| s.parameter == *parameter) else {
                fail(
                    names.child(i),
                    format!("`{name}` is not scattered; correlate only parameters in `scatter`"),
                );
                continue;
            };
            if spec.parameters[..i].contains(parameter) {
                fail(names.child(i), format!("`{name}` is listed twice"));
                continue;
            }
            if let Some(&first) = members.first() {
                let (one, other): (&ScatterSpec, &ScatterSpec) = (&scatter[first], &scatter[index]);
                if one.per != other.per {
                    fail(
                        names.child(i),
                        format!(
                            "`{name}` is scattered per {}, `{}` per {}: correlation is only among \
                             scatter entries of the same `per`",
                            other.per.name(),
                            one.parameter.name(),
                            one.per.name()
                        ),
                    );
                    continue;
                }
            }
            members.push(index);
        }
        if spec.matrix.len() == spec.parameters.len() {
            check_matrix(&spec.matrix, &at.child("matrix"), &mut fail);
        } else {
            fail(
                at.child("matrix"),
                format!(
                    "must have one row per parameter ({}), got {}",
                    spec.parameters.len(),
                    spec.matrix.len()
                ),
            );
        }
        if !errors.is_empty() {
            return Err(errors);
        }
        let cholesky = cholesky(&spec.matrix).map_err(|row| {
            vec![FieldError {
                pointer: at.child("matrix").child(row).to_string(),
                detail: format!(
                    "the matrix is not positive definite: its first {} rows and columns are \
                     singular or indefinite (a pivot of the Cholesky factorisation is not above \
                     {MIN_PIVOT:e})",
                    row + 1
                ),
            }]
        })?;
        Ok(Self {
            per: scatter[members[0]].per,
            members,
            cholesky,
        })
    }

    pub fn per(&self) -> Per {
        self.per
    }

    /// The job's scatter entries the matrix is over, in its row order.
    pub fn members(&self) -> &[usize] {
        &self.members
    }

    /// Turns independent standard normals into correlated ones, in place: `z <- L z`.
    pub fn correlate(&self, z: &mut [f64]) {
        for i in (0..z.len()).rev() {
            z[i] = self.cholesky[i]
                .iter()
                .zip(&z[..=i])
                .map(|(l, x)| l * x)
                .sum();
        }
    }
}

/// Square, one row per parameter, entries in [-1, 1], unit diagonal, symmetric.
fn check_matrix(matrix: &[Vec<f64>], at: &Pointer, fail: &mut impl FnMut(Pointer, String)) {
    let n = matrix.len();
    for (i, row) in matrix.iter().enumerate() {
        if row.len() != n {
            fail(
                at.child(i),
                format!(
                    "must have {n} entries (the matrix is square), got {}",
                    row.len()
                ),
            );
            continue;
        }
        for (j, &value) in row.iter().enumerate() {
            let detail = if !(-1.0..=1.0).contains(&value) {
                format!("must be from -1 to 1, got {}", shown(value))
            } else if i == j && value != 1.0 {
                format!("must be 1 (a diagonal entry), got {}", shown(value))
            } else if j > i && matrix[j].get(i).is_some_and(|&mirror| mirror != value) {
                format!(
                    "must equal entry [{j}][{i}] ({}): the matrix is symmetric",
                    matrix[j][i]
                )
            } else {
                continue;
            };
            fail(at.child(i).child(j), detail);
        }
    }
}

/// The lower Cholesky factor of a correlation matrix whose every squared pivot is above
/// [`MIN_PIVOT`]; else the row whose pivot is not.
fn cholesky(matrix: &[Vec<f64>]) -> Result<Vec<Vec<f64>>, usize> {
    cholesky_above(matrix, MIN_PIVOT)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_reproduces_the_matrix() {
        let matrix = vec![
            vec![1.0, 0.5, -0.3],
            vec![0.5, 1.0, 0.2],
            vec![-0.3, 0.2, 1.0],
        ];
        let factor = cholesky(&matrix).unwrap();
        for i in 0..3 {
            for j in 0..=i {
                let product: f64 = (0..=j).map(|k| factor[i][k] * factor[j][k]).sum();
                assert!((product - matrix[i][j]).abs() < 1e-15, "[{i}][{j}]");
            }
        }
    }

    #[test]
    fn an_indefinite_matrix_is_refused_at_the_row_whose_pivot_fails() {
        let matrix = vec![
            vec![1.0, 0.9, 0.9],
            vec![0.9, 1.0, -0.9],
            vec![0.9, -0.9, 1.0],
        ];
        assert_eq!(cholesky(&matrix), Err(2));
        assert_eq!(cholesky(&[vec![1.0, 1.0], vec![1.0, 1.0]]), Err(1));
    }
}
