//! The conversions between point maps and functional maps, once for the
//! whole workspace: the point map of a functional map (direct or adjoint,
//! by exact nearest rows in the spectral embedding) and the functional
//! map of a point map (the pull-back `Φ_Bᵀ M_B Π_BA Φ_A`, or its
//! unweighted form for least squares on samples), as faer GEMMs on
//! row-major copies of the eigenvector matrices ([`BasisRows`], made once
//! and reused: the nearest-neighbour search reads their rows in place, and
//! the pull-back gathers whole rows). The refiners iterate on these; the
//! one-off functions of the crate root call them too.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use fmaps_eigensolve::SpectralBasis;
use fmaps_nearest::{NnParams, nearest_rows};
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::{Error, Result};

/// The first `k` eigenvectors of a basis (or of some of its vertices),
/// row-major: row i holds vertex i's k coordinates.
#[derive(Debug, Clone)]
pub struct BasisRows {
    v: Vec<f64>,
    n: usize,
    k: usize,
}

impl BasisRows {
    /// The first `k` eigenvectors (clamped to the basis size) at every
    /// vertex.
    pub fn new(basis: &SpectralBasis, k: usize) -> BasisRows {
        Self::of(&basis.eigenvectors, k.min(basis.k()), None)
    }

    /// The first `k` eigenvectors (clamped to the basis size) at the
    /// vertices `rows`, in that order (e.g. farthest-point samples).
    pub fn at_vertices(basis: &SpectralBasis, k: usize, rows: &[usize]) -> Result<BasisRows> {
        if let Some((at, &index)) = rows.iter().enumerate().find(|(_, r)| **r >= basis.n()) {
            return Err(Error::IndexOutOfRange {
                at,
                index,
                n: basis.n(),
            });
        }
        Ok(Self::of(&basis.eigenvectors, k.min(basis.k()), Some(rows)))
    }

    /// The first `k` columns of `m`, the rows `rows` (all when `None`).
    fn of(m: &DMatrix<f64>, k: usize, rows: Option<&[usize]>) -> BasisRows {
        let n = rows.map_or(m.nrows(), <[usize]>::len);
        let mut v = vec![0.0; n * k];
        let (nr, all) = (m.nrows(), m.as_slice());
        if k > 0 {
            // Tiles of 32 rows (a tile of 32 x k stays in L1 while the
            // columns are read 32 entries at a time), in parallel.
            v.par_chunks_mut(32 * k).enumerate().for_each(|(b, tile)| {
                let i0 = b * 32;
                let len = tile.len() / k;
                for j in 0..k {
                    let col = &all[j * nr..(j + 1) * nr];
                    match rows {
                        None => {
                            for (t, &x) in col[i0..i0 + len].iter().enumerate() {
                                tile[t * k + j] = x;
                            }
                        }
                        Some(r) => {
                            for (t, &i) in r[i0..i0 + len].iter().enumerate() {
                                tile[t * k + j] = col[i];
                            }
                        }
                    }
                }
            });
        }
        BasisRows { v, n, k }
    }

    /// Row count (vertices).
    pub fn n(&self) -> usize {
        self.n
    }

    /// Columns kept (eigenvectors).
    pub fn k(&self) -> usize {
        self.k
    }

    /// The first `k` columns as a faer view (rows contiguous).
    ///
    /// # Panics
    /// If `k` exceeds [`k`](Self::k).
    #[track_caller]
    pub fn view(&self, k: usize) -> MatRef<'_, f64> {
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
    inner_by_chunks(a.nrows(), a.ncols(), b.ncols(), |r0, rows, part| {
        matmul(
            part,
            Accum::Replace,
            a.subrows(r0, rows).transpose(),
            b.subrows(r0, rows),
            1.0,
            Par::Seq,
        );
    })
}

/// The sum `Σ_i a_iᵀ b_i` (p x q) over `n` rows taken in fixed chunks of
/// [`INNER_CHUNK`] (in parallel, the partial products then summed in
/// order: the same bits for any thread count); `product(r0, rows, part)`
/// writes rows `r0..r0 + rows`'s `aᵀ b` into `part`.
fn inner_by_chunks(
    n: usize,
    p: usize,
    q: usize,
    product: impl Fn(usize, usize, MatMut<'_, f64>) + Sync,
) -> DMatrix<f64> {
    let starts: Vec<usize> = (0..n).step_by(INNER_CHUNK).collect();
    let parts: Vec<Mat<f64>> = starts
        .par_iter()
        .map(|&r0| {
            let mut part = Mat::<f64>::zeros(p, q);
            product(r0, INNER_CHUNK.min(n - r0), part.as_mut());
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

/// How a functional map is converted to a point map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Conversion {
    /// `T_BA(y) = argmin_x ‖C_AB Φ_A(x)ᵀ − Φ_B(y)ᵀ‖`.
    #[default]
    Direct,
    /// `T_BA(y) = argmin_x ‖Φ_A(x)ᵀ − C_ABᵀ Φ_B(y)ᵀ‖`, better when `C_AB`
    /// is far from square-orthonormal.
    Adjoint,
}

/// The point map `T_BA` (one vertex of A per row of `phi_b`) of the
/// k_B x k_A map `c_ab`, on the spectral embeddings direct `(Φ_A Cᵀ,
/// Φ_B)` or adjoint `(Φ_A, Φ_B C)`. `hint`: a guess of the answer per row
/// of `phi_b` (the previous iteration's map), speed only, never the
/// result (ignored when its length is not n_B).
///
/// Errors: `c_ab` larger than the rows hold; empty shapes.
pub fn point_map(
    c_ab: &DMatrix<f64>,
    phi_a: &BasisRows,
    phi_b: &BasisRows,
    conversion: Conversion,
    hint: Option<&[usize]>,
    params: &NnParams,
) -> Result<Vec<usize>> {
    let (kb, ka) = c_ab.shape();
    check_cols("C_AB columns vs eigenvectors of A", ka, phi_a)?;
    check_cols("C_AB rows vs eigenvectors of B", kb, phi_b)?;
    let c = MatRef::from_column_major_slice(c_ab.as_slice(), kb, ka);
    // One guess per query (a vertex of B) or none.
    let hint = hint.filter(|h| h.len() == phi_b.n());
    match conversion {
        Conversion::Adjoint => {
            // n_B x k_A
            let queries = product_rows(phi_b.view(kb), c);
            let queries = MatRef::from_row_major_slice(&queries, phi_b.n(), ka);
            nearest_rows(phi_a.view(ka), queries, hint, params)
        }
        Conversion::Direct => {
            // n_A x k_B
            let data = product_rows(phi_a.view(ka), c.transpose());
            let data = MatRef::from_row_major_slice(&data, phi_a.n(), kb);
            nearest_rows(data, phi_b.view(kb), hint, params)
        }
    }
    .map_err(Error::Search)
}

/// [`point_map`] by the Fast Sinkhorn Filter ([`crate::sinkhorn`])
/// instead of nearest neighbours, on the same embeddings (direct or
/// adjoint): `T_BA`, and the reverse map `T_AB` of the same plan.
///
/// Errors: `c_ab` larger than the rows hold; empty shapes; bad parameters.
pub fn point_map_sinkhorn(
    c_ab: &DMatrix<f64>,
    phi_a: &BasisRows,
    phi_b: &BasisRows,
    conversion: Conversion,
    params: &crate::sinkhorn::Sinkhorn,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let (kb, ka) = c_ab.shape();
    check_cols("C_AB columns vs eigenvectors of A", ka, phi_a)?;
    check_cols("C_AB rows vs eigenvectors of B", kb, phi_b)?;
    let c = MatRef::from_column_major_slice(c_ab.as_slice(), kb, ka);
    let maps = match conversion {
        Conversion::Adjoint => {
            let queries = product_rows(phi_b.view(kb), c);
            let queries = MatRef::from_row_major_slice(&queries, phi_b.n(), ka);
            crate::sinkhorn::sinkhorn_maps(phi_a.view(ka), queries, params)?
        }
        Conversion::Direct => {
            let data = product_rows(phi_a.view(ka), c.transpose());
            let data = MatRef::from_row_major_slice(&data, phi_a.n(), kb);
            crate::sinkhorn::sinkhorn_maps(data, phi_b.view(kb), params)?
        }
    };
    Ok((maps.query_to_data, maps.data_to_query))
}

fn check_cols(what: &'static str, k: usize, rows: &BasisRows) -> Result<()> {
    if k > rows.k() {
        return Err(Error::SizeMismatch {
            what,
            found: k,
            expected: rows.k(),
        });
    }
    Ok(())
}

/// Checks a point map `t_ba` against the rows it indexes and is indexed by.
fn check_map(t_ba: &[usize], phi_a: &BasisRows, phi_b: &BasisRows) -> Result<()> {
    if t_ba.len() != phi_b.n() {
        return Err(Error::SizeMismatch {
            what: "point map T_BA length vs rows of B",
            found: t_ba.len(),
            expected: phi_b.n(),
        });
    }
    if let Some((at, &index)) = t_ba.iter().enumerate().find(|(_, x)| **x >= phi_a.n()) {
        return Err(Error::IndexOutOfRange {
            at,
            index,
            n: phi_a.n(),
        });
    }
    Ok(())
}

/// `w[y] Φ_A(T(y), :ka)` (`w` = 1 without weights), row-major n_B x ka.
fn gathered(t_ba: &[usize], phi_a: &BasisRows, ka: usize, w: Option<&[f64]>) -> Vec<f64> {
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

/// The checks of [`pullback`]'s input.
fn check_pullback(
    t_ba: &[usize],
    phi_a: &BasisRows,
    ka: usize,
    phi_b: &BasisRows,
    kb: usize,
    mass_b: &[f64],
) -> Result<()> {
    check_map(t_ba, phi_a, phi_b)?;
    check_cols("k_A vs eigenvectors of A", ka, phi_a)?;
    check_cols("k_B vs eigenvectors of B", kb, phi_b)?;
    if mass_b.len() != phi_b.n() {
        return Err(Error::SizeMismatch {
            what: "mass of B vs rows of B",
            found: mass_b.len(),
            expected: phi_b.n(),
        });
    }
    Ok(())
}

/// `C_AB = Φ_Bᵀ M_B Π_BA Φ_A` on the first `ka`/`kb` columns (k_B x k_A):
/// the functional map of the point map `t_ba` (one row of `phi_a` per row
/// of `phi_b`), `mass_b` the mass of B's rows.
///
/// Errors: sizes that do not match, indices out of range.
pub fn pullback(
    t_ba: &[usize],
    phi_a: &BasisRows,
    ka: usize,
    phi_b: &BasisRows,
    kb: usize,
    mass_b: &[f64],
) -> Result<DMatrix<f64>> {
    check_pullback(t_ba, phi_a, ka, phi_b, kb, mass_b)?;
    let w = gathered(t_ba, phi_a, ka, Some(mass_b));
    Ok(inner(
        phi_b.view(kb),
        MatRef::from_row_major_slice(&w, t_ba.len(), ka),
    ))
}

/// [`pullback`] of `t_ba` computed from `c_prev`, the pull-back of another
/// point map `t_prev` on the same rows and mass at a size
/// `kb_p x ka_p <= kb x ka`: only the rows of B whose image changed
/// (`t_ba[y] ≠ t_prev[y]`) and the new rows and columns are summed. This is
/// what ZoomOut needs at each step (the map changes at a fraction of the
/// vertices, the size grows by a few columns); the result equals
/// [`pullback`] up to the rounding of a different summation order. When
/// most rows changed it computes [`pullback`] directly.
///
/// Errors: those of [`pullback`]; `t_prev` of another length or out of
/// range; `c_prev` larger than `kb x ka`.
#[allow(clippy::too_many_arguments)]
pub fn pullback_update(
    c_prev: &DMatrix<f64>,
    t_prev: &[usize],
    t_ba: &[usize],
    phi_a: &BasisRows,
    ka: usize,
    phi_b: &BasisRows,
    kb: usize,
    mass_b: &[f64],
) -> Result<DMatrix<f64>> {
    check_map(t_prev, phi_a, phi_b)?;
    let (kbp, kap) = c_prev.shape();
    if kbp > kb || kap > ka {
        return Err(Error::InvalidParameter(format!(
            "the previous pull-back ({kbp} x {kap}) is larger than the new one ({kb} x {ka})"
        )));
    }
    let n = t_ba.len();
    let changed: Vec<usize> = (0..n.min(t_prev.len()))
        .filter(|&y| t_ba[y] != t_prev[y])
        .collect();
    // Products of the update (changed rows of the old block, new rows and
    // new columns) against the full product; the direct one when cheaper.
    let update = changed.len() * kbp * kap + n * (kb * ka - kbp * kap);
    if update >= n * kb * ka {
        return pullback(t_ba, phi_a, ka, phi_b, kb, mass_b);
    }
    check_pullback(t_ba, phi_a, ka, phi_b, kb, mass_b)?;
    let mut c = DMatrix::zeros(kb, ka);
    c.view_mut((0, 0), (kbp, kap)).copy_from(c_prev);
    if !changed.is_empty() && kbp > 0 && kap > 0 {
        // Σ over changed y of m_y Φ_B(y)ᵀ (Φ_A(t(y)) − Φ_A(t_prev(y))).
        let nc = changed.len();
        // Each chunk's rows gathered just before their product (still in
        // cache for it).
        let delta = inner_by_chunks(nc, kbp, kap, |r0, rows, part| {
            let ys = &changed[r0..r0 + rows];
            // (Filled row by row: no zeroing first.)
            let mut d = Vec::with_capacity(rows * kap);
            let mut rows_b = Vec::with_capacity(rows * kbp);
            for &y in ys {
                let (new, old) = (phi_a.row(t_ba[y], kap), phi_a.row(t_prev[y], kap));
                d.extend(new.iter().zip(old).map(|(&p, &q)| mass_b[y] * (p - q)));
                rows_b.extend_from_slice(phi_b.row(y, kbp));
            }
            matmul(
                part,
                Accum::Replace,
                MatRef::from_row_major_slice(&rows_b, rows, kbp).transpose(),
                MatRef::from_row_major_slice(&d, rows, kap),
                1.0,
                Par::Seq,
            );
        });
        let mut old = c.view_mut((0, 0), (kbp, kap));
        old += delta;
    }
    if ka > kap || kb > kbp {
        // The new columns (every row) and the new rows (the old columns).
        let (cols, rows) = border(t_ba, phi_a, (kap, ka), phi_b, (kbp, kb), mass_b);
        c.view_mut((0, kap), (kb, ka - kap)).copy_from(&cols);
        if let Some(rows) = rows {
            c.view_mut((kbp, 0), (kb - kbp, kap)).copy_from(&rows);
        }
    }
    Ok(c)
}

/// The border of [`pullback`] that [`pullback_update`] adds to the
/// previous block, with `w_y = m_y Φ_A(t(y))` (the mass-weighted rows of
/// [`pullback`]'s product): the new columns `Σ_y Φ_B(y)[:kb]ᵀ w_y[kap:ka]`
/// (`kb x (ka − kap)`) and the new rows `Σ_y Φ_B(y)[kbp:kb]ᵀ w_y[:kap]`
/// (`(kb − kbp) x kap`, `None` when empty).
/// Both are thin, and neither gathers whole rows of A (a random read of
/// `ka` values per vertex of B, what bounds [`pullback`]): the columns read
/// the few new coordinates of each `t(y)`, summed over fixed chunks of
/// [`INNER_CHUNK`] vertices of B in parallel, the chunks then in order;
/// the rows first scatter `m_y Φ_B(y)[kbp:kb]` onto the vertices of A
/// (in vertex order), then take one product with A's rows read in order
/// ([`inner`]). Independent of the thread count.
fn border(
    t_ba: &[usize],
    phi_a: &BasisRows,
    (kap, ka): (usize, usize),
    phi_b: &BasisRows,
    (kbp, kb): (usize, usize),
    mass_b: &[f64],
) -> (DMatrix<f64>, Option<DMatrix<f64>>) {
    let (dn, db) = (ka - kap, kb - kbp);
    let n = t_ba.len();
    let mut cols = vec![0.0; dn * kb];
    if dn > 0 && kb > 0 {
        let starts: Vec<usize> = (0..n).step_by(INNER_CHUNK).collect();
        let parts: Vec<Vec<f64>> = starts
            .par_iter()
            .map(|&y0| {
                fmaps_simd::dispatch(NewColumns {
                    t_ba,
                    phi_a,
                    phi_b,
                    mass_b,
                    ys: y0..(y0 + INNER_CHUNK).min(n),
                    a: (kap, ka),
                    kb,
                })
            })
            .collect();
        for part in &parts {
            for (x, v) in cols.iter_mut().zip(part) {
                *x += v;
            }
        }
    }
    // p(x) = Σ_{y: t(y) = x} m_y Φ_B(y)[kbp:kb], one row per vertex of A.
    let rows = (db > 0 && kap > 0).then(|| {
        let mut p = vec![0.0; phi_a.n() * db];
        for (y, &x) in t_ba.iter().enumerate() {
            let (m, b) = (mass_b[y], &phi_b.row(y, kb)[kbp..]);
            for (acc, &v) in p[x * db..(x + 1) * db].iter_mut().zip(b) {
                *acc += m * v;
            }
        }
        // (Transposed: A's columns against p's. A product `db` rows high
        // fills a fraction of the GEMM's micro-kernel.)
        inner(
            phi_a.view(kap),
            MatRef::from_row_major_slice(&p, phi_a.n(), db),
        )
        .transpose()
    });
    (DMatrix::from_column_slice(kb, dn, &cols), rows)
}

/// One chunk of [`border`]'s new columns: plain products and sums in
/// vertex order (no fused multiply-adds: the same bits at every SIMD
/// level).
struct NewColumns<'a> {
    t_ba: &'a [usize],
    phi_a: &'a BasisRows,
    phi_b: &'a BasisRows,
    mass_b: &'a [f64],
    ys: std::ops::Range<usize>,
    a: (usize, usize),
    kb: usize,
}

impl fmaps_simd::Kernel for NewColumns<'_> {
    type Output = Vec<f64>;

    #[inline(always)]
    fn run(self, _level: fmaps_simd::SimdLevel) -> Vec<f64> {
        let ((kap, ka), kb) = (self.a, self.kb);
        let mut cols = vec![0.0; (ka - kap) * kb];
        let end = self.ys.end;
        for y in self.ys {
            // The coordinates of an image a few vertices ahead (anywhere in
            // A's rows): requested now.
            if y + 8 < end {
                fmaps_simd::prefetch(&self.phi_a.row(self.t_ba[y + 8], ka)[kap..]);
            }
            let m = self.mass_b[y];
            let a = &self.phi_a.row(self.t_ba[y], ka)[kap..];
            let b = self.phi_b.row(y, kb);
            for (acc, &v) in cols.chunks_exact_mut(kb).zip(a) {
                let s = m * v;
                for (x, &u) in acc.iter_mut().zip(b) {
                    *x += u * s;
                }
            }
        }
        cols
    }
}

/// `Φ_B[:, :kb]ᵀ Π_BA Φ_A[:, :ka]` without the mass: the right-hand side
/// of the least-squares fit of a map on samples (with [`gram`] of B).
///
/// Errors: sizes that do not match, indices out of range.
pub fn pullback_unweighted(
    t_ba: &[usize],
    phi_a: &BasisRows,
    ka: usize,
    phi_b: &BasisRows,
    kb: usize,
) -> Result<DMatrix<f64>> {
    check_map(t_ba, phi_a, phi_b)?;
    check_cols("k_A vs eigenvectors of A", ka, phi_a)?;
    check_cols("k_B vs eigenvectors of B", kb, phi_b)?;
    let y = gathered(t_ba, phi_a, ka, None);
    Ok(inner(
        phi_b.view(kb),
        MatRef::from_row_major_slice(&y, t_ba.len(), ka),
    ))
}

/// `Φᵀ Φ` (k x k) of the first `k` columns (clamped to the rows held).
pub fn gram(phi: &BasisRows, k: usize) -> DMatrix<f64> {
    let k = k.min(phi.k());
    inner(phi.view(k), phi.view(k))
}
