//! Fast Sinkhorn Filters (Pai, Ren, Melzi, Wonka, Ovsjanikov, CVPR 2021):
//! point maps from aligned spectral embeddings by entropic optimal
//! transport on a sparse support, instead of nearest neighbours.
//!
//! Nearest neighbours send many points to one and leave others unhit; the
//! transport plan between uniform distributions on both shapes must cover
//! every point, so its row-wise argmax is much closer to a bijection.
//! Following the paper, the kernel is sparse: the support is the union of
//! each query row's `knn` nearest data rows and each data row's `knn`
//! nearest query rows (so every row and column has entries), with values
//! `exp(-λ d)` of the Euclidean distance `d` and `λ = sharpness / max d`
//! over the support. Sinkhorn's matrix scaling `u ← a / (K v)`,
//! `v ← b / (Kᵀ u)` runs until the column marginals are within
//! `tolerance` (L1) or `max_iter` scalings; the plan is
//! `diag(u) K diag(v)`, and the maps are its row-wise and column-wise
//! argmax.
//!
//! As the sharpness grows the kernel concentrates on each row's nearest
//! neighbour; with no scaling (`max_iter = 0`) the row-wise argmax *is*
//! the nearest neighbour (ties aside), which the tests check.
//!
//! ```
//! use faer::Mat;
//! use fmaps_solve::sinkhorn::{Sinkhorn, sinkhorn_maps};
//!
//! // A shuffled copy: the transport plan recovers the permutation.
//! let data = Mat::from_fn(50, 3, |i, j| ((i * (j + 3)) as f64 * 0.37).sin());
//! let perm: Vec<usize> = (0..50).map(|i| (i * 7) % 50).collect();
//! let queries = Mat::from_fn(50, 3, |i, j| data[(perm[i], j)]);
//! let maps = sinkhorn_maps(data.as_ref(), queries.as_ref(), &Sinkhorn::default())?;
//! assert_eq!(maps.query_to_data, perm);
//! # Ok::<(), fmaps_solve::Error>(())
//! ```

use faer::MatRef;
use fmaps_nearest::k_nearest_rows;

use crate::{Error, Result};

/// Parameters of a Sinkhorn conversion. Defaults: 20 neighbours and at
/// most 500 scalings as in the authors' public sample code; `λ = 50 / max
/// distance` and a marginal tolerance of 0.01 (their sample uses 5 and
/// 0.05 with the sparse kernel, 200 with the full one): on noisy copies
/// (the unit test's set-up) a sharpness of 5 leaves the plan so blurred
/// that its argmax is barely more bijective than nearest neighbours
/// (356 vs 348 of 400 rows hit), while 20-200 hit 391-398 and match more
/// rows correctly (362-365 vs 339).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sinkhorn {
    /// Neighbours per row and per column in the sparse support.
    pub knn: usize,
    /// `λ · max d`: larger is closer to nearest neighbours (less entropy).
    pub sharpness: f64,
    /// Most scalings (0: the kernel's argmax, i.e. nearest neighbours).
    pub max_iter: usize,
    /// Stop when the L1 error of the column marginals is below this.
    pub tolerance: f64,
}

impl Default for Sinkhorn {
    fn default() -> Self {
        Sinkhorn {
            knn: 20,
            sharpness: 50.0,
            max_iter: 500,
            tolerance: 0.01,
        }
    }
}

impl Sinkhorn {
    /// Checks the parameters.
    pub fn check(&self) -> Result<()> {
        if self.knn == 0 || !(self.sharpness > 0.0 && self.sharpness.is_finite()) {
            return Err(Error::InvalidParameter(format!(
                "Sinkhorn needs knn >= 1 and a finite sharpness > 0, got knn {} and sharpness {}",
                self.knn, self.sharpness
            )));
        }
        if !(self.tolerance >= 0.0) {
            return Err(Error::InvalidParameter(format!(
                "Sinkhorn tolerance must be >= 0, got {}",
                self.tolerance
            )));
        }
        Ok(())
    }
}

/// The maps of a Sinkhorn conversion and how the scaling went.
#[derive(Debug, Clone, PartialEq)]
pub struct SinkhornMaps {
    /// For each query row, the data row of its largest plan entry.
    pub query_to_data: Vec<usize>,
    /// For each data row, the query row of its largest plan entry.
    pub data_to_query: Vec<usize>,
    /// Scalings run.
    pub iterations: usize,
    /// L1 error of the column (data) marginals at the end (the row
    /// marginals are exact after each scaling).
    pub marginal_error: f64,
}

/// Transport between the rows of `data` (n_x) and of `queries` (n_q),
/// both uniform, on the sparse k-NN support; see the module docs.
///
/// Errors: rows of different lengths or not finite, an empty side, bad
/// parameters.
pub fn sinkhorn_maps(
    data: MatRef<'_, f64>,
    queries: MatRef<'_, f64>,
    params: &Sinkhorn,
) -> Result<SinkhornMaps> {
    params.check()?;
    let (nx, nq) = (data.nrows(), queries.nrows());
    if nx == 0 || nq == 0 {
        return Err(Error::InvalidParameter(format!(
            "Sinkhorn conversion between {nq} query rows and {nx} data rows: both sides need rows"
        )));
    }
    let (fwd, bwd) = rayon::join(
        || k_nearest_rows(data, queries, params.knn),
        || k_nearest_rows(queries, data, params.knn),
    );
    let (fwd, bwd) = (fwd.map_err(Error::Search)?, bwd.map_err(Error::Search)?);
    // The support: (query, data, distance), union of both directions.
    let mut entries: Vec<(usize, usize, f64)> = Vec::with_capacity(nq * fwd.k + nx * bwd.k);
    for q in 0..nq {
        for (&x, &d) in fwd.indices(q).iter().zip(fwd.distances(q)) {
            entries.push((q, x, d));
        }
    }
    for x in 0..nx {
        for (&q, &d) in bwd.indices(x).iter().zip(bwd.distances(x)) {
            entries.push((q, x, d));
        }
    }
    entries.sort_unstable_by_key(|a| (a.0, a.1));
    entries.dedup_by(|a, b| a.0 == b.0 && a.1 == b.1);
    let dmax = entries.iter().map(|e| e.2).fold(0.0, f64::max);
    let lambda = if dmax > 0.0 {
        params.sharpness / dmax
    } else {
        0.0
    };
    // Row-major (by query) entries; the kernel in [exp(-sharpness), 1].
    let cols: Vec<usize> = entries.iter().map(|e| e.1).collect();
    let kern: Vec<f64> = entries.iter().map(|e| (-lambda * e.2).exp()).collect();
    let mut row_start = vec![0usize; nq + 1];
    for e in &entries {
        row_start[e.0 + 1] += 1;
    }
    for q in 0..nq {
        row_start[q + 1] += row_start[q];
    }
    let (a, b) = (1.0 / nq as f64, 1.0 / nx as f64);
    let mut u = vec![1.0; nq];
    let mut v = vec![1.0; nx];
    let mut iterations = 0;
    let mut marginal_error = f64::INFINITY;
    let mut kt_u = vec![0.0; nx];
    let column_sums = |u: &[f64], out: &mut [f64]| {
        out.iter_mut().for_each(|x| *x = 0.0);
        for q in 0..nq {
            for e in row_start[q]..row_start[q + 1] {
                out[cols[e]] += kern[e] * u[q];
            }
        }
    };
    while iterations < params.max_iter {
        // v ← b / Kᵀu, then u ← a / K v (rows exact afterwards).
        column_sums(&u, &mut kt_u);
        for (vx, s) in v.iter_mut().zip(&kt_u) {
            *vx = if *s > 0.0 { b / s } else { 0.0 };
        }
        for q in 0..nq {
            let s: f64 = (row_start[q]..row_start[q + 1])
                .map(|e| kern[e] * v[cols[e]])
                .sum();
            u[q] = if s > 0.0 { a / s } else { 0.0 };
        }
        iterations += 1;
        if iterations % 10 == 0 || iterations == params.max_iter {
            column_sums(&u, &mut kt_u);
            marginal_error = kt_u.iter().zip(&v).map(|(s, vx)| (s * vx - b).abs()).sum();
            if marginal_error < params.tolerance {
                break;
            }
        }
    }
    // Argmax of the plan u_q K_qx v_x by rows and by columns (ties: the
    // smaller index).
    let mut query_to_data = vec![0usize; nq];
    let mut best_col = vec![(f64::NEG_INFINITY, usize::MAX); nx];
    for q in 0..nq {
        let mut best = (f64::NEG_INFINITY, usize::MAX);
        for e in row_start[q]..row_start[q + 1] {
            let x = cols[e];
            let p = u[q] * kern[e] * v[x];
            if p > best.0 || (p == best.0 && x < best.1) {
                best = (p, x);
            }
            if p > best_col[x].0 {
                best_col[x] = (p, q);
            }
        }
        query_to_data[q] = best.1;
    }
    let data_to_query = best_col.iter().map(|c| c.1).collect();
    Ok(SinkhornMaps {
        query_to_data,
        data_to_query,
        iterations,
        marginal_error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    fn random_rows(n: usize, d: usize, seed: u64) -> Mat<f64> {
        let mut s = seed;
        Mat::from_fn(n, d, |_, j| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) / (1.0 + j as f64)
        })
    }

    fn nearest(data: &Mat<f64>, queries: &Mat<f64>) -> Vec<usize> {
        (0..queries.nrows())
            .map(|q| {
                (0..data.nrows())
                    .min_by(|&i, &j| {
                        let d = |r: usize| -> f64 {
                            (0..data.ncols())
                                .map(|c| (queries[(q, c)] - data[(r, c)]).powi(2))
                                .sum()
                        };
                        d(i).total_cmp(&d(j)).then(i.cmp(&j))
                    })
                    .unwrap()
            })
            .collect()
    }

    #[test]
    fn without_scaling_it_is_nearest_neighbours() {
        let data = random_rows(300, 6, 1);
        let queries = random_rows(200, 6, 2);
        let p = Sinkhorn {
            max_iter: 0,
            ..Sinkhorn::default()
        };
        let maps = sinkhorn_maps(data.as_ref(), queries.as_ref(), &p).unwrap();
        assert_eq!(maps.query_to_data, nearest(&data, &queries));
        assert_eq!(maps.iterations, 0);
    }

    #[test]
    fn scaling_balances_the_marginals_and_spreads_the_map() {
        let correct = |m: &[usize]| m.iter().enumerate().filter(|(i, x)| i == *x).count();
        // Noisy copies: nearest neighbours collide (many queries on one
        // data row), the transport plan spreads them out.
        let data = random_rows(400, 3, 3);
        let noise = random_rows(400, 3, 4);
        let queries = Mat::from_fn(400, 3, |q, c| data[(q, c)] + 0.2 * noise[(q, c)]);
        let nn = nearest(&data, &queries);
        let maps = sinkhorn_maps(data.as_ref(), queries.as_ref(), &Sinkhorn::default()).unwrap();
        let early = Sinkhorn {
            max_iter: 1,
            ..Sinkhorn::default()
        };
        let first = sinkhorn_maps(data.as_ref(), queries.as_ref(), &early).unwrap();
        assert!(maps.marginal_error < 0.05, "{}", maps.marginal_error);
        assert!(first.marginal_error > maps.marginal_error);
        let hit = |m: &[usize]| {
            let mut s = m.to_vec();
            s.sort_unstable();
            s.dedup();
            s.len()
        };
        assert!(
            hit(&maps.query_to_data) as f64 > 1.05 * hit(&nn) as f64,
            "sinkhorn hits {}, nearest neighbours {}",
            hit(&maps.query_to_data),
            hit(&nn)
        );
        assert!(correct(&maps.query_to_data) > correct(&nn));
    }

    #[test]
    fn maps_are_permutation_equivariant_and_exact_on_copies() {
        let data = random_rows(120, 5, 5);
        let perm: Vec<usize> = (0..120).map(|i| (i * 37 + 11) % 120).collect();
        let queries = Mat::from_fn(120, 5, |i, j| data[(perm[i], j)]);
        let maps = sinkhorn_maps(data.as_ref(), queries.as_ref(), &Sinkhorn::default()).unwrap();
        assert_eq!(maps.query_to_data, perm);
        for (q, &x) in perm.iter().enumerate() {
            assert_eq!(maps.data_to_query[x], q);
        }
    }

    #[test]
    fn bad_parameters_are_errors() {
        let data = random_rows(10, 2, 6);
        for p in [
            Sinkhorn {
                knn: 0,
                ..Sinkhorn::default()
            },
            Sinkhorn {
                sharpness: f64::NAN,
                ..Sinkhorn::default()
            },
            Sinkhorn {
                tolerance: -1.0,
                ..Sinkhorn::default()
            },
        ] {
            assert!(sinkhorn_maps(data.as_ref(), data.as_ref(), &p).is_err());
        }
        let empty = Mat::<f64>::zeros(0, 2);
        assert!(sinkhorn_maps(empty.as_ref(), data.as_ref(), &Sinkhorn::default()).is_err());
    }
}
