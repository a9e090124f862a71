//! Dense kernels shared by the refiners: the two point-map conversions on
//! (possibly sub-sampled) bases and the pull-back of a point map, as faer
//! GEMMs on views of the column-major eigenvector matrices.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use fmaps_solve::{NnStrategy, nearest_rows, nearest_rows_hinted_with};
use nalgebra::DMatrix;
use rayon::prelude::*;

/// The first `k` columns of a column-major matrix as a faer view.
pub(crate) fn leading(m: &DMatrix<f64>, k: usize) -> MatRef<'_, f64> {
    let n = m.nrows();
    MatRef::from_column_major_slice(&m.as_slice()[..n * k], n, k)
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

/// `a · b` (or with `b` transposed) into a new nalgebra matrix.
fn product(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> DMatrix<f64> {
    let mut out = DMatrix::<f64>::zeros(a.nrows(), b.ncols());
    let (r, c) = out.shape();
    matmul(
        MatMut::from_column_major_slice_mut(out.as_mut_slice(), r, c),
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
    phi_a: &DMatrix<f64>,
    phi_b: &DMatrix<f64>,
    adjoint: bool,
    hint: Option<&[usize]>,
    strategy: NnStrategy,
) -> Vec<usize> {
    let (kb, ka) = c_ab.shape();
    let c = MatRef::from_column_major_slice(c_ab.as_slice(), kb, ka);
    let (data, queries) = if adjoint {
        (
            copy(leading(phi_a, ka)),
            product(leading(phi_b, kb), c), // n_B x k_A
        )
    } else {
        (
            product(leading(phi_a, ka), c.transpose()), // n_A x k_B
            copy(leading(phi_b, kb)),
        )
    };
    match hint {
        Some(h) if h.len() == queries.nrows() => {
            nearest_rows_hinted_with(&data, &queries, h, strategy)
        }
        _ => nearest_rows(&data, &queries),
    }
}

fn copy(m: MatRef<'_, f64>) -> DMatrix<f64> {
    columns(m.nrows(), m.ncols(), |j, col| {
        for (i, v) in col.iter_mut().enumerate() {
            *v = m[(i, j)];
        }
    })
}

/// An n x k matrix filled column by column, in parallel.
fn columns(n: usize, k: usize, fill: impl Fn(usize, &mut [f64]) + Sync) -> DMatrix<f64> {
    let mut out = vec![0.0; n * k];
    if n > 0 {
        out.par_chunks_mut(n)
            .enumerate()
            .for_each(|(j, col)| fill(j, col));
    }
    DMatrix::from_vec(n, k, out)
}

/// `w[y] Φ_A(T(y), j)` for the first `ka` columns (`w` = 1 without
/// weights), n_B x ka.
fn gathered(t_ba: &[usize], phi_a: &DMatrix<f64>, ka: usize, w: Option<&[f64]>) -> DMatrix<f64> {
    columns(t_ba.len(), ka, |j, col| {
        let src = phi_a.column(j);
        for (y, v) in col.iter_mut().enumerate() {
            *v = src[t_ba[y]] * w.map_or(1.0, |w| w[y]);
        }
    })
}

/// `C_AB = Φ_Bᵀ M_B Π_BA Φ_A` on the first `ka`/`kb` columns (k_B x k_A).
pub(crate) fn pullback(
    t_ba: &[usize],
    phi_a: &DMatrix<f64>,
    ka: usize,
    phi_b: &DMatrix<f64>,
    kb: usize,
    mass_b: &[f64],
) -> DMatrix<f64> {
    let weighted = gathered(t_ba, phi_a, ka, Some(mass_b));
    inner(leading(phi_b, kb), leading(&weighted, ka))
}

/// `Φ_B[:, :kb]ᵀ Y` for the least-squares pull-back on samples.
pub(crate) fn gather_rhs(
    t_ba: &[usize],
    phi_a: &DMatrix<f64>,
    ka: usize,
    phi_b: &DMatrix<f64>,
    kb: usize,
) -> DMatrix<f64> {
    let rows = gathered(t_ba, phi_a, ka, None);
    inner(leading(phi_b, kb), leading(&rows, ka))
}

/// `Φᵀ Φ` (k x k).
pub(crate) fn gram(phi: &DMatrix<f64>) -> DMatrix<f64> {
    let k = phi.ncols();
    inner(leading(phi, k), leading(phi, k))
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
