//! The small dense linear algebra the fits need: symmetric positive definite systems by Cholesky.
//! Matrices are a few rows (parameters or inputs of one fit), so plain `Vec<Vec<f64>>` serves.

/// Solves `a x = b` for a symmetric positive definite `a` by Cholesky; `None` if it is not.
pub(crate) fn solve(a: Vec<Vec<f64>>, b: Vec<f64>) -> Option<Vec<f64>> {
    let l = cholesky(&a)?;
    let n = b.len();
    let mut y = vec![0.0; n];
    for i in 0..n {
        y[i] = (b[i] - (0..i).map(|j| l[i][j] * y[j]).sum::<f64>()) / l[i][i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        x[i] = (y[i] - (i + 1..n).map(|j| l[j][i] * x[j]).sum::<f64>()) / l[i][i];
    }
    Some(x)
}

/// The lower Cholesky factor `L` of a symmetric positive definite `a = L L^T`; `None` if `a` is
/// not positive definite.
pub(crate) fn cholesky(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    cholesky_above(a, 0.0).ok()
}

/// The lower Cholesky factor of `a` when every squared pivot is above `min_pivot`; else the row
/// whose pivot is not.
pub(crate) fn cholesky_above(a: &[Vec<f64>], min_pivot: f64) -> Result<Vec<Vec<f64>>, usize> {
    let n = a.len();
    let mut l = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in 0..=i {
            let sum = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if sum.is_nan() || sum <= min_pivot {
                    return Err(i);
                }
                l[i][i] = sum.sqrt();
            } else {
                l[i][j] = sum / l[j][j];
            }
        }
    }
    Ok(l)
}

/// The smallest squared Cholesky pivot of a Gram matrix of unit columns: 0 when they are linearly
/// dependent, 1 when orthogonal.
pub(crate) fn smallest_pivot(gram: &[Vec<f64>]) -> f64 {
    match cholesky(gram) {
        Some(l) => (0..l.len()).map(|i| l[i][i] * l[i][i]).fold(1.0, f64::min),
        None => 0.0,
    }
}

/// The inverse of a symmetric positive definite matrix, column by column.
pub(crate) fn invert(a: Vec<Vec<f64>>) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let columns: Option<Vec<Vec<f64>>> = (0..n)
        .map(|j| {
            solve(
                a.clone(),
                (0..n).map(|i| f64::from(u8::from(i == j))).collect(),
            )
        })
        .collect();
    columns
}
