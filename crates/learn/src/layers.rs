//! DiffusionNet's layers with their forward and backward passes written
//! out (the hand-written candidate among the automatic-differentiation
//! backends; every backward is checked against finite differences in the
//! tests). Features are n x C matrices, one row per vertex.
//!
//! - [`Linear`]: `Y = X Wᵀ + 1 bᵀ`.
//! - [`SpectralDiffusion`]: each channel diffused for its own learned time
//!   `t_c` in the spectral domain, `Y = Φ (e^{−λ t} ⊙ Φᵀ M X)`.
//! - [`GradientFeatures`]: the spatial gradient features of the paper's
//!   reference implementation: with `g = G_X x + i G_Y x` per channel and a
//!   learned complex-linear map `A = A_re + i A_im` across channels, the
//!   feature is `tanh(Re(conj(g) ⊙ (A g)))`, i.e. `tanh(g_x b_re + g_y
//!   b_im)` with `b = A g`: `b_re = A_re g_x − A_im g_y`, `b_im = A_re g_y
//!   + A_im g_x`. The released codes write this two ways: the authors'
//!   DiffusionNet as here, geomfum with `b_im = A_re g_x + A_im g_y`,
//!   which is not a complex product (it no longer commutes with rotating
//!   every tangent frame by the same angle, the reason for the complex
//!   form: the features must not depend on the arbitrary choice of frame
//!   up to a common rotation). This crate implements the authors' form,
//!   the reference default `with_gradient_rotations = true`.

use nalgebra::{DMatrix, DVector};
use sprs::CsMat;

use crate::gemm::Op::{N, T};
use crate::gemm::{mul, mul_add};

/// `m · x` for a sparse matrix in CSR form and a dense n x C one (column
/// by column: each column of `x` is read where the sparse row points).
///
/// # Panics
///
/// When `m` is not CSR or the sizes do not fit (a programming error).
pub fn sparse_mul(m: &CsMat<f64>, x: &DMatrix<f64>) -> DMatrix<f64> {
    assert!(m.is_csr() && m.cols() == x.nrows(), "CSR m x (cols x C)");
    let rows = m.rows();
    let mut out = DMatrix::zeros(rows, x.ncols());
    let (indptr, indices, data) = (m.indptr(), m.indices(), m.data());
    let indptr = indptr.raw_storage();
    for (oc, xc) in out
        .as_mut_slice()
        .chunks_exact_mut(rows)
        .zip(x.as_slice().chunks_exact(x.nrows()))
    {
        for i in 0..rows {
            let mut acc = 0.0;
            for k in indptr[i]..indptr[i + 1] {
                acc += data[k] * xc[indices[k]];
            }
            oc[i] = acc;
        }
    }
    out
}

/// `mᵀ · x` for a sparse matrix in CSR form and a dense n x C one.
///
/// # Panics
///
/// When `m` is not CSR or the sizes do not fit (a programming error).
pub fn sparse_mul_transposed(m: &CsMat<f64>, x: &DMatrix<f64>) -> DMatrix<f64> {
    assert!(m.is_csr() && m.rows() == x.nrows(), "CSR mᵀ x (rows x C)");
    let cols = m.cols();
    let mut out = DMatrix::zeros(cols, x.ncols());
    let (indptr, indices, data) = (m.indptr(), m.indices(), m.data());
    let indptr = indptr.raw_storage();
    for (oc, xc) in out
        .as_mut_slice()
        .chunks_exact_mut(cols)
        .zip(x.as_slice().chunks_exact(x.nrows()))
    {
        for i in 0..x.nrows() {
            let xi = xc[i];
            for k in indptr[i]..indptr[i + 1] {
                oc[indices[k]] += data[k] * xi;
            }
        }
    }
    out
}

/// An affine layer `Y = X Wᵀ + 1 bᵀ` (`W`: C_out x C_in).
#[derive(Debug, Clone, PartialEq)]
pub struct Linear {
    /// Weights, C_out x C_in.
    pub weight: DMatrix<f64>,
    /// Bias, C_out.
    pub bias: DVector<f64>,
}

/// The gradients of a [`Linear`] layer's parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearGrad {
    /// d loss / d weight.
    pub weight: DMatrix<f64>,
    /// d loss / d bias.
    pub bias: DVector<f64>,
}

impl Linear {
    /// `X Wᵀ + 1 bᵀ`.
    pub fn forward(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        let mut y = mul(x, N, &self.weight, T);
        for mut row in y.row_iter_mut() {
            row += self.bias.transpose();
        }
        y
    }

    /// Given `dY` (d loss / d output) and the input `x`: d loss / d input
    /// and the parameters' gradients.
    pub fn backward(&self, x: &DMatrix<f64>, dy: &DMatrix<f64>) -> (DMatrix<f64>, LinearGrad) {
        let dx = mul(dy, N, &self.weight, N);
        let grad = LinearGrad {
            weight: mul(dy, T, x, N),
            bias: DVector::from_iterator(dy.ncols(), dy.column_iter().map(|c| c.sum())),
        };
        (dx, grad)
    }
}

/// Learned per-channel diffusion in the spectral domain of a shape:
/// `Y = Φ (e^{−λ t} ⊙ Φᵀ M X)`, `t_c ≥ 0` per channel.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralDiffusion {
    /// Diffusion time per channel (the reference starts them at 0 and
    /// keeps them at least 1e-8).
    pub times: DVector<f64>,
}

/// A shape's spectral basis as the diffusion uses it.
#[derive(Debug, Clone, Copy)]
pub struct Spectrum<'a> {
    /// Eigenvalues (k).
    pub eigenvalues: &'a DVector<f64>,
    /// Eigenvectors (n x k), M-orthonormal.
    pub eigenvectors: &'a DMatrix<f64>,
    /// Mass diagonal (n).
    pub mass: &'a DVector<f64>,
}

impl Spectrum<'_> {
    /// Features projected on the basis: `Φᵀ M F` (k x p).
    pub fn project(&self, features: &DMatrix<f64>) -> DMatrix<f64> {
        let mut mf = features.clone();
        for (mut row, m) in mf.row_iter_mut().zip(self.mass.iter()) {
            row *= *m;
        }
        mul(self.eigenvectors, T, &mf, N)
    }

    /// The gradient of [`project`](Self::project)'s input for `d` = d
    /// loss / d output: `M Φ d`.
    pub fn project_backward(&self, d: &DMatrix<f64>) -> DMatrix<f64> {
        let mut out = mul(self.eigenvectors, N, d, N);
        for (mut row, m) in out.row_iter_mut().zip(self.mass.iter()) {
            row *= *m;
        }
        out
    }
}

impl SpectralDiffusion {
    /// `e^{−λ_i t_c}`, k x C.
    fn coefficients(&self, s: Spectrum<'_>) -> DMatrix<f64> {
        DMatrix::from_fn(s.eigenvalues.len(), self.times.len(), |i, c| {
            (-s.eigenvalues[i] * self.times[c]).exp()
        })
    }

    /// The diffused features (n x C).
    pub fn forward(&self, s: Spectrum<'_>, x: &DMatrix<f64>) -> DMatrix<f64> {
        self.forward_spectral(s, x).0
    }

    /// The diffused features and the input's spectral coefficients
    /// `Φᵀ M X` (for [`backward_spectral`](Self::backward_spectral)).
    pub fn forward_spectral(
        &self,
        s: Spectrum<'_>,
        x: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DMatrix<f64>) {
        let spec = s.project(x);
        let y = mul(
            s.eigenvectors,
            N,
            &spec.component_mul(&self.coefficients(s)),
            N,
        );
        (y, spec)
    }

    /// Given `dY` and the input `x`: d loss / d input and d loss / d times.
    pub fn backward(
        &self,
        s: Spectrum<'_>,
        x: &DMatrix<f64>,
        dy: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DVector<f64>) {
        self.backward_spectral(s, &s.project(x), dy)
    }

    /// [`backward`](Self::backward) from the input's spectral coefficients.
    pub fn backward_spectral(
        &self,
        s: Spectrum<'_>,
        spec: &DMatrix<f64>,
        dy: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DVector<f64>) {
        let coef = self.coefficients(s);
        // Y = Φ D, D = coef ⊙ spec: dD = Φᵀ dY.
        let dd = mul(s.eigenvectors, T, dy, N);
        let dtimes = DVector::from_fn(self.times.len(), |c, _| {
            (0..s.eigenvalues.len())
                .map(|i| -s.eigenvalues[i] * coef[(i, c)] * spec[(i, c)] * dd[(i, c)])
                .sum()
        });
        // spec = Φᵀ M X: dX = M Φ dspec.
        (s.project_backward(&dd.component_mul(&coef)), dtimes)
    }
}

/// DiffusionNet's spatial gradient features (see the module docs): a
/// complex-linear map `A_re + i A_im` (C x C each, no bias).
#[derive(Debug, Clone, PartialEq)]
pub struct GradientFeatures {
    /// Real part of `A`.
    pub a_re: DMatrix<f64>,
    /// Imaginary part of `A`.
    pub a_im: DMatrix<f64>,
}

/// The gradients of a [`GradientFeatures`] layer's parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct GradientFeaturesGrad {
    /// d loss / d `A_re`.
    pub a_re: DMatrix<f64>,
    /// d loss / d `A_im`.
    pub a_im: DMatrix<f64>,
}

/// A shape's gradient operators as the features use them.
#[derive(Debug, Clone, Copy)]
pub struct Gradients<'a> {
    /// X components (n x n).
    pub x: &'a CsMat<f64>,
    /// Y components (n x n).
    pub y: &'a CsMat<f64>,
}

impl GradientFeatures {
    /// `(g_x, g_y, b_re, b_im)` of the input.
    fn parts(
        &self,
        g: Gradients<'_>,
        v: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
        let gx = sparse_mul(g.x, v);
        let gy = sparse_mul(g.y, v);
        let mut b_re = mul(&gx, N, &self.a_re, T);
        mul_add(&mut b_re, -1.0, &gy, N, &self.a_im, T);
        let mut b_im = mul(&gy, N, &self.a_re, T);
        mul_add(&mut b_im, 1.0, &gx, N, &self.a_im, T);
        (gx, gy, b_re, b_im)
    }

    /// `tanh(g_x ⊙ b_re + g_y ⊙ b_im)`, n x C.
    pub fn forward(&self, g: Gradients<'_>, v: &DMatrix<f64>) -> DMatrix<f64> {
        self.forward_tape(g, v).out
    }

    /// The forward pass keeping what the backward pass needs.
    pub fn forward_tape(&self, g: Gradients<'_>, v: &DMatrix<f64>) -> FeaturesTape {
        let (gx, gy, b_re, b_im) = self.parts(g, v);
        let out = (gx.component_mul(&b_re) + gy.component_mul(&b_im)).map(tanh);
        FeaturesTape {
            gx,
            gy,
            b_re,
            b_im,
            out,
        }
    }

    /// Given `dY` and the input `v`: d loss / d input and the parameters'
    /// gradients.
    pub fn backward(
        &self,
        g: Gradients<'_>,
        v: &DMatrix<f64>,
        dy: &DMatrix<f64>,
    ) -> (DMatrix<f64>, GradientFeaturesGrad) {
        self.backward_tape(g, &self.forward_tape(g, v), dy)
    }

    /// [`backward`](Self::backward) from the tape of the forward pass.
    pub fn backward_tape(
        &self,
        g: Gradients<'_>,
        t: &FeaturesTape,
        dy: &DMatrix<f64>,
    ) -> (DMatrix<f64>, GradientFeaturesGrad) {
        let (gx, gy, b_re, b_im) = (&t.gx, &t.gy, &t.b_re, &t.b_im);
        let dd = dy.zip_map(&t.out, |d, o| d * (1.0 - o * o));
        let db_re = dd.component_mul(gx);
        let db_im = dd.component_mul(gy);
        // b_re = gx A_reᵀ − gy A_imᵀ; b_im = gy A_reᵀ + gx A_imᵀ.
        let mut a_re = mul(&db_re, T, gx, N);
        mul_add(&mut a_re, 1.0, &db_im, T, gy, N);
        let mut a_im = mul(&db_im, T, gx, N);
        mul_add(&mut a_im, -1.0, &db_re, T, gy, N);
        let mut dgx = dd.component_mul(b_re);
        mul_add(&mut dgx, 1.0, &db_re, N, &self.a_re, N);
        mul_add(&mut dgx, 1.0, &db_im, N, &self.a_im, N);
        let mut dgy = dd.component_mul(b_im);
        mul_add(&mut dgy, -1.0, &db_re, N, &self.a_im, N);
        mul_add(&mut dgy, 1.0, &db_im, N, &self.a_re, N);
        let dv = sparse_mul_transposed(g.x, &dgx) + sparse_mul_transposed(g.y, &dgy);
        (dv, GradientFeaturesGrad { a_re, a_im })
    }
}

/// `tanh x` as `sign(x) (1 − e^{−2|x|}) / (1 + e^{−2|x|})`: one `exp`
/// (several times faster than the C library's `tanh`), within a few
/// units of 1e-16 of it in absolute terms.
fn tanh(x: f64) -> f64 {
    let t = (-2.0 * x.abs()).exp();
    ((1.0 - t) / (1.0 + t)).copysign(x)
}

/// What a [`GradientFeatures`] forward pass keeps for its backward pass.
#[derive(Debug, Clone)]
pub struct FeaturesTape {
    gx: DMatrix<f64>,
    gy: DMatrix<f64>,
    b_re: DMatrix<f64>,
    b_im: DMatrix<f64>,
    /// The features (the layer's output).
    pub out: DMatrix<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ShapeOperators;

    /// Rotating every vertex's tangent frame by its own angle leaves the
    /// complex form's features unchanged (the reason for that form); the
    /// product as geomfum writes it (`b_im = A_re g_x + A_im g_y`)
    /// changes.
    #[test]
    fn gradient_features_ignore_the_frames_rotation() {
        let mesh = fmaps_shapes::icosphere(1.0, 2);
        let ops = ShapeOperators::compute(&mesh, 8).unwrap();
        let n = mesh.n_vertices();
        let mut rng = fmaps_simd::SplitMix(31);
        let theta: Vec<f64> = (0..n).map(|_| 3.0 * rng.symmetric()).collect();
        // Row v of the rotated operators: g'_x = c g_x + s g_y and
        // g'_y = −s g_x + c g_y (c, s of θ_v).
        let rotated = |which: usize| {
            let mut t = sprs::TriMat::new((n, n));
            for (k, m) in [&ops.grad_x, &ops.grad_y].into_iter().enumerate() {
                for (v, row) in m.outer_iterator().enumerate() {
                    let (c, s) = (theta[v].cos(), theta[v].sin());
                    let coef = [[c, s], [-s, c]][which][k];
                    for (j, &val) in row.iter() {
                        t.add_triplet(v, j, coef * val);
                    }
                }
            }
            t.to_csr::<usize>()
        };
        let (gx2, gy2) = (rotated(0), rotated(1));
        let c = 5;
        let layer = GradientFeatures {
            a_re: random(c, c, 32),
            a_im: random(c, c, 33),
        };
        let v = random(n, c, 34);
        let g1 = Gradients {
            x: &ops.grad_x,
            y: &ops.grad_y,
        };
        let g2 = Gradients { x: &gx2, y: &gy2 };
        let (f1, f2) = (layer.forward(g1, &v), layer.forward(g2, &v));
        assert!(
            (&f1 - &f2).abs().max() < 1e-12,
            "{}",
            (&f1 - &f2).abs().max()
        );
        let geomfum = |g: Gradients<'_>| {
            let (gx, gy) = (sparse_mul(g.x, &v), sparse_mul(g.y, &v));
            let b_re = &gx * layer.a_re.transpose() - &gy * layer.a_im.transpose();
            let b_im = &gx * layer.a_re.transpose() + &gy * layer.a_im.transpose();
            (gx.component_mul(&b_re) + gy.component_mul(&b_im)).map(f64::tanh)
        };
        assert!((geomfum(g1) - geomfum(g2)).abs().max() > 1e-2);
    }

    /// The one-`exp` tanh against the C library's, over [−40, 40].
    #[test]
    fn tanh_matches_the_library() {
        for i in -40_000..=40_000 {
            let x = f64::from(i) * 1e-3;
            assert!((tanh(x) - x.tanh()).abs() < 4e-16, "{x}");
        }
        assert_eq!(tanh(0.0), 0.0);
        assert!(tanh(f64::NAN).is_nan());
    }

    /// A reproducible matrix of values in [−1, 1).
    fn random(r: usize, c: usize, seed: u64) -> DMatrix<f64> {
        let mut s = seed.wrapping_mul(0x9E3779B97F4A7C15) | 1;
        DMatrix::from_fn(r, c, |_, _| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        })
    }

    /// The central difference of `f` along `dir`, step `h`.
    fn central(f: &dyn Fn(f64) -> f64, h: f64) -> f64 {
        (f(h) - f(-h)) / (2.0 * h)
    }

    /// `⟨a, b⟩` of two matrices.
    fn inner(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
        a.component_mul(b).sum()
    }

    /// Checks an analytic directional derivative against the central
    /// difference: relative error below 1e-6 (f64, step 1e-5: the
    /// truncation error is O(h²) ~ 1e-10 and the rounding O(ε/h) ~ 1e-11).
    fn close(analytic: f64, numeric: f64, what: &str) {
        let scale = analytic.abs().max(numeric.abs()).max(1e-8);
        assert!(
            (analytic - numeric).abs() / scale < 1e-6,
            "{what}: analytic {analytic}, finite difference {numeric}"
        );
    }

    fn operators() -> ShapeOperators {
        ShapeOperators::compute(&fmaps_shapes::creature_pair(1).source, 12).unwrap()
    }

    /// For a loss `L = ⟨R, Y⟩`, each backward's gradients agree with
    /// central differences of the forward along random directions.
    #[test]
    fn linear_backward_matches_finite_differences() {
        let (n, ci, co) = (7, 4, 3);
        let layer = Linear {
            weight: random(co, ci, 1),
            bias: DVector::from_iterator(co, random(co, 1, 2).iter().copied()),
        };
        let (x, r) = (random(n, ci, 3), random(n, co, 4));
        let (dx, grad) = layer.backward(&x, &r);
        let (ex, ew, eb) = (random(n, ci, 5), random(co, ci, 6), random(co, 1, 7));
        let loss = |l: &Linear, x: &DMatrix<f64>| inner(&r, &l.forward(x));
        close(
            inner(&dx, &ex),
            central(&|h| loss(&layer, &(&x + &ex * h)), 1e-5),
            "dX",
        );
        let along_w = |h: f64| {
            let mut l = layer.clone();
            l.weight += &ew * h;
            loss(&l, &x)
        };
        close(inner(&grad.weight, &ew), central(&along_w, 1e-5), "dW");
        let along_b = |h: f64| {
            let mut l = layer.clone();
            l.bias += eb.column(0) * h;
            loss(&l, &x)
        };
        close(grad.bias.dot(&eb.column(0)), central(&along_b, 1e-5), "db");
    }

    #[test]
    fn diffusion_backward_matches_finite_differences() {
        let ops = operators();
        let s = Spectrum {
            eigenvalues: &ops.eigenvalues,
            eigenvectors: &ops.eigenvectors,
            mass: &ops.mass,
        };
        let (n, c) = (ops.mass.len(), 5);
        let layer = SpectralDiffusion {
            times: DVector::from_iterator(c, random(c, 1, 8).iter().map(|v| 0.01 * (v + 1.5))),
        };
        let (x, r) = (random(n, c, 9), random(n, c, 10));
        let (dx, dt) = layer.backward(s, &x, &r);
        let (ex, et) = (random(n, c, 11), random(c, 1, 12));
        let loss = |l: &SpectralDiffusion, x: &DMatrix<f64>| inner(&r, &l.forward(s, x));
        close(
            inner(&dx, &ex),
            central(&|h| loss(&layer, &(&x + &ex * h)), 1e-5),
            "dX",
        );
        let along_t = |h: f64| {
            let mut l = layer.clone();
            l.times += et.column(0) * h;
            loss(&l, &x)
        };
        close(dt.dot(&et.column(0)), central(&along_t, 1e-5), "dt");
    }

    /// Time 0 leaves a function in the basis' span as it is; a long time
    /// leaves its mean (the constant eigenfunction's part).
    #[test]
    fn diffusion_at_time_zero_and_infinity() {
        let ops = operators();
        let s = Spectrum {
            eigenvalues: &ops.eigenvalues,
            eigenvectors: &ops.eigenvectors,
            mass: &ops.mass,
        };
        let x = &ops.eigenvectors * random(ops.eigenvalues.len(), 2, 13);
        let none = SpectralDiffusion {
            times: DVector::zeros(2),
        };
        assert!((none.forward(s, &x) - &x).amax() < 1e-9);
        let long = SpectralDiffusion {
            times: DVector::from_element(2, 1e6),
        };
        let y = long.forward(s, &x);
        let area = ops.mass.sum();
        for c in 0..2 {
            let mean = x.column(c).dot(&ops.mass) / area;
            assert!(y.column(c).iter().all(|v| (v - mean).abs() < 1e-9));
        }
    }

    #[test]
    fn gradient_features_backward_matches_finite_differences() {
        let ops = operators();
        let g = Gradients {
            x: &ops.grad_x,
            y: &ops.grad_y,
        };
        let (n, c) = (ops.mass.len(), 4);
        let layer = GradientFeatures {
            a_re: random(c, c, 14),
            a_im: random(c, c, 15),
        };
        // Small inputs keep tanh away from saturation.
        let (v, r) = (random(n, c, 16) * 0.05, random(n, c, 17));
        let (dv, grad) = layer.backward(g, &v, &r);
        let (ev, ere, eim) = (random(n, c, 18) * 0.05, random(c, c, 19), random(c, c, 20));
        let loss = |l: &GradientFeatures, v: &DMatrix<f64>| inner(&r, &l.forward(g, v));
        close(
            inner(&dv, &ev),
            central(&|h| loss(&layer, &(&v + &ev * h)), 1e-5),
            "dV",
        );
        let along_re = |h: f64| {
            let mut l = layer.clone();
            l.a_re += &ere * h;
            loss(&l, &v)
        };
        close(inner(&grad.a_re, &ere), central(&along_re, 1e-5), "dA_re");
        let along_im = |h: f64| {
            let mut l = layer.clone();
            l.a_im += &eim * h;
            loss(&l, &v)
        };
        close(inner(&grad.a_im, &eim), central(&along_im, 1e-5), "dA_im");
    }

    /// With `A = i` (a quarter turn) the feature of any gradient is 0
    /// (`Re(conj(g) i g) = 0`); with `A = 1` it is `tanh |g|²`.
    #[test]
    fn gradient_features_closed_forms() {
        let ops = operators();
        let g = Gradients {
            x: &ops.grad_x,
            y: &ops.grad_y,
        };
        let n = ops.mass.len();
        let v = random(n, 3, 21) * 0.1;
        let turn = GradientFeatures {
            a_re: DMatrix::zeros(3, 3),
            a_im: DMatrix::identity(3, 3),
        };
        assert!(turn.forward(g, &v).amax() < 1e-15);
        let id = GradientFeatures {
            a_re: DMatrix::identity(3, 3),
            a_im: DMatrix::zeros(3, 3),
        };
        let (gx, gy) = (sparse_mul(g.x, &v), sparse_mul(g.y, &v));
        let want = (gx.component_mul(&gx) + gy.component_mul(&gy)).map(f64::tanh);
        assert!((id.forward(g, &v) - want).amax() < 1e-15);
    }
}
