//! Dense kernels shared by the refiners: the two point-map conversions on
//! (possibly sub-sampled) bases and the pull-back of a point map, as faer
//! GEMMs on row-major copies of the eigenvector matrices (made once per
//! refinement: the nearest-neighbour search reads their rows in place, and
//! the pull-back gathers whole rows).

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use fmaps_nn::{NnParams, NnStrategy, nearest_rows};
use nalgebra::DMatrix;
use rayon::prelude::*;

/// The first `k` eigenvectors of a basis (or of some of its vertices),
/// row-major: row i holds vertex i's k coordinates.
pub(crate) struct Rows {
    v: Vec<f64>,
    n: usize,
    k: usize,
}

impl Rows {
    /// The first `k` columns of `m`, the rows `rows` (all when `None`).
    pub(crate) fn of(m: &DMatrix<f64>, k: usize, rows: Option<&[usize]>) -> Rows {
        let n = rows.map_or(m.nrows(), <[usize]>::len);
        let mut v = vec![0.0; n * k];
        if k > 0 {
            // Blocks of 8 rows, column by column (contiguous reads of each
            // column for consecutive rows), in parallel.
            v.par_chunks_mut(8 * k).enumerate().for_each(|(b, block)| {
                let i0 = b * 8;
                for j in 0..k {
                    let col = m.column(j);
                    let col = col.as_slice();
                    for (t, row) in block.chunks_exact_mut(k).enumerate() {
                        row[j] = col[rows.map_or(i0 + t, |r| r[i0 + t])];
                    }
                }
            });
        }
        Rows { v, n, k }
    }

    /// Row count.
    pub(crate) fn n(&self) -> usize {
        self.n
    }

    /// The first `k` columns as a faer view (rows contiguous).
    pub(crate) fn view(&self, k: usize) -> MatRef<'_, f64> {
        assert!(k <= self.k, "{k} columns of {}", self.k);
        MatRef::from_row_major_slice_with_stride(&self.v, self.n, k, self.k.max(1))
    }

    /// The first `k` coordinates of row `i`.
    fn row(&self, i: usize, k: usize) -> &[f64] {
        &self.v[i * self.k..i * self.k + k]
    }
}

/// Rows per partial product of [`inner`].
const INNER_CHUNK: usize = 1024;

/// `aᵀ b` for tall `a` (n x p) and `b` (n x q): partial products over
/// fixed chunks of 1024 rows in parallel, summed in order (the small
/// output leaves a GEMM little to split otherwise; the fixed chunks keep
/// the result independent of the thread count).
fn inner(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> DMatrix<f64> {
    let (n, p, q) = (a.nrows(), a.ncols(), b.ncols());
    let starts: Vec<usize> = (0..n).step_by(INNER_CHUNK).collect();
    let parts: Vec<Mat<f64>> = starts
        .par_iter()
        .map(|&r0| {
            let rows = INNER_CHUNK.min(n - r0);
            let mut part = Mat::<f64>::zeros(p, q);
            matmul(
                part.as_mut(),
                Accum::Replace,
                a.subrows(r0, rows).transpose(),
                b.subrows(r0, rows),
                1.0,
                Par::Seq,
            );
            part
        })
        .collect();
    DMatrix::from_fn(p, q, |i, j| parts.iter().map(|m| m[(i, j)]).sum())
}

/// `a · b` into a new row-major n x q buffer.
fn product_rows(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Vec<f64> {
    let (n, q) = (a.nrows(), b.ncols());
    let mut out = vec![0.0; n * q];
    matmul(
        MatMut::from_row_major_slice_mut(&mut out, n, q),
        Accum::Replace,
        a,
        b,
        1.0,
        Par::rayon(0),
    );
    out
}

/// Spectral embeddings of A (data) and B (queries) for the conversion of a
/// k_B x k_A map: direct `(Φ_A Cᵀ, Φ_B)`, adjoint `(Φ_A, Φ_B C)`.
/// `phi_a`/`phi_b` hold at least k_A / k_B columns. `hint`: a guess of the
/// answer (the previous iteration's map), searched with `strategy`; speed
/// only, never the result.
pub(crate) fn point_map(
    c_ab: &DMatrix<f64>,
    phi_a: &Rows,
    phi_b: &Rows,
    adjoint: bool,
    hint: Option<&[usize]>,
    strategy: NnStrategy,
) -> Result<Vec<usize>, fmaps_nn::Error> {
    let (kb, ka) = c_ab.shape();
    let params = NnParams::with_strategy(strategy);
    let c = MatRef::from_column_major_slice(c_ab.as_slice(), kb, ka);
    // One guess per query (a vertex of B) or none.
    let hint = hint.filter(|h| h.len() == phi_b.n());
    if adjoint {
        // n_B x k_A
        let queries = product_rows(phi_b.view(kb), c);
        let queries = MatRef::from_row_major_slice(&queries, phi_b.n(), ka);
        nearest_rows(phi_a.view(ka), queries, hint, &params)
    } else {
        // n_A x k_B
        let data = product_rows(phi_a.view(ka), c.transpose());
        let data = MatRef::from_row_major_slice(&data, phi_a.n(), kb);
        nearest_rows(data, phi_b.view(kb), hint, &params)
    }
}

/// `w[y] Φ_A(T(y), :ka)` (`w` = 1 without weights), row-major n_B x ka.
fn gathered(t_ba: &[usize], phi_a: &Rows, ka: usize, w: Option<&[f64]>) -> Vec<f64> {
    let mut out = vec![0.0; t_ba.len() * ka];
    if ka > 0 {
        out.par_chunks_mut(64 * ka)
            .enumerate()
            .for_each(|(b, block)| {
                for (t, row) in block.chunks_exact_mut(ka).enumerate() {
                    let y = b * 64 + t;
                    let scale = w.map_or(1.0, |w| w[y]);
                    for (x, &v) in row.iter_mut().zip(phi_a.row(t_ba[y], ka)) {
                        *x = v * scale;
                    }
                }
            });
    }
    out
}

/// `C_AB = Φ_Bᵀ M_B Π_BA Φ_A` on the first `ka`/`kb` columns (k_B x k_A).
pub(crate) fn pullback(
    t_ba: &[usize],
    phi_a: &Rows,
    ka: usize,
    phi_b: &Rows,
    kb: usize,
    mass_b: &[f64],
) -> DMatrix<f64> {
    let w = gathered(t_ba, phi_a, ka, Some(mass_b));
    inner(
        phi_b.view(kb),
        MatRef::from_row_major_slice(&w, t_ba.len(), ka),
    )
}

/// `Φ_B[:, :kb]ᵀ Y` for the least-squares pull-back on samples.
pub(crate) fn gather_rhs(
    t_ba: &[usize],
    phi_a: &Rows,
    ka: usize,
    phi_b: &Rows,
    kb: usize,
) -> DMatrix<f64> {
    let y = gathered(t_ba, phi_a, ka, None);
    inner(
        phi_b.view(kb),
        MatRef::from_row_major_slice(&y, t_ba.len(), ka),
    )
}

/// `Φᵀ Φ` (k x k) of the first `k` columns.
pub(crate) fn gram(phi: &Rows, k: usize) -> DMatrix<f64> {
    inner(phi.view(k), phi.view(k))
}

/// The nearest orthonormal matrix `U Vᵀ` (with the rectangular identity
/// between them for k_B ≠ k_A): orthogonal Procrustes.
pub(crate) fn nearest_orthonormal(c: DMatrix<f64>) -> DMatrix<f64> {
    let (kb, ka) = c.shape();
    let svd = c.svd(true, true);
    let (u, vt) = (svd.u.expect("u requested"), svd.v_t.expect("v_t requested"));
    let r = kb.min(ka);
    u.columns(0, r) * vt.rows(0, r)
}
