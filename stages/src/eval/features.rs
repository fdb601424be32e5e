//! FID and KID between two sets of image features (N × D rows, e.g. Inception-v3 pool3
//! features, D = 2048), computed in f64.
//!
//! - **FID** (Heusel et al. 2017, as `pytorch-fid` computes it): ‖μ₁ − μ₂‖² + tr Σ₁ + tr Σ₂ −
//!   2 tr (Σ₁Σ₂)^{1/2}, with the covariances normalised by N − 1 (`numpy.cov`). `pytorch-fid`
//!   takes the real part of `scipy.linalg.sqrtm(Σ₁Σ₂)`; here the trace comes from the symmetric
//!   form tr (Σ₁^{1/2} Σ₂ Σ₁^{1/2})^{1/2}, which has the same eigenvalues (Σ₁Σ₂ is similar to
//!   Σ₁^{1/2}Σ₂Σ₁^{1/2}), through two symmetric eigendecompositions; eigenvalues that rounding
//!   made slightly negative count as 0 (where `sqrtm` gives a tiny imaginary part).
//! - **KID** (Bińkowski et al. 2018): the unbiased estimate of MMD² with the cubic polynomial
//!   kernel k(x, y) = (x·y / D + 1)³, over the two whole sets (`torch-fidelity` and `clean-fid`
//!   average the same estimate over random subsets; the whole-set value is what they estimate).

use nalgebra::{DMatrix, DVector, SymmetricEigen};

/// A feature set: `rows` vectors of `cols` values, row after row.
#[derive(Debug, Clone, PartialEq)]
pub struct Features {
    /// Rows (images).
    pub rows: usize,
    /// Columns (feature dimension).
    pub cols: usize,
    /// `rows × cols` values.
    pub data: Vec<f64>,
}

/// Why two feature sets cannot be compared.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FeatureError {
    /// The dimensions differ.
    #[error(
        "the feature sets have {0} and {1} columns (expected the same feature extractor for both)"
    )]
    Dimension(usize, usize),
    /// Too few rows.
    #[error("a feature set has {0} rows (expected at least 2)")]
    TooFew(usize),
    /// A value is NaN or infinite.
    #[error("row {row}, column {col} is not finite (expected finite features)")]
    NotFinite {
        /// Row.
        row: usize,
        /// Column.
        col: usize,
    },
}

impl Features {
    fn matrix(&self) -> DMatrix<f64> {
        DMatrix::from_row_slice(self.rows, self.cols, &self.data)
    }

    fn check(&self) -> Result<(), FeatureError> {
        if self.rows < 2 {
            return Err(FeatureError::TooFew(self.rows));
        }
        if let Some(i) = self.data.iter().position(|v| !v.is_finite()) {
            return Err(FeatureError::NotFinite {
                row: i / self.cols.max(1),
                col: i % self.cols.max(1),
            });
        }
        Ok(())
    }
}

fn check_pair(a: &Features, b: &Features) -> Result<(), FeatureError> {
    a.check()?;
    b.check()?;
    if a.cols != b.cols {
        return Err(FeatureError::Dimension(a.cols, b.cols));
    }
    Ok(())
}

/// Mean and covariance (normalised by N − 1) of the rows.
fn mean_and_covariance(x: &DMatrix<f64>) -> (DVector<f64>, DMatrix<f64>) {
    let n = x.nrows() as f64;
    let mean: DVector<f64> = x.row_mean().transpose();
    let mut centred = x.clone();
    for mut row in centred.row_iter_mut() {
        row -= mean.transpose();
    }
    let cov = centred.transpose() * &centred / (n - 1.0);
    (mean, cov)
}

/// The square root of a symmetric positive semi-definite matrix (negative eigenvalues from
/// rounding count as 0).
fn sqrt_psd(m: DMatrix<f64>) -> DMatrix<f64> {
    let eigen = SymmetricEigen::new(m);
    let roots = eigen.eigenvalues.map(|l| l.max(0.0).sqrt());
    &eigen.eigenvectors * DMatrix::from_diagonal(&roots) * eigen.eigenvectors.transpose()
}

/// The Fréchet distance of the Gaussians fitted to two feature sets (FID).
pub fn fid(real: &Features, generated: &Features) -> Result<f64, FeatureError> {
    check_pair(real, generated)?;
    let (mu1, sigma1) = mean_and_covariance(&real.matrix());
    let (mu2, sigma2) = mean_and_covariance(&generated.matrix());
    Ok(frechet_distance(&mu1, &sigma1, &mu2, &sigma2))
}

/// ‖μ₁ − μ₂‖² + tr Σ₁ + tr Σ₂ − 2 tr (Σ₁^{1/2} Σ₂ Σ₁^{1/2})^{1/2}.
pub fn frechet_distance(
    mu1: &DVector<f64>,
    sigma1: &DMatrix<f64>,
    mu2: &DVector<f64>,
    sigma2: &DMatrix<f64>,
) -> f64 {
    let root1 = sqrt_psd(sigma1.clone());
    let mut inner = &root1 * sigma2 * &root1;
    // Symmetrise what rounding made slightly asymmetric.
    inner = (&inner + inner.transpose()) * 0.5;
    let tr_sqrt: f64 = SymmetricEigen::new(inner)
        .eigenvalues
        .iter()
        .map(|l| l.max(0.0).sqrt())
        .sum();
    (mu1 - mu2).norm_squared() + sigma1.trace() + sigma2.trace() - 2.0 * tr_sqrt
}

/// The unbiased MMD² estimate with the kernel (x·y/D + 1)³ (KID).
pub fn kid(real: &Features, generated: &Features) -> Result<f64, FeatureError> {
    check_pair(real, generated)?;
    let d = real.cols as f64;
    let x = real.matrix();
    let y = generated.matrix();
    let kernel =
        |a: &DMatrix<f64>, b: &DMatrix<f64>| (a * b.transpose()).map(|v| (v / d + 1.0).powi(3));
    let kxx = kernel(&x, &x);
    let kyy = kernel(&y, &y);
    let kxy = kernel(&x, &y);
    let (m, n) = (real.rows as f64, generated.rows as f64);
    let off_diagonal = |k: &DMatrix<f64>| k.sum() - k.trace();
    Ok(
        off_diagonal(&kxx) / (m * (m - 1.0)) + off_diagonal(&kyy) / (n * (n - 1.0))
            - 2.0 * kxy.sum() / (m * n),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn features(rows: usize, cols: usize, f: impl Fn(usize, usize) -> f64) -> Features {
        Features {
            rows,
            cols,
            data: (0..rows * cols).map(|i| f(i / cols, i % cols)).collect(),
        }
    }

    #[test]
    fn identical_sets_have_no_distance_and_a_shift_is_its_square() {
        let a = features(40, 5, |r, c| {
            ((r * 7 + c * 3) % 11) as f64 * 0.3 + (r as f64).sin()
        });
        assert_relative_eq!(fid(&a, &a).expect("fid"), 0.0, epsilon = 1e-8);
        let shifted = Features {
            data: a.data.iter().map(|v| v + 2.0).collect(),
            ..a.clone()
        };
        // Same covariance, means 2 apart in each of 5 dimensions: 5 · 2².
        assert_relative_eq!(fid(&a, &shifted).expect("fid"), 20.0, epsilon = 1e-8);
        // KID of a set with itself is small but, unbiased, not exactly 0; with a shift it grows.
        assert!(kid(&a, &shifted).expect("kid") > kid(&a, &a).expect("kid").abs() * 10.0);
    }

    #[test]
    fn mismatched_or_short_sets_are_refused() {
        let a = features(10, 4, |r, c| (r + c) as f64);
        let b = features(10, 3, |r, c| (r * c) as f64);
        assert_eq!(fid(&a, &b), Err(FeatureError::Dimension(4, 3)));
        assert_eq!(
            kid(&a, &features(1, 4, |_, _| 0.0)),
            Err(FeatureError::TooFew(1))
        );
        let mut nan = a.clone();
        nan.data[6] = f64::NAN;
        assert_eq!(
            fid(&nan, &a),
            Err(FeatureError::NotFinite { row: 1, col: 2 })
        );
    }
}
