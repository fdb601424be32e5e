//! The `features` text encoder: precomputed sentence embeddings (SBERT `all-mpnet-base-v2`,
//! as MesaTask uses, computed offline), one row per asset, and one query embedding per
//! instance.
//!
//! The text score is the cosine of the two vectors, computed in f64 from the f32 values (for
//! SBERT's unit vectors it is the dot product MesaTask's code takes). Ranking 12,000 assets
//! for a scene's queries takes one pass over the matrix in 16-bit integers: each row a is
//! stored as s_a·â + r_a (â integers, the scale s_a from the row's largest component, r_a the
//! rounding residual), each query likewise, and â·q̂ is exact in i32 (the quantisation step
//! keeps every sum below 2³¹), vectorised, rows split across threads. The cosine it gives is
//! off by at most e = (s_a·|â|·|r_q| + |r_a|·|q|) / (|a|·|q|), known per row; every row whose
//! upper bound reaches the k-th best lower bound is rescored exactly in f64, and the rows are
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
    /// The rows quantised to ±`levels`.
    quantised: Quantised,
}

/// Rows in 16-bit integers with what bounds their error.
#[derive(Debug, Clone)]
struct Quantised {
    /// The largest integer magnitude: `levels² · dim < 2³¹`.
    levels: f64,
    /// `rows × dim` integers.
    data: Vec<i16>,
    /// s_a of each row.
    scale: Vec<f64>,
    /// |â| of each row.
    int_norm: Vec<f64>,
    /// |r_a| = |a − s_a·â| of each row.
    residual: Vec<f64>,
}

/// One vector quantised: (integers, scale, |â|, |r|).
fn quantise(v: &[f32], levels: f64) -> (Vec<i16>, f64, f64, f64) {
    let max = v.iter().fold(0.0f64, |m, x| m.max(f64::from(x.abs())));
    let scale = if max > 0.0 { max / levels } else { 1.0 };
    let mut ints = Vec::with_capacity(v.len());
    let (mut int_norm, mut residual) = (0.0, 0.0);
    for x in v {
        let x = f64::from(*x);
        // |x / scale| <= levels <= i16::MAX: the cast cannot saturate.
        let q = (x / scale).round().clamp(-levels, levels);
        ints.push(q as i16);
        int_norm += q * q;
        let r = x - scale * q;
        residual += r * r;
    }
    // The residual norm is inflated by a hair so its own rounding cannot undercut it.
    (
        ints,
        scale,
        int_norm.sqrt(),
        residual.sqrt() * (1.0 + 1e-12),
    )
}

/// An exact integer dot product (the caller keeps it below 2³¹), 16 lanes so that the
/// compiler uses multiply-add of 16-bit pairs.
fn dot_i16(a: &[i16], b: &[i16]) -> i32 {
    const LANES: usize = 16;
    let mut acc = [0i32; LANES];
    let mut a_chunks = a.chunks_exact(LANES);
    let mut b_chunks = b.chunks_exact(LANES);
    for (x, y) in (&mut a_chunks).zip(&mut b_chunks) {
        for k in 0..LANES {
            acc[k] += i32::from(x[k]) * i32::from(y[k]);
        }
    }
    let mut sum: i32 = acc.iter().sum();
    for (x, y) in a_chunks.remainder().iter().zip(b_chunks.remainder()) {
        sum += i32::from(*x) * i32::from(*y);
    }
    sum
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

/// Why a feature matrix and its uids do not make a [`FeatureMatrix`] (the caller names the
/// files).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FeaturesError {
    /// The matrix has a different number of rows than there are uids.
    #[error("{rows} rows of features for {uids} uids (expected one uid per row)")]
    RowCount {
        /// Rows of the matrix.
        rows: usize,
        /// Number of uids.
        uids: usize,
    },
    /// The matrix has no columns.
    #[error("the features have 0 columns")]
    NoColumns,
    /// A uid names two rows.
    #[error("uid \"{uid}\" is listed twice (rows {first} and {second})")]
    DuplicateUid {
        /// The uid.
        uid: String,
        /// Its first row.
        first: usize,
        /// Its second row.
        second: usize,
    },
    /// A row is zero, NaN or infinite.
    #[error("row {row} (uid \"{uid}\") has norm {norm} (expected a non-zero finite embedding)")]
    Norm {
        /// The row.
        row: usize,
        /// Its uid.
        uid: String,
        /// Its Euclidean norm.
        norm: f64,
    },
}

impl FeatureMatrix {
    /// Embeddings from a matrix and the uid of each row.
    pub fn new(matrix: Matrix, uids: Vec<String>) -> Result<Self, FeaturesError> {
        if matrix.rows != uids.len() {
            return Err(FeaturesError::RowCount {
                rows: matrix.rows,
                uids: uids.len(),
            });
        }
        if matrix.cols == 0 {
            return Err(FeaturesError::NoColumns);
        }
        let mut seen = std::collections::HashMap::new();
        for (i, uid) in uids.iter().enumerate() {
            if let Some(first) = seen.insert(uid.as_str(), i) {
                return Err(FeaturesError::DuplicateUid {
                    uid: uid.clone(),
                    first,
                    second: i,
                });
            }
        }
        let dim = matrix.cols;
        let levels = ((f64::from(i32::MAX) / dim as f64).sqrt().floor())
            .min(f64::from(i16::MAX))
            .max(1.0);
        let mut norms = Vec::with_capacity(matrix.rows);
        let mut quantised = Quantised {
            levels,
            data: Vec::with_capacity(matrix.data.len()),
            scale: Vec::with_capacity(matrix.rows),
            int_norm: Vec::with_capacity(matrix.rows),
            residual: Vec::with_capacity(matrix.rows),
        };
        for (i, row) in matrix.data.chunks_exact(dim).enumerate() {
            let norm = norm_f64(row);
            if !(norm.is_finite() && norm > 0.0) {
                return Err(FeaturesError::Norm {
                    row: i,
                    uid: uids[i].clone(),
                    norm,
                });
            }
            norms.push(norm);
            let (ints, scale, int_norm, residual) = quantise(row, levels);
            quantised.data.extend(ints);
            quantised.scale.push(scale);
            quantised.int_norm.push(int_norm);
            quantised.residual.push(residual);
        }
        Ok(Self {
            uids,
            dim,
            data: matrix.data,
            norms,
            quantised,
        })
    }

    /// Reads `text_features.npy` and `text_uids.json` (a JSON list of uids, or objathor's
    /// `{"uids": [...]}`).
    pub fn read(npy: &Path, uids: &Path) -> Result<Self, RetrieveError> {
        let matrix =
            read_matrix(npy).map_err(|problem| RetrieveError::file(npy, problem.to_string()))?;
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
        let q = &self.quantised;
        let dim = self.dim;
        // Each query as (integers, scale, |residual|, norm).
        let quantised_queries: Vec<(Vec<i16>, f64, f64, f64)> = queries
            .iter()
            .map(|v| {
                let (ints, scale, _, residual) = quantise(v, q.levels);
                (ints, scale, residual, norm_f64(v))
            })
            .collect();
        // Screening: integer dots of every row with every query, one pass over the matrix.
        const BLOCK: usize = 256;
        let nq = queries.len();
        let mut dots = vec![0i32; n * nq];
        dots.par_chunks_mut(BLOCK * nq)
            .enumerate()
            .for_each(|(block, out)| {
                let first = block * BLOCK;
                for (r, slots) in out.chunks_mut(nq).enumerate() {
                    let i = first + r;
                    let row = &q.data[i * dim..(i + 1) * dim];
                    for (slot, query) in slots.iter_mut().zip(&quantised_queries) {
                        *slot = dot_i16(row, &query.0);
                    }
                }
            });
        quantised_queries
            .par_iter()
            .enumerate()
            .map(|(qi, (_, q_scale, q_residual, q_norm))| {
                let query = queries[qi];
                // [approximate cosine − bound, + bound] of each row.
                let bounds: Vec<(f64, f64)> = (0..n)
                    .map(|i| {
                        let denominator = self.norms[i] * q_norm;
                        let approx =
                            q.scale[i] * q_scale * f64::from(dots[i * nq + qi]) / denominator;
                        let error = (q.scale[i] * q.int_norm[i] * q_residual
                            + q.residual[i] * q_norm)
                            / denominator
                            + 1e-12;
                        (approx - error, approx + error)
                    })
                    .collect();
                let mut lower: Vec<f64> = bounds.iter().map(|b| b.0).collect();
                // The k-th largest lower bound: k rows score at least that much.
                let (_, kth, _) = lower.select_nth_unstable_by(k - 1, |a, b| b.total_cmp(a));
                let threshold = *kth;
                let mut exact: Vec<(usize, f64)> = (0..n)
                    .filter(|i| bounds[*i].1 >= threshold)
                    .map(|i| (i, self.exact(i, query, *q_norm)))
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
        let e = FeatureMatrix::new(m.clone(), vec!["a".into(), "b".into()])
            .expect_err("zero row")
            .to_string();
        assert!(e.starts_with("row 1 (uid \"b\") has norm 0"), "{e}");
        let e = FeatureMatrix::new(m.clone(), vec!["a".into()]).expect_err("count");
        assert_eq!(
            e.to_string(),
            "2 rows of features for 1 uids (expected one uid per row)"
        );
        let e = FeatureMatrix::new(m, vec!["a".into(), "a".into()]).expect_err("dup");
        assert_eq!(e.to_string(), "uid \"a\" is listed twice (rows 0 and 1)");
    }
}
