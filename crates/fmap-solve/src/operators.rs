//! Operators on a reduced basis derived from vertex functions: descriptor
//! multiplication (`Φᵀ M diag(d) Φ`) and orientation (Ren et al., "Continuous
//! and orientation-preserving correspondences via functional maps", 2018).
//!
//! The orientation operator of a function f maps g to the normal component
//! of `∇f × ∇g`, i.e. `⟨n × ∇f, ∇g⟩`. On a triangle both gradients are
//! constant and lie in its plane, and with ψ_u the hat functions and e_u the
//! edge opposite to u (from next(u) to prev(u) in the face's order),
//! `⟨n × ∇f, area·∇ψ_u⟩ = ⟨∇f, e_u⟩ / 2 = (f_prev(u) − f_next(u)) / 2`:
//! the discrete operator needs only the oriented faces, no coordinates. Its
//! reduced form `Φᵀ M O_f Φ` (O_f averaged to vertices with the lumped
//! mass, as in pyFM, so M cancels) is
//! `Σ_F ∫_F φ_i ⟨n × ∇f, ∇φ_j⟩`, antisymmetric on closed meshes.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use crate::{Error, Result};

/// `Φᵀ M diag(d_q) Φ` (k x k) for every column d_q of `descriptors`
/// (n x p), with `phi` n x k; computed in parallel, one GEMM each.
pub fn multiplication_operators(
    phi: &DMatrix<f64>,
    mass: &DVector<f64>,
    descriptors: &DMatrix<f64>,
) -> Result<Vec<DMatrix<f64>>> {
    let n = phi.nrows();
    check_rows(n, mass.len(), "mass length vs basis rows")?;
    check_rows(n, descriptors.nrows(), "descriptor rows vs basis rows")?;
    let phi_rows = row_major(phi);
    Ok(reduce_each(phi, descriptors.ncols(), |q, vt| {
        let k = phi.ncols();
        let d = descriptors.column(q);
        for v in 0..n {
            let s = mass[v] * d[v];
            let src = &phi_rows[v * k..(v + 1) * k];
            for (o, x) in vt[v * k..(v + 1) * k].iter_mut().zip(src) {
                *o = s * x;
            }
        }
    }))
}

/// The reduced orientation operators `Φᵀ M O_{d_q} Φ` (k x k) of every
/// column d_q of `descriptors` (n x p) on a mesh with oriented triangles
/// `faces` and basis `phi` (n x k). `reversing` negates them (the operators
/// of orientation-reversing maps).
pub fn orientation_operators(
    faces: &[[usize; 3]],
    phi: &DMatrix<f64>,
    descriptors: &DMatrix<f64>,
    reversing: bool,
) -> Result<Vec<DMatrix<f64>>> {
    let n = phi.nrows();
    check_rows(n, descriptors.nrows(), "descriptor rows vs basis rows")?;
    if let Some((at, f)) = faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&v| v >= n))
    {
        return Err(Error::IndexOutOfRange {
            at,
            index: f.iter().copied().max().unwrap_or(0),
            n,
        });
    }
    let k = phi.ncols();
    let phi_rows = row_major(phi);
    let sign = if reversing { -1.0 } else { 1.0 } / 6.0;
    Ok(reduce_each(phi, descriptors.ncols(), |q, vt| {
        vt.fill(0.0);
        let d = descriptors.column(q);
        let mut r = vec![0.0; k];
        for &[a, b, c] in faces {
            // Row contribution Σ_u s_u φ(u), s_u = (f_prev − f_next)/6.
            let (sa, sb, sc) = (
                sign * (d[c] - d[b]),
                sign * (d[a] - d[c]),
                sign * (d[b] - d[a]),
            );
            let (pa, pb, pc) = (
                &phi_rows[a * k..(a + 1) * k],
                &phi_rows[b * k..(b + 1) * k],
                &phi_rows[c * k..(c + 1) * k],
            );
            for j in 0..k {
                r[j] = sa * pa[j] + sb * pb[j] + sc * pc[j];
            }
            for v in [a, b, c] {
                for (o, x) in vt[v * k..(v + 1) * k].iter_mut().zip(&r) {
                    *o += x;
                }
            }
        }
    }))
}

/// For q in 0..p: fills `vt` (k x n column-major, i.e. V_q row-major) with
/// `fill(q, vt)` and returns `Φᵀ V_q`, in parallel over q.
fn reduce_each<F>(phi: &DMatrix<f64>, p: usize, fill: F) -> Vec<DMatrix<f64>>
where
    F: Fn(usize, &mut [f64]) + Sync,
{
    let (n, k) = phi.shape();
    let phi_ref = MatRef::from_column_major_slice(phi.as_slice(), n, k);
    (0..p)
        .into_par_iter()
        .map_init(
            || vec![0.0; n * k],
            |vt, q| {
                fill(q, vt);
                let vt_ref = MatRef::from_column_major_slice(vt, k, n);
                // (Φᵀ V)ᵀ = Vᵀ Φ: out[j, i] = Σ_v V[v, j] Φ[v, i].
                let mut out = DMatrix::<f64>::zeros(k, k);
                let dst = MatMut::from_column_major_slice_mut(out.as_mut_slice(), k, k);
                matmul(dst, Accum::Replace, vt_ref, phi_ref, 1.0, Par::Seq);
                out.transpose()
            },
        )
        .collect()
}

fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

fn check_rows(n: usize, found: usize, what: &'static str) -> Result<()> {
    if found == n {
        Ok(())
    } else {
        Err(Error::SizeMismatch {
            what,
            found,
            expected: n,
        })
    }
}
