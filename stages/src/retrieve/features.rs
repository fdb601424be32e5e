//! The `features` text encoder: precomputed sentence embeddings (SBERT `all-mpnet-base-v2`,
//! as MesaTask uses, computed offline), one row per asset, and one query embedding per
//! instance.
//!
//! The text score is the cosine of the two vectors, computed in f64 from the f32 values (for
//! SBERT's unit vectors it is the dot product MesaTask's code takes). Ranking 12,000 assets
//! for a scene's queries is one pass over the matrix: every row is scored against every query
//! in f32 (vectorised, rows split across threads); then the candidates that can be in the top k
//! — within twice the f32 error bound of the k-th score — are rescored exactly in f64 and
//! sorted by (score descending, uid ascending). The result is the ranking a brute-force f64
//! computation gives, exactly.

use std::path::Path;

use rayon::prelude::*;

use super::npy::{read_matrix, Matrix};
use super::RetrieveError;

/// Asset embeddings: `text_features.npy` with the uid of each row.
#[derive(Debug, Clone)]
pub struct FeatureMatrix {
    uids: Vec<String>,
    dim: usize,
    data: Vec<f32>,
    /// Euclidean norm of each row, f64.
    norms: Vec<f64>,
}

/// The f64 cosine of two f32 vectors: the definition the fast path reproduces exactly.
pub fn cosine_f64(a: &[f32], b: &[f32]) -> f64 {
    let mut dot = 0.0;
    let mut aa = 0.0;
    let mut bb = 0.0;
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (f64::from(*x), f64::from(*y));
        dot += x * y;
        aa += x * x;
        bb += y * y;
    }
    dot / (aa.sqrt() * bb.sqrt())
}

fn norm_f64(a: &[f32]) -> f64 {
    a.iter()
        .map(|x| f64::from(*x) * f64::from(*x))
        .sum::<f64>()
        .sqrt()
}

fn dot_f64(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| f64::from(*x) * f64::from(*y))
        .sum()
}

/// A dot product in f32 with eight independent accumulators (the compiler vectorises it).
fn dot_f32(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let chunks = a.len() / 8;
    for c in 0..chunks {
        let (x, y) = (&a[c * 8..c * 8 + 8], &b[c * 8..c * 8 + 8]);
        for k in 0..8 {
            acc[k] += x[k] * y[k];
        }
    }
    let mut sum: f32 = acc.iter().sum();
    for k in chunks * 8..a.len() {
        sum += a[k] * b[k];
    }
    sum
}

/// An upper bound of |f32 cosine − exact cosine| for vectors of `dim` components: the dot
/// product's rounding error is at most γ(dim + 1)·Σ|a_i b_i| ≤ γ(dim + 1)·|a||b| whatever the
/// summation order (γ(n) = n·u / (1 − n·u), u = 2⁻²⁴), plus a margin for the f64 division.
fn screening_error(dim: usize) -> f64 {
    let u = f64::from(f32::EPSILON) / 2.0;
    let n = (dim + 1) as f64;
    1.01 * n * u / (1.0 - n * u) + 1e-12
}

impl FeatureMatrix {
    /// Embeddings from a matrix and the uid of each row.
    pub fn new(matrix: Matrix, uids: Vec<String>) -> Result<Self, String> {
        if matrix.rows != uids.len() {
            return Err(format!(
                "{} rows of features for {} uids (expected one uid per row)",
                matrix.rows,
                uids.len()
            ));
        }
        if matrix.cols == 0 {
            return Err("the features have 0 columns".to_owned());
        }
        let mut seen = std::collections::HashMap::new();
        for (i, uid) in uids.iter().enumerate() {
            if let Some(first) = seen.insert(uid.as_str(), i) {
                return Err(format!(
                    "uid \"{uid}\" is listed twice (rows {first} and {i})"
                ));
            }
        }
        let mut norms = Vec::with_capacity(matrix.rows);
        for (i, row) in matrix.data.chunks_exact(matrix.cols).enumerate() {
            let norm = norm_f64(row);
            if !(norm.is_finite() && norm > 0.0) {
                return Err(format!(
                    "row {i} (uid \"{}\") has norm {norm} (expected a non-zero finite embedding)",
                    uids[i]
                ));
            }
            norms.push(norm);
        }
        Ok(Self {
            uids,
            dim: matrix.cols,
            data: matrix.data,
            norms,
        })
    }

    /// Reads `text_features.npy` and `text_uids.json` (a JSON list of uids, or objathor's
    /// `{"uids": [...]}`).
    pub fn read(npy: &Path, uids: &Path) -> Result<Self, RetrieveError> {
        let matrix = read_matrix(npy).map_err(|problem| RetrieveError::file(npy, problem))?;
        let text = std::fs::read_to_string(uids)
            .map_err(|e| RetrieveError::file(uids, format!("cannot read: {e}")))?;
        let value: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| RetrieveError::file(uids, format!("is not JSON: {e}")))?;
        let list = value.get("uids").unwrap_or(&value);
        let uid_list: Vec<String> = serde_json::from_value(list.clone()).map_err(|_| {
            RetrieveError::file(
                uids,
                "is not a list of uid strings (expected [\"uid\", ...] or {\"uids\": [...]})",
            )
        })?;
        Self::new(matrix, uid_list).map_err(|problem| {
            RetrieveError::file(npy, format!("{problem} (uids from {})", uids.display()))
        })
    }

    /// The embedding width.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The uid of each row.
    pub fn uids(&self) -> &[String] {
        &self.uids
    }

    fn row(&self, i: usize) -> &[f32] {
        &self.data[i * self.dim..(i + 1) * self.dim]
    }

    /// The exact f64 cosine of row `i` and `query` (whose norm is `query_norm`).
    fn exact(&self, i: usize, query: &[f32], query_norm: f64) -> f64 {
        dot_f64(self.row(i), query) / (self.norms[i] * query_norm)
    }

    /// For each query, the `k` rows of highest cosine, sorted by (score descending, uid
    /// ascending), with exact f64 scores. Every query must have [`Self::dim`] components and a
    /// non-zero norm.
    pub fn top_k(&self, queries: &[&[f32]], k: usize) -> Vec<Vec<(usize, f64)>> {
        let n = self.uids.len();
        let k = k.min(n);
        if k == 0 || queries.is_empty() {
            return vec![Vec::new(); queries.len()];
        }
        let query_norms: Vec<f64> = queries.iter().map(|q| norm_f64(q)).collect();
        // Screening: f32 dots of every row with every query, one pass over the matrix.
        const BLOCK: usize = 256;
        let mut screened = vec![0.0f32; n * queries.len()];
        screened
            .par_chunks_mut(BLOCK * queries.len())
            .enumerate()
            .for_each(|(block, out)| {
                let first = block * BLOCK;
                for (r, scores) in out.chunks_mut(queries.len()).enumerate() {
                    let row = self.row(first + r);
                    for (slot, q) in scores.iter_mut().zip(queries) {
                        *slot = dot_f32(row, q);
                    }
                }
            });
        let margin = 2.0 * screening_error(self.dim);
        queries
            .par_iter()
            .enumerate()
            .map(|(qi, query)| {
                let qn = query_norms[qi];
                let approx: Vec<f64> = (0..n)
                    .map(|i| f64::from(screened[i * queries.len() + qi]) / (self.norms[i] * qn))
                    .collect();
                let mut sorted = approx.clone();
                // The k-th largest approximate score.
                let (_, kth, _) = sorted.select_nth_unstable_by(k - 1, |a, b| b.total_cmp(a));
                let threshold = *kth - margin;
                let mut exact: Vec<(usize, f64)> = (0..n)
                    .filter(|i| approx[*i] >= threshold)
                    .map(|i| (i, self.exact(i, query, qn)))
                    .collect();
                exact.sort_by(|a, b| {
                    b.1.total_cmp(&a.1)
                        .then_with(|| self.uids[a.0].cmp(&self.uids[b.0]))
                });
                exact.truncate(k);
                exact
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_matrix(rows: usize, cols: usize, seed: u64) -> Matrix {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        Matrix {
            rows,
            cols,
            data: (0..rows * cols)
                .map(|_| rng.random_range(-1.0f32..1.0))
                .collect(),
        }
    }

    /// The reference: every cosine in f64, one full sort.
    fn brute_force(m: &Matrix, uids: &[String], query: &[f32], k: usize) -> Vec<(usize, f64)> {
        let mut all: Vec<(usize, f64)> = (0..m.rows)
            .map(|i| (i, cosine_f64(&m.data[i * m.cols..(i + 1) * m.cols], query)))
            .collect();
        all.sort_by(|a, b| b.1.total_cmp(&a.1).then_with(|| uids[a.0].cmp(&uids[b.0])));
        all.truncate(k);
        all
    }

    #[test]
    fn the_fast_ranking_is_the_brute_force_ranking() {
        let m = random_matrix(3000, 64, 1);
        let uids: Vec<String> = (0..m.rows).map(|i| format!("asset_{i:05}")).collect();
        let features = FeatureMatrix::new(m.clone(), uids.clone()).expect("valid");
        let mut queries: Vec<Vec<f32>> = (0..5)
            .map(|i| m.data[i * 97 * m.cols..(i * 97 + 1) * m.cols].to_vec())
            .collect();
        queries.extend(
            random_matrix(10, 64, 2)
                .data
                .chunks(64)
                .map(<[f32]>::to_vec),
        );
        let refs: Vec<&[f32]> = queries.iter().map(Vec::as_slice).collect();
        let fast = features.top_k(&refs, 20);
        for (q, ranked) in refs.iter().zip(&fast) {
            assert_eq!(*ranked, brute_force(&m, &uids, q, 20));
        }
        // An exact embedding of an asset finds it first, with cosine 1.
        assert_eq!(fast[0][0].0, 0);
        assert!((fast[0][0].1 - 1.0).abs() < 1e-12);
    }

    #[test]
    fn ties_are_broken_by_uid() {
        // Four identical rows: the ranking is by uid, whatever the row order.
        let m = Matrix {
            rows: 4,
            cols: 2,
            data: vec![1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0],
        };
        let uids: Vec<String> = ["d", "b", "c", "a"].map(str::to_owned).to_vec();
        let features = FeatureMatrix::new(m, uids).expect("valid");
        let ranked = features.top_k(&[&[2.0, 0.0]], 3);
        assert_eq!(ranked[0].iter().map(|r| r.0).collect::<Vec<_>>(), [3, 1, 2]);
    }

    #[test]
    fn bad_matrices_are_refused() {
        let m = Matrix {
            rows: 2,
            cols: 2,
            data: vec![1.0, 0.0, 0.0, 0.0],
        };
        let e = FeatureMatrix::new(m.clone(), vec!["a".into(), "b".into()]).expect_err("zero row");
        assert!(e.starts_with("row 1 (uid \"b\") has norm 0"), "{e}");
        let e = FeatureMatrix::new(m.clone(), vec!["a".into()]).expect_err("count");
        assert_eq!(
            e,
            "2 rows of features for 1 uids (expected one uid per row)"
        );
        let e = FeatureMatrix::new(m, vec!["a".into(), "a".into()]).expect_err("dup");
        assert_eq!(e, "uid \"a\" is listed twice (rows 0 and 1)");
    }
}
