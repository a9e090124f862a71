//! The coupling loss of ULRSSM (Cao, Roetzer, Bernard, SIGGRAPH 2023):
//! the functional maps must agree with the soft point maps the features
//! define.
//!
//! With the features of both shapes normalised per vertex (`G_x`, `G_y`),
//! the soft point map from y to x is the row softmax of their cosine
//! similarity at temperature τ, `P_yx = softmax(G_y G_xᵀ / τ)`, and the
//! functional map it induces is `Φ_yᵀ M_y P_yx Φ_x`; the loss is
//!
//! `‖C_xy − Φ_yᵀ M_y P_yx Φ_x‖² + ‖C_yx − Φ_xᵀ M_x P_xy Φ_y‖²`.
//!
//! The soft maps are n_y x n_x: on meshes of thousands of vertices the
//! loss can be evaluated on a sample of each shape's vertices
//! ([`CouplingShape::vertices`]), the soft map then going from the
//! sampled vertices of one shape to those of the other and the integral
//! over the sampled vertices weighted by their mass scaled to the
//! shape's area (a quadrature of the same integral). With every vertex
//! sampled it is the loss above exactly.

use nalgebra::{DMatrix, DVector};

use crate::gemm::Op::{N, T};
use crate::gemm::{mul, mul_add};

/// One shape's side of the coupling loss.
#[derive(Debug, Clone, Copy)]
pub struct CouplingShape<'a> {
    /// Per-vertex features (n x p), as the network outputs them.
    pub features: &'a DMatrix<f64>,
    /// The functional maps' basis (n x k).
    pub eigenvectors: &'a DMatrix<f64>,
    /// Vertex masses (n).
    pub mass: &'a DVector<f64>,
    /// The sampled vertices (every vertex when `None`).
    pub vertices: Option<&'a [usize]>,
}

/// The loss and its gradients.
#[derive(Debug, Clone)]
pub struct CouplingGrad {
    /// The loss.
    pub loss: f64,
    /// d loss / d features of x (n_x x p).
    pub features_x: DMatrix<f64>,
    /// d loss / d features of y.
    pub features_y: DMatrix<f64>,
    /// d loss / d `C_xy`.
    pub c_xy: DMatrix<f64>,
    /// d loss / d `C_yx`.
    pub c_yx: DMatrix<f64>,
}

/// The sampled rows: normalised features, basis rows, quadrature weights.
struct Sampled {
    rows: Vec<usize>,
    /// Row norms of the features before normalising.
    norms: Vec<f64>,
    normalized: DMatrix<f64>,
    basis: DMatrix<f64>,
    weights: DVector<f64>,
}

fn sample(s: &CouplingShape<'_>) -> Sampled {
    let n = s.features.nrows();
    let rows: Vec<usize> = match s.vertices {
        Some(v) => v.to_vec(),
        None => (0..n).collect(),
    };
    let p = s.features.ncols();
    let k = s.eigenvectors.ncols();
    let mut normalized = DMatrix::zeros(rows.len(), p);
    let mut norms = Vec::with_capacity(rows.len());
    let mut basis = DMatrix::zeros(rows.len(), k);
    for (r, &v) in rows.iter().enumerate() {
        let f = s.features.row(v);
        // The reference normalises with max(‖f‖, 1e-12).
        let norm = f.norm().max(1e-12);
        norms.push(norm);
        normalized.row_mut(r).copy_from(&(f / norm));
        basis.row_mut(r).copy_from(&s.eigenvectors.row(v));
    }
    let total: f64 = s.mass.sum();
    let sampled: f64 = rows.iter().map(|&v| s.mass[v]).sum();
    let scale = if sampled > 0.0 { total / sampled } else { 0.0 };
    let weights = DVector::from_iterator(rows.len(), rows.iter().map(|&v| s.mass[v] * scale));
    Sampled {
        rows,
        norms,
        normalized,
        basis,
        weights,
    }
}

/// Column softmax of `z / tau` (each column a distribution; columns are
/// contiguous in nalgebra's storage).
pub(crate) fn softmax_columns(z: &DMatrix<f64>, tau: f64) -> DMatrix<f64> {
    let mut p = z.clone();
    let rows = p.nrows();
    for col in p.as_mut_slice().chunks_exact_mut(rows) {
        let max = col.iter().fold(f64::NEG_INFINITY, |m, &v| m.max(v));
        let mut sum = 0.0;
        for v in col.iter_mut() {
            *v = ((*v - max) / tau).exp();
            sum += *v;
        }
        col.iter_mut().for_each(|v| *v /= sum);
    }
    p
}

/// `d z` of `p = softmax_columns(z / tau)` given `dp`.
pub(crate) fn softmax_columns_backward(
    p: &DMatrix<f64>,
    dp: &DMatrix<f64>,
    tau: f64,
) -> DMatrix<f64> {
    let mut dz = p.component_mul(dp);
    let rows = p.nrows();
    for (o, (pc, dc)) in dz.as_mut_slice().chunks_exact_mut(rows).zip(
        p.as_slice()
            .chunks_exact(rows)
            .zip(dp.as_slice().chunks_exact(rows)),
    ) {
        let dot: f64 = pc.iter().zip(dc).map(|(a, b)| a * b).sum();
        for (v, pv) in o.iter_mut().zip(pc) {
            *v = (*v - pv * dot) / tau;
        }
    }
    dz
}

/// `diag(w) m`.
fn scale_rows(m: &DMatrix<f64>, w: &DVector<f64>) -> DMatrix<f64> {
    let mut out = m.clone();
    for (mut row, s) in out.row_iter_mut().zip(w.iter()) {
        row *= *s;
    }
    out
}

/// The coupling loss of `c_xy` (k_y x k_x, x's coefficients to y's) and
/// `c_yx` with the soft maps of temperature `tau` (ULRSSM: 0.07), and its
/// gradients.
pub fn coupling(
    x: &CouplingShape<'_>,
    y: &CouplingShape<'_>,
    c_xy: &DMatrix<f64>,
    c_yx: &DMatrix<f64>,
    tau: f64,
) -> CouplingGrad {
    let sx = sample(x);
    let sy = sample(y);
    // Cosine similarity, sampled x by sampled y, and its transpose: the
    // soft maps are column softmaxes of these (columns are contiguous),
    // q_yx = P_yxᵀ (n_x x n_y) and q_xy = P_xyᵀ (n_y x n_x).
    let sim = mul(&sx.normalized, N, &sy.normalized, T);
    let sim_t = mul(&sy.normalized, N, &sx.normalized, T);
    let q_yx = softmax_columns(&sim, tau);
    let q_xy = softmax_columns(&sim_t, tau);
    drop((sim, sim_t));
    let wphi_x = scale_rows(&sx.basis, &sx.weights);
    let wphi_y = scale_rows(&sy.basis, &sy.weights);
    // est_xy = (W Φ_y)ᵀ P_yx Φ_x = (q_yx W Φ_y)ᵀ Φ_x.
    let est_xy = mul(&mul(&q_yx, N, &wphi_y, N), T, &sx.basis, N);
    let est_yx = mul(&mul(&q_xy, N, &wphi_x, N), T, &sy.basis, N);
    let e1 = c_xy - est_xy;
    let e2 = c_yx - est_yx;
    let loss = e1.norm_squared() + e2.norm_squared();
    // d loss / d est = −2 E: dP_yx = −2 W Φ_y E₁ Φ_xᵀ, so
    // dq_yx = −2 Φ_x E₁ᵀ (W Φ_y)ᵀ.
    let dq_yx = mul(&mul(&sx.basis, N, &e1, T), N, &wphi_y, T) * -2.0;
    let dq_xy = mul(&mul(&sy.basis, N, &e2, T), N, &wphi_x, T) * -2.0;
    // d sim = dz_yx + dz_xyᵀ (n_x x n_y).
    let dz_yx = softmax_columns_backward(&q_yx, &dq_yx, tau);
    let dz_xy = softmax_columns_backward(&q_xy, &dq_xy, tau);
    drop((q_yx, q_xy, dq_yx, dq_xy));
    let mut dg_x = mul(&dz_yx, N, &sy.normalized, N);
    mul_add(&mut dg_x, 1.0, &dz_xy, T, &sy.normalized, N);
    let mut dg_y = mul(&dz_yx, T, &sx.normalized, N);
    mul_add(&mut dg_y, 1.0, &dz_xy, N, &sx.normalized, N);
    CouplingGrad {
        loss,
        features_x: unnormalize(&sx, &dg_x, x.features.shape()),
        features_y: unnormalize(&sy, &dg_y, y.features.shape()),
        c_xy: e1 * 2.0,
        c_yx: e2 * 2.0,
    }
}

/// d loss / d features from d loss / d normalised features:
/// `(dg − g (g · dg)) / ‖f‖` on the sampled rows, zero elsewhere.
fn unnormalize(s: &Sampled, dg: &DMatrix<f64>, shape: (usize, usize)) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(shape.0, shape.1);
    for (r, &v) in s.rows.iter().enumerate() {
        let g = s.normalized.row(r);
        let d = dg.row(r);
        let dot = g.dot(&d);
        let mut o = out.row_mut(v);
        for c in 0..shape.1 {
            // A vertex sampled twice adds up.
            o[c] += (d[c] - g[c] * dot) / s.norms[r];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random;

    fn side<'a>(
        f: &'a DMatrix<f64>,
        phi: &'a DMatrix<f64>,
        m: &'a DVector<f64>,
        v: Option<&'a [usize]>,
    ) -> CouplingShape<'a> {
        CouplingShape {
            features: f,
            eigenvectors: phi,
            mass: m,
            vertices: v,
        }
    }

    /// Every gradient against central differences along a random
    /// direction, with all vertices and with a sample (one vertex twice).
    #[test]
    fn gradients_match_finite_differences() {
        let (nx, ny, p, k) = (9, 7, 4, 3);
        let (fx, fy) = (random(nx, p, 1), random(ny, p, 2));
        let (px, py) = (random(nx, k, 3), random(ny, k, 4));
        let mx = DVector::from_fn(nx, |i, _| 0.5 + 0.1 * i as f64);
        let my = DVector::from_fn(ny, |i, _| 0.7 + 0.05 * i as f64);
        let (cxy, cyx) = (random(k, k, 5), random(k, k, 6));
        let (dfx, dfy) = (random(nx, p, 7), random(ny, p, 8));
        let (dcxy, dcyx) = (random(k, k, 9), random(k, k, 10));
        let tau = 0.3;
        let sx: &[usize] = &[0, 2, 2, 5, 8];
        let sy: &[usize] = &[1, 3, 6];
        for (vx, vy) in [(None, None), (Some(sx), Some(sy))] {
            let loss =
                |fx: &DMatrix<f64>, fy: &DMatrix<f64>, a: &DMatrix<f64>, b: &DMatrix<f64>| {
                    coupling(&side(fx, &px, &mx, vx), &side(fy, &py, &my, vy), a, b, tau).loss
                };
            let g = coupling(
                &side(&fx, &px, &mx, vx),
                &side(&fy, &py, &my, vy),
                &cxy,
                &cyx,
                tau,
            );
            let analytic = g.features_x.component_mul(&dfx).sum()
                + g.features_y.component_mul(&dfy).sum()
                + g.c_xy.component_mul(&dcxy).sum()
                + g.c_yx.component_mul(&dcyx).sum();
            let h = 1e-6;
            let numeric = (loss(
                &(&fx + &dfx * h),
                &(&fy + &dfy * h),
                &(&cxy + &dcxy * h),
                &(&cyx + &dcyx * h),
            ) - loss(
                &(&fx - &dfx * h),
                &(&fy - &dfy * h),
                &(&cxy - &dcxy * h),
                &(&cyx - &dcyx * h),
            )) / (2.0 * h);
            assert!(
                (analytic - numeric).abs() < 1e-6 * analytic.abs().max(1.0),
                "sampled {}: analytic {analytic}, finite difference {numeric}",
                vx.is_some()
            );
        }
    }

    /// Identical features on the same shape at a low temperature: the
    /// soft map is the identity, the induced map `Φᵀ M Φ` = I for an
    /// M-orthonormal basis, and the loss of C = I vanishes.
    #[test]
    fn identity_map_of_identical_shapes() {
        let n = 6;
        // Orthonormal columns of a random matrix (Gram–Schmidt by QR),
        // unit masses.
        let q = random(n, 3, 11).qr().q();
        let m = DVector::from_element(n, 1.0);
        // Features far apart: the cosine similarity is 1 on the diagonal
        // and at most 0 elsewhere.
        let f = DMatrix::<f64>::identity(n, n);
        let s = side(&f, &q, &m, None);
        let i3 = DMatrix::identity(3, 3);
        let g = coupling(&s, &s, &i3, &i3, 0.01);
        assert!(g.loss < 1e-20, "loss {}", g.loss);
    }
}
