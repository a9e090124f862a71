//! The normal equations of the energy with operator terms, solved by
//! conjugate gradients in f64 preconditioned by a Cholesky factor in f32.
//! (tidy: long file: assembly, structured products and the solver share
//! one private state, and the tests check them against each other.)
//!
//! The normal equations `H vec(C) = b` (H is half the Hessian of the
//! energy, size k_A·k_B less the fixed column) are symmetric positive
//! definite and, on real shape pairs, well conditioned: on the FAUST pair
//! tr_reg_002 → tr_reg_007 with the default parameters (k = 50, WKS, the
//! orientation term on) the condition number of H is 4.7e2. So the
//! expensive dense factorization can run in single precision (twice the
//! SIMD width of f64, half the memory) and serve as the preconditioner of
//! conjugate gradients whose products with H are exact f64 matrix
//! products in the structured form
//!
//! ```text
//! H C = w_descr C A Aᵀ + w_lap mask ∘ C
//!     + Σ_q w_q [(C X_q − Y_q C) X_qᵀ − Y_qᵀ (C X_q − Y_q C)]
//! ```
//!
//! (four GEMMs of the stacked operators, ~4 k³ p multiply-adds, no H).
//! Each iteration gains about as many digits as the f32 factor is
//! accurate (−log10(cond · 2⁻²⁴) ≈ 4–5 here), so the residual reaches
//! rounding level (1e-14 of the right-hand side) in 3–4 iterations and
//! the result is the f64 minimizer, not an f32 approximation of it. When
//! the f32 factorization fails or the iteration stalls (a very badly
//! conditioned or singular H), the caller falls back to the dense f64
//! Cholesky.
//!
//! The f32 matrix is assembled column block by column block (one block per
//! column of C): the cross terms `Σ_q w_q (X_q[j,l] Y_q[i,r] + X_q[l,j]
//! Y_q[r,i])` of block l are a GEMM of the stacked, vectorized operators
//! of B (k_B² x 2p) with a 2p x (k_A − l) matrix of entries of the
//! operators of A (one GEMM per group of ~48 such columns), written
//! straight into the lower triangle; every entry is written once. The
//! right-hand side's coupling to a fixed first column is a rank-one
//! update, not a product with H.
//!
//! On one thread the factorization is faer's (left-looking); on more, the
//! right-looking one of `chol` with look-ahead (1.7x on two threads where
//! faer's gains 1.3x), and the products with H split their 2p cross-term
//! blocks over two threads.

use faer::linalg::matmul::matmul;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef, Par};

use rayon::prelude::*;

use crate::FmapEnergy;

/// Relative residual at which the iteration stops.
const TOL: f64 = 1e-14;
/// Relative residual accepted when the iteration stops improving (the
/// energy is then within ~(1e-10)² relative of its minimum).
const ACCEPT: f64 = 1e-10;
/// Iterations before giving up (and falling back to f64).
const MAX_ITER: usize = 60;

/// The structured normal equations of an energy with operator terms.
pub(crate) struct Normal {
    ka: usize,
    kb: usize,
    /// Fixed leading columns of C (0 or 1).
    j0: usize,
    /// Number of operator pairs.
    p: usize,
    /// `w_descr A Aᵀ` (k_A x k_A).
    aat: Mat<f64>,
    /// `w_lap mask` (k_B x k_A).
    mask: Mat<f64>,
    /// `[√w_1 X_1 … √w_p X_p]` (k_A x k_A·p).
    xs: Mat<f64>,
    /// `[√w_1 Y_1; …; √w_p Y_p; √w_1 Y_1ᵀ; …; √w_p Y_pᵀ]` (2p·k_B x k_B).
    ys2: Mat<f64>,
    /// `[√w_1 X_1ᵀ; …; √w_p X_pᵀ; √w_1 X_1; …; √w_p X_p]` (2p·k_A x k_A).
    xs2: Mat<f64>,
    /// `K = w_descr A Aᵀ + Σ_q w_q X_q X_qᵀ` (k_A x k_A).
    kx: Mat<f64>,
    /// `K_Y = Σ_q w_q Y_qᵀ Y_q` (k_B x k_B).
    kyy: Mat<f64>,
    /// Added to the diagonal of H: 1e-13 of its largest free diagonal
    /// entry (as the dense path's first ridge).
    ridge: f64,
    /// Parallel factorization and products (large H: k_A k_B ≥ 400).
    par: Par,
}

impl Normal {
    pub(crate) fn new(e: &FmapEnergy, ka: usize, kb: usize, j0: usize) -> Normal {
        let terms: Vec<_> = e.op_terms().collect();
        let p = terms.len();
        let mut xs = Mat::<f64>::zeros(ka, ka * p);
        let mut ys2 = Mat::<f64>::zeros(2 * p * kb, kb);
        let mut xs2 = Mat::<f64>::zeros(2 * p * ka, ka);
        // Column `c` of a column-major faer matrix as a slice.
        fn col(m: &mut Mat<f64>, c: usize) -> &mut [f64] {
            m.col_mut(c).try_as_col_major_mut().unwrap().as_slice_mut()
        }
        for (q, (w, (x, y))) in terms.iter().enumerate() {
            let s = w.sqrt();
            let (x, y) = (x.as_slice(), y.as_slice());
            for l in 0..ka {
                let src = &x[l * ka..(l + 1) * ka];
                for (d, v) in col(&mut xs, q * ka + l).iter_mut().zip(src) {
                    *d = s * v;
                }
                // xs2 block q: (√w X_q)ᵀ; block p + q: √w X_q.
                let dst = &mut col(&mut xs2, l)[(p + q) * ka..(p + q + 1) * ka];
                for (d, v) in dst.iter_mut().zip(src) {
                    *d = s * v;
                }
                let dst = &mut col(&mut xs2, l)[q * ka..(q + 1) * ka];
                for (j, d) in dst.iter_mut().enumerate() {
                    *d = s * x[l + ka * j];
                }
            }
            // ys2 block q: √w Y_q; block p + q: (√w Y_q)ᵀ.
            for r in 0..kb {
                let src = &y[r * kb..(r + 1) * kb];
                let dst = &mut col(&mut ys2, r)[q * kb..(q + 1) * kb];
                for (d, v) in dst.iter_mut().zip(src) {
                    *d = s * v;
                }
                let dst = &mut col(&mut ys2, r)[(p + q) * kb..(p + q + 1) * kb];
                for (i, d) in dst.iter_mut().enumerate() {
                    *d = s * y[r + kb * i];
                }
            }
        }
        let a = MatRef::from_column_major_slice(e.descr_a.as_slice(), ka, e.descr_a.ncols());
        let mut aat = Mat::<f64>::zeros(ka, ka);
        matmul(
            aat.as_mut(),
            Accum::Replace,
            a,
            a.transpose(),
            e.w_descr,
            Par::Seq,
        );
        let mask = Mat::from_fn(kb, ka, |i, j| e.w_lap * e.lap_mask[(i, j)]);
        // By size only, never by the number of threads: the parallel
        // path's arithmetic (its Cholesky, the split of the cross terms)
        // is the same on any number of threads, so C is too.
        let par = if ka * kb >= 400 {
            Par::rayon(0)
        } else {
            Par::Seq
        };
        let mut n = Normal {
            ka,
            kb,
            j0,
            p,
            aat,
            mask,
            xs,
            ys2,
            xs2,
            kx: Mat::zeros(0, 0),
            kyy: Mat::zeros(0, 0),
            ridge: 0.0,
            par,
        };
        (n.kx, n.kyy) = n.kronecker_factors();
        n.ridge = 1e-13 * n.max_free_diagonal();
        n
    }

    /// Number of unknowns.
    pub(crate) fn n(&self) -> usize {
        self.kb * (self.ka - self.j0)
    }

    /// `K = w_descr A Aᵀ + Σ_q w_q X_q X_qᵀ` and `Σ_q w_q Y_qᵀ Y_q`.
    fn kronecker_factors(&self) -> (Mat<f64>, Mat<f64>) {
        let mut kx = self.aat.clone();
        matmul(
            kx.as_mut(),
            Accum::Add,
            self.xs.as_ref(),
            self.xs.transpose(),
            1.0,
            Par::Seq,
        );
        let mut kyy = Mat::<f64>::zeros(self.kb, self.kb);
        matmul(
            kyy.as_mut(),
            Accum::Replace,
            self.ys2.as_ref().subrows(0, self.p * self.kb).transpose(),
            self.ys2.as_ref().subrows(0, self.p * self.kb),
            1.0,
            Par::Seq,
        );
        (kx, kyy)
    }

    /// The largest diagonal entry of H over the free unknowns (0 if none).
    fn max_free_diagonal(&self) -> f64 {
        let (ka, kb) = (self.ka, self.kb);
        let (kx, kyy) = (&self.kx, &self.kyy);
        let mut m = 0.0f64;
        for l in self.j0..ka {
            for r in 0..kb {
                let cross: f64 = (0..self.p)
                    .map(|q| self.xs[(l, q * ka + l)] * self.ys2[(q * kb + r, r)])
                    .sum();
                m = m.max(kx[(l, l)] + kyy[(r, r)] + self.mask[(r, l)] - 2.0 * cross);
            }
        }
        m
    }

    /// Buffers for [`apply_into`](Self::apply_into), reused across the
    /// products of one solve.
    pub(crate) fn scratch(&self) -> Scratch {
        let (ka, kb) = (self.ka, self.kb);
        Scratch {
            c: Mat::zeros(kb, ka),
            out: Mat::zeros(kb, ka),
            out2: Mat::zeros(kb, ka),
            vh: Mat::zeros(kb, 2 * self.p * ka),
        }
    }

    /// `H C` for a full k_B x k_A matrix C (the ridge included).
    #[cfg(test)]
    fn apply(&self, c: MatRef<'_, f64>) -> Mat<f64> {
        let mut s = self.scratch();
        self.apply_into(c, &mut s.out, &mut s.out2, &mut s.vh);
        s.out
    }

    /// `out = H C` as
    /// `C K + K_Y C + (mask + ridge) ∘ C − Σ_q w_q (Y_q C X_qᵀ + Y_qᵀ C X_q)`
    /// (K and K_Y the Kronecker factors): the blocks `Y_q C`, `Y_qᵀ C` are
    /// written side by side into `vh` (k_B x 2p·k_A), and the cross terms
    /// are then one GEMM of `vh` with the stacked `X_qᵀ`, `X_q`. With more
    /// than one thread the 2p blocks are split in two halves, the second
    /// summed into `out2` on another thread and added at the end.
    fn apply_into(
        &self,
        c: MatRef<'_, f64>,
        out: &mut Mat<f64>,
        out2: &mut Mat<f64>,
        vh: &mut Mat<f64>,
    ) {
        let (ka, p) = (self.ka, self.p);
        let parallel = !matches!(self.par, Par::Seq) && p > 0;
        let half = if parallel { p } else { 2 * p };
        let (vh1, vh2) = vh.as_mut().split_at_col_mut(half * ka);
        let first = |out: &mut Mat<f64>| {
            for j in 0..ka {
                let o = out
                    .col_mut(j)
                    .try_as_col_major_mut()
                    .unwrap()
                    .as_slice_mut();
                let m = self.mask.col(j).try_as_col_major().unwrap().as_slice();
                for ((o, m), c) in o.iter_mut().zip(m).zip(c.col(j).iter()) {
                    *o = (m + self.ridge) * c;
                }
            }
            matmul(out.as_mut(), Accum::Add, c, self.kx.as_ref(), 1.0, Par::Seq);
            matmul(
                out.as_mut(),
                Accum::Add,
                self.kyy.as_ref(),
                c,
                1.0,
                Par::Seq,
            );
            self.cross_terms(c, 0, vh1, out.as_mut(), Accum::Add);
        };
        if parallel {
            rayon::join(
                || first(out),
                || self.cross_terms(c, half, vh2, out2.as_mut(), Accum::Replace),
            );
            faer::zip!(out.as_mut(), out2.as_ref()).for_each(|faer::unzip!(o, t)| *o += *t);
        } else {
            first(out);
        }
    }

    /// `out (+)= − Σ_t V_t Z_t` over the blocks t = t0 .. t0 + (columns of
    /// `vh`) / k_A of `[Y_1; …; Y_p; Y_1ᵀ; …; Y_pᵀ]` (V_t = block t times C,
    /// written into `vh`) and of the stacked `[X_1ᵀ; …; X_pᵀ; X_1; …; X_p]`.
    fn cross_terms(
        &self,
        c: MatRef<'_, f64>,
        t0: usize,
        mut vh: MatMut<'_, f64>,
        out: MatMut<'_, f64>,
        accum: Accum,
    ) {
        let (ka, kb) = (self.ka, self.kb);
        let nt = vh.ncols() / ka;
        for t in 0..nt {
            matmul(
                vh.rb_mut().subcols_mut(t * ka, ka),
                Accum::Replace,
                self.ys2.as_ref().subrows((t0 + t) * kb, kb),
                c,
                1.0,
                Par::Seq,
            );
        }
        matmul(
            out,
            accum,
            vh.rb(),
            self.xs2.as_ref().subrows(t0 * ka, nt * ka),
            -1.0,
            Par::Seq,
        );
    }

    /// `H_ff x` over the free unknowns (vec of the free columns of C); the
    /// fixed columns of `s.c` stay zero.
    fn apply_free(&self, x: &[f64], s: &mut Scratch) -> Vec<f64> {
        let (kb, j0) = (self.kb, self.j0);
        for (j, chunk) in x.chunks(kb).enumerate() {
            s.c.col_mut(j + j0)
                .try_as_col_major_mut()
                .unwrap()
                .as_slice_mut()
                .copy_from_slice(chunk);
        }
        self.apply_into(s.c.as_ref(), &mut s.out, &mut s.out2, &mut s.vh);
        let mut out = Vec::with_capacity(x.len());
        for j in j0..self.ka {
            out.extend_from_slice(s.out.col(j).try_as_col_major().unwrap().as_slice());
        }
        out
    }

    /// H over the free unknowns in f32, column-major n x n: the lower
    /// triangle, zeros above it. Every element of `h` is written.
    fn assemble_f32(&self, h: &mut [f32]) {
        let (ka, kb, j0, p) = (self.ka, self.kb, self.j0, self.p);
        let n = self.n();
        assert_eq!(h.len(), n * n);
        let (kx, kyy) = (&self.kx, &self.kyy);
        // yw[(i + kb r), q] = √w Y_q[i, r], yw[(i + kb r), p + q] = √w Y_q[r, i].
        let mut yw = Mat::<f32>::zeros(kb * kb, 2 * p);
        for q in 0..p {
            for r in 0..kb {
                for i in 0..kb {
                    yw[(i + kb * r, q)] = self.ys2[(q * kb + i, r)] as f32;
                    yw[(i + kb * r, p + q)] = self.ys2[(q * kb + r, i)] as f32;
                }
            }
        }
        // Column blocks l in groups of about COLS columns of G (one GEMM
        // per group: faer packs yw once per group, not once per l).
        const COLS: usize = 48;
        let nl = ka - j0;
        let mut groups = Vec::new();
        let (mut start, mut cols) = (0, 0);
        for lf in 0..nl {
            cols += nl - lf;
            if cols >= COLS || lf + 1 == nl {
                groups.push((start, lf + 1));
                (start, cols) = (lf + 1, 0);
            }
        }
        let mut parts = Vec::with_capacity(groups.len());
        let mut rest = h;
        for &(a, b) in &groups {
            let (head, tail) = rest.split_at_mut((b - a) * n * kb);
            parts.push((a, b, head));
            rest = tail;
        }
        parts.into_par_iter().for_each(|(a, b, slabs)| {
            let total: usize = (a..b).map(|lf| nl - lf).sum();
            // z[q, c] = √w X_q[j, l], z[p + q, c] = √w X_q[l, j] for the
            // column c of (l, j ≥ l) in the group.
            let mut z = Mat::<f32>::zeros(2 * p, total);
            let mut c = 0;
            for lf in a..b {
                let l = lf + j0;
                for j in l..ka {
                    for q in 0..p {
                        z[(q, c)] = self.xs[(j, q * ka + l)] as f32;
                        z[(p + q, c)] = self.xs[(l, q * ka + j)] as f32;
                    }
                    c += 1;
                }
            }
            // g[(i + kb r), c] = Σ_q w_q (Y_q[i,r] X_q[j,l] + Y_q[r,i] X_q[l,j]).
            let mut g = Mat::<f32>::zeros(kb * kb, total);
            matmul(
                g.as_mut(),
                Accum::Replace,
                yw.as_ref(),
                z.as_ref(),
                1.0,
                Par::Seq,
            );
            let mut seg = vec![0.0f32; kb];
            let mut c0 = 0;
            for (lf, slab) in (a..b).zip(slabs.chunks_mut(n * kb)) {
                let l = lf + j0;
                let nj = ka - l;
                for r in 0..kb {
                    let col = &mut slab[r * n..(r + 1) * n];
                    col[..kb * lf].fill(0.0);
                    for jj in 0..nj {
                        let j = jj + l;
                        let gc = &g.col(c0 + jj).try_as_col_major().unwrap().as_slice()
                            [kb * r..kb * (r + 1)];
                        for (s, g) in seg.iter_mut().zip(gc) {
                            *s = -g;
                        }
                        seg[r] += kx[(j, l)] as f32;
                        if jj == 0 {
                            for (i, s) in seg.iter_mut().enumerate() {
                                *s = if i < r { 0.0 } else { *s + kyy[(i, r)] as f32 };
                            }
                            seg[r] += (self.mask[(r, l)] + self.ridge) as f32;
                        }
                        let row0 = kb * (j - j0);
                        col[row0..row0 + kb].copy_from_slice(&seg);
                    }
                }
                c0 += nj;
            }
        });
    }

    /// [`assemble_f32`](Self::assemble_f32) into a fresh buffer whose
    /// first element is 64-byte aligned (the columns then start on cache
    /// lines when n is a multiple of 16); returns it and that offset. No
    /// separate zeroing pass: every element is written once.
    fn assembled_f32(&self) -> (Vec<f32>, usize) {
        let len = self.n() * self.n();
        // Zeroed by the allocator (fresh pages from the OS for a matrix of
        // this size: no zeroing pass), then every element of the body
        // written once.
        let mut buf = vec![0.0f32; len + 16];
        let off = ((64 - buf.as_ptr() as usize % 64) % 64) / 4;
        self.assemble_f32(&mut buf[off..off + len]);
        (buf, off)
    }

    /// The right-hand side over the free unknowns: `w_descr B Aᵀ` less the
    /// coupling `H (c0 e_0ᵀ)` to the fixed first column `c0` (when
    /// `j0 = 1`). With one nonzero column the product is rank one per
    /// term, `c0 K[0, :] − Σ_q w_q ((Y_q c0) X_q[:, 0]ᵀ + (Y_qᵀ c0) X_q[0, :])`
    /// (columns j ≥ 1; the other terms act on column 0 only): O(p k²), not
    /// a full product with H.
    pub(crate) fn rhs(&self, e: &FmapEnergy, c0: Option<&[f64]>) -> Vec<f64> {
        let (ka, kb, p) = (self.ka, self.kb, self.p);
        let a = MatRef::from_column_major_slice(e.descr_a.as_slice(), ka, e.descr_a.ncols());
        let b = MatRef::from_column_major_slice(e.descr_b.as_slice(), kb, e.descr_b.ncols());
        let mut bat = Mat::<f64>::zeros(kb, ka);
        matmul(
            bat.as_mut(),
            Accum::Replace,
            b,
            a.transpose(),
            e.w_descr,
            Par::Seq,
        );
        if let (Some(c0), 1) = (c0, self.j0) {
            let c0 = MatRef::from_column_major_slice(c0, kb, 1);
            // u = [Y_1 c0 … Y_p c0, Y_1ᵀ c0 … Y_pᵀ c0] (k_B x 2p).
            let mut u = Mat::<f64>::zeros(2 * p * kb, 1);
            matmul(
                u.as_mut(),
                Accum::Replace,
                self.ys2.as_ref(),
                c0,
                1.0,
                Par::Seq,
            );
            let u = MatRef::from_column_major_slice(
                u.col(0).try_as_col_major().unwrap().as_slice(),
                kb,
                2 * p,
            );
            // z[q, j] = √w X_q[j, 0], z[p + q, j] = √w X_q[0, j].
            let z = Mat::<f64>::from_fn(2 * p, ka, |t, j| {
                if t < p {
                    self.xs[(j, t * ka)]
                } else {
                    self.xs[(0, (t - p) * ka + j)]
                }
            });
            matmul(bat.as_mut(), Accum::Add, u, z.as_ref(), 1.0, Par::Seq);
            matmul(
                bat.as_mut(),
                Accum::Add,
                c0,
                self.kx.as_ref().subrows(0, 1),
                -1.0,
                Par::Seq,
            );
        }
        let mut out = Vec::with_capacity(self.n());
        for j in self.j0..ka {
            out.extend_from_slice(bat.col(j).try_as_col_major().unwrap().as_slice());
        }
        out
    }

    /// Solves `H_ff x = b` by conjugate gradients preconditioned with an
    /// f32 Cholesky factor of H. `None` when the factorization fails or the
    /// iteration does not reach the accepted residual (then the caller
    /// solves in f64).
    pub(crate) fn solve(&self, b: &[f64]) -> Option<(Vec<f64>, usize, f64)> {
        use faer::dyn_stack::{MemBuffer, MemStack};
        use faer::linalg::cholesky::llt::factor;
        let n = self.n();
        if n == 0 {
            return Some((Vec::new(), 0, 0.0));
        }
        // An all-zero or non-finite H: the dense path reports the error.
        if !(self.ridge > 0.0 && self.ridge.is_finite()) {
            return None;
        }
        let bn = norm(b);
        if bn == 0.0 {
            return Some((vec![0.0; n], 0, 0.0));
        }
        if !bn.is_finite() {
            return None;
        }
        let (mut buf, off) = self.assembled_f32();
        let mut l = MatMut::from_column_major_slice_mut(&mut buf[off..off + n * n], n, n);
        // One thread: faer's left-looking factorization. More: the
        // right-looking one of `chol` with look-ahead (1.7x faer's on two
        // threads at n = 2450, where faer's gains 1.3x).
        match self.par {
            Par::Seq => {
                let mut mem = MemBuffer::new(factor::cholesky_in_place_scratch::<f32>(
                    n,
                    Par::Seq,
                    Default::default(),
                ));
                factor::cholesky_in_place(
                    l.rb_mut(),
                    Default::default(),
                    Par::Seq,
                    MemStack::new(&mut mem),
                    Default::default(),
                )
                .ok()?;
            }
            _ => crate::chol::cholesky_lower(l.rb_mut()).ok()?,
        }
        let l = l.as_ref();
        let precond = |r: &[f64]| -> Vec<f64> { precondition(l, r) };
        let mut scratch = self.scratch();
        pcg(|x| self.apply_free(x, &mut scratch), precond, b, bn)
    }
}

/// Buffers reused by the products with H of one solve.
pub(crate) struct Scratch {
    /// C with the free columns of the current vector, zero elsewhere.
    c: Mat<f64>,
    out: Mat<f64>,
    /// The second half of the cross terms (parallel products).
    out2: Mat<f64>,
    vh: Mat<f64>,
}

/// `L⁻ᵀ L⁻¹ r` in f32 (r scaled to unit max norm first, so that no value
/// underflows).
fn precondition(l: MatRef<'_, f32>, r: &[f64]) -> Vec<f64> {
    use faer::linalg::triangular_solve;
    let s = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if s == 0.0 || !s.is_finite() {
        return vec![0.0; r.len()];
    }
    let mut z: Vec<f32> = r.iter().map(|v| (v / s) as f32).collect();
    let mut zm = MatMut::from_column_major_slice_mut(&mut z, r.len(), 1);
    triangular_solve::solve_lower_triangular_in_place(l, zm.rb_mut(), Par::Seq);
    triangular_solve::solve_upper_triangular_in_place(l.transpose(), zm.rb_mut(), Par::Seq);
    z.iter().map(|&v| f64::from(v) * s).collect()
}

/// Preconditioned conjugate gradients (flexible: the f32 preconditioner
/// is symmetric only to rounding) for `A x = b`, from `x = 0`. Stops at a
/// relative residual of [`TOL`], or when the residual has not halved in
/// four iterations, accepting it then if below [`ACCEPT`]. The residual is
/// recomputed from x before returning: (x, iterations, ‖b − A x‖ / ‖b‖).
fn pcg(
    mut apply: impl FnMut(&[f64]) -> Vec<f64>,
    precond: impl Fn(&[f64]) -> Vec<f64>,
    b: &[f64],
    bn: f64,
) -> Option<(Vec<f64>, usize, f64)> {
    // From x = 0: the first step is the best multiple of P b.
    let mut x = vec![0.0; b.len()];
    let mut r = b.to_vec();
    let mut z = precond(&r);
    let mut d = z.clone();
    let mut rz = dot(&r, &z);
    let (mut best, mut best_x, mut since) = (norm(&r), x.clone(), 0);
    let mut iterations = 0;
    for _ in 0..MAX_ITER {
        if best <= TOL * bn || since >= 4 {
            break;
        }
        iterations += 1;
        let ad = apply(&d);
        let dad = dot(&d, &ad);
        if !(dad > 0.0 && rz.is_finite()) {
            break;
        }
        let alpha = rz / dad;
        for (xi, di) in x.iter_mut().zip(&d) {
            *xi += alpha * di;
        }
        let r_old = r.clone();
        for (ri, ai) in r.iter_mut().zip(&ad) {
            *ri -= alpha * ai;
        }
        let rn = norm(&r);
        if rn < 0.5 * best {
            since = 0;
        } else {
            since += 1;
        }
        if rn < best {
            best = rn;
            best_x.copy_from_slice(&x);
        }
        if best <= TOL * bn || since >= 4 {
            break;
        }
        let z_new = precond(&r);
        let beta = (dot(&z_new, &r) - dot(&z_new, &r_old)) / rz;
        rz = dot(&r, &z_new);
        z = z_new;
        for (di, zi) in d.iter_mut().zip(&z) {
            *di = zi + beta * *di;
        }
    }
    // The recurrence drifts from the true residual by rounding: check.
    let ax = apply(&best_x);
    let true_r = b
        .iter()
        .zip(&ax)
        .map(|(b, a)| (b - a) * (b - a))
        .sum::<f64>()
        .sqrt()
        / bn;
    (true_r <= ACCEPT).then_some((best_x, iterations, true_r))
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    fn rnd(r: usize, c: usize, seed: u64) -> DMatrix<f64> {
        let mut s = seed;
        DMatrix::from_fn(r, c, |_, _| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        })
    }

    /// General (non-symmetric) operators and k_A ≠ k_B, so index mix-ups
    /// cannot hide; large enough (k_A k_B ≥ 400) for the parallel path.
    fn energy(ka: usize, kb: usize, fixed: bool) -> FmapEnergy {
        let ea = nalgebra::DVector::from_fn(ka, |i, _| i as f64 * 0.3);
        let eb = nalgebra::DVector::from_fn(kb, |i, _| i as f64 * 0.35);
        FmapEnergy {
            descr_a: rnd(ka, 9, 1),
            descr_b: rnd(kb, 9, 2),
            lap_mask: crate::resolvent_mask(&ea, &eb, 0.5),
            ops: (0..3)
                .map(|q| (rnd(ka, ka, 10 + q), rnd(kb, kb, 20 + q)))
                .collect(),
            orient_ops: (0..2)
                .map(|q| (rnd(ka, ka, 30 + q), rnd(kb, kb, 40 + q)))
                .collect(),
            w_descr: 1.0,
            w_lap: 0.5,
            w_dcomm: 0.7,
            w_orient: 0.3,
            fixed_first_column: fixed
                .then(|| nalgebra::DVector::from_fn(kb, |i, _| 0.1 * i as f64 + 1.0)),
        }
    }

    /// Two independent constructions of H: the structured f64 product
    /// (four GEMMs of stacked operators) applied to unit vectors, and the
    /// dense f64 assembly of the direct solver (Kronecker identities,
    /// entry by entry), agree to rounding; the f32 assembly (a third
    /// construction, column block by column block) agrees to f32 rounding.
    #[test]
    fn structured_product_and_both_assemblies_agree() {
        for (ka, kb, fixed) in [(21, 23, true), (24, 20, false), (6, 5, true)] {
            let e = energy(ka, kb, fixed);
            let j0 = usize::from(fixed);
            let nrm = Normal::new(&e, ka, kb, j0);
            let m = ka * kb;
            let mut h = Mat::<f64>::zeros(m, m);
            let aat = &e.descr_a * e.descr_a.transpose();
            e.fill_normal_matrix(&mut h, &aat, ka, kb);
            let n = nrm.n();
            let (buf, off) = nrm.assembled_f32();
            let h32 = MatRef::from_column_major_slice(&buf[off..off + n * n], n, n);
            let hmax = (0..m).fold(0.0f64, |a, i| a.max(h[(i, i)]));
            let mut worst = (0.0f64, 0.0f64);
            let mut scratch = nrm.scratch();
            for c in 0..n {
                let mut x = vec![0.0; n];
                x[c] = 1.0;
                let hx = nrm.apply_free(&x, &mut scratch);
                for r in 0..n {
                    // Free index t ↔ full index t + kb j0.
                    let (fr, fc) = (r + kb * j0, c + kb * j0);
                    let dense = if fr >= fc { h[(fr, fc)] } else { h[(fc, fr)] };
                    let ridge = if r == c { nrm.ridge } else { 0.0 };
                    worst.0 = worst.0.max((hx[r] - dense - ridge).abs());
                    if r >= c {
                        worst.1 = worst.1.max((f64::from(h32[(r, c)]) - dense - ridge).abs());
                    } else {
                        assert_eq!(h32[(r, c)], 0.0);
                    }
                }
            }
            assert!(worst.0 < 1e-13 * hmax, "{ka}x{kb}: f64 {}", worst.0);
            assert!(worst.1 < 1e-6 * hmax, "{ka}x{kb}: f32 {}", worst.1);
            assert!(worst.1 > 0.0, "the f32 matrix is not exact");
        }
    }

    /// The rank-one right-hand side equals `w B Aᵀ − H (c0 e_0ᵀ)` by the
    /// full structured product.
    #[test]
    fn right_hand_side_matches_the_full_product() {
        for (ka, kb) in [(21, 23), (7, 9)] {
            let e = energy(ka, kb, true);
            let nrm = Normal::new(&e, ka, kb, 1);
            let c0 = e.fixed_first_column.as_ref().unwrap();
            let rhs = nrm.rhs(&e, Some(c0.as_slice()));
            let mut c = Mat::<f64>::zeros(kb, ka);
            for i in 0..kb {
                c[(i, 0)] = c0[i];
            }
            let hc = nrm.apply(c.as_ref());
            let bat = &e.descr_b * e.descr_a.transpose() * e.w_descr;
            let mut worst = 0.0f64;
            for j in 1..ka {
                for i in 0..kb {
                    let full = bat[(i, j)] - hc[(i, j)];
                    worst = worst.max((rhs[i + kb * (j - 1)] - full).abs() / full.abs().max(1.0));
                }
            }
            assert!(worst < 1e-12, "{ka}x{kb}: {worst}");
        }
    }

    #[test]
    fn iterative_and_dense_minimizers_agree() {
        for (ka, kb, fixed) in [(21, 23, true), (24, 20, false)] {
            let e = energy(ka, kb, fixed);
            let (c, report) = e.minimize_with_report().unwrap();
            assert_eq!(report.method, crate::SolveMethod::Iterative);
            assert!(report.iterations <= 7, "{report:?}");
            assert!(report.residual.unwrap() <= TOL, "{report:?}");
            let d = e.minimize_dense().unwrap();
            assert!((&c - &d).amax() < 1e-11 * d.amax(), "{}", (&c - &d).amax());
            // The energy at the iterative solution is not above the
            // direct one (beyond rounding of the energy itself).
            assert!(e.value(&c) <= e.value(&d) * (1.0 + 1e-14));
        }
    }

    /// The same C, bit for bit, on one thread and on two: the parallel
    /// path is chosen by size, and its arithmetic does not depend on the
    /// number of threads (it used to switch Cholesky variants and the
    /// summation order of the cross terms).
    #[test]
    fn the_solution_does_not_depend_on_the_number_of_threads() {
        let e = energy(24, 20, true);
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| e.minimize_with_report().unwrap())
        };
        let (c1, r1) = on(1);
        let (c2, r2) = on(2);
        assert_eq!(r1.method, crate::SolveMethod::Iterative);
        assert_eq!(r1.iterations, r2.iterations);
        assert_eq!(c1.as_slice(), c2.as_slice());
    }

    /// Without a useful preconditioner and with few iterations allowed
    /// the iteration stops short, and reports failure (the caller then
    /// solves densely) rather than returning an inexact solution.
    #[test]
    fn pcg_reports_failure_instead_of_an_inexact_solution() {
        // A diagonal system with condition 1e8, identity preconditioner.
        let n = 200;
        let diag: Vec<f64> = (0..n)
            .map(|i| 10f64.powf(8.0 * i as f64 / (n - 1) as f64))
            .collect();
        let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin() + 1.5).collect();
        let apply = |x: &[f64]| -> Vec<f64> { x.iter().zip(&diag).map(|(x, d)| x * d).collect() };
        let bn = norm(&b);
        assert!(pcg(apply, |r: &[f64]| r.to_vec(), &b, bn).is_none());
        // With the exact inverse as preconditioner: one step.
        let inv = |r: &[f64]| -> Vec<f64> { r.iter().zip(&diag).map(|(r, d)| r / d).collect() };
        let (x, it, res) = pcg(apply, inv, &b, bn).unwrap();
        assert!(it <= 1 && res <= TOL, "{it} {res}");
        for i in 0..n {
            assert!((x[i] * diag[i] - b[i]).abs() <= 1e-14 * b[i].abs());
        }
    }
}
