//! The ARAP term's per-vertex rotations (one-ring Procrustes, Kabsch's
//! rotation): a 3 x 3 Jacobi eigen-solve of `SᵀS` per vertex, eight
//! vertices side by side in a dispatched kernel ([`JacobiLanes`]), then
//! the rotation from its eigenvectors ([`kabsch`]).

use nalgebra::{Matrix3, Vector3};

use super::shell::v3;

/// Per-vertex ARAP rotations from `rest` to `cur` (one-ring Procrustes).
pub(super) fn rotations(
    rest: &[[f64; 3]],
    cur: &[[f64; 3]],
    nb: &[Vec<usize>],
) -> Vec<Matrix3<f64>> {
    let s: Vec<Matrix3<f64>> = (0..rest.len())
        .map(|i| {
            let mut s = Matrix3::zeros();
            for &j in &nb[i] {
                let e = v3(rest[i]) - v3(rest[j]);
                let ed = v3(cur[i]) - v3(cur[j]);
                s += e * ed.transpose();
            }
            s
        })
        .collect();
    let b: Vec<[[f64; 3]; 3]> = s.iter().map(gram).collect();
    let eig = fmaps_simd::dispatch(JacobiLanes(&b));
    s.iter()
        .zip(&eig)
        .map(|(s, e)| match e {
            Some((d, v)) => kabsch(s, d, v),
            None => Matrix3::identity(),
        })
        .collect()
}

/// `SᵀS` as an array.
fn gram(s: &Matrix3<f64>) -> [[f64; 3]; 3] {
    let b = s.transpose() * s;
    std::array::from_fn(|i| std::array::from_fn(|j| b[(i, j)]))
}

/// Off-diagonal size at which the Jacobi sweeps stop, relative to the
/// trace.
const JACOBI_TOL: f64 = 1e-15;

/// The eigenvalues (the diagonal left) and eigenvectors (columns of `v`)
/// of the symmetric 3 x 3 `b` by cyclic Jacobi sweeps (Golub & Van Loan
/// 8.5.2) until the off-diagonal part is below [`JACOBI_TOL`] of the
/// trace; `None` for a zero or non-finite trace. The reference that
/// [`JacobiLanes`] runs lane by lane (the tests compare them).
#[cfg(test)]
#[allow(clippy::type_complexity)]
fn jacobi(b: &[[f64; 3]; 3]) -> Option<([f64; 3], [[f64; 3]; 3])> {
    let mut a = *b;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = a[0][0] + a[1][1] + a[2][2];
    if !(scale > 0.0) || !scale.is_finite() {
        return None;
    }
    for _ in 0..32 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        if off <= (JACOBI_TOL * scale) * (JACOBI_TOL * scale) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let (c, sn) = givens(a[p][p], a[q][q], a[p][q]);
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - sn * akq;
                a[k][q] = sn * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - sn * aqk;
                a[q][k] = sn * apk + c * aqk;
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - sn * vq;
                row[q] = sn * vp + c * vq;
            }
        }
    }
    Some(([a[0][0], a[1][1], a[2][2]], v))
}

/// The Jacobi rotation `(cos, sin)` zeroing the entry `apq` between the
/// diagonal entries `app` and `aqq`.
#[inline(always)]
fn givens(app: f64, aqq: f64, apq: f64) -> (f64, f64) {
    let tau = (aqq - app) / (2.0 * apq);
    let t = tau.signum() / (tau.abs() + (1.0 + tau * tau).sqrt());
    let c = 1.0 / (1.0 + t * t).sqrt();
    (c, t * c)
}

/// Matrices diagonalised side by side in [`JacobiLanes`].
const LANES: usize = 8;

/// The eigenvalues and eigenvectors of every symmetric 3 x 3 matrix (or
/// `None` for a zero or non-finite trace) by cyclic Jacobi sweeps (Golub
/// & Van Loan 8.5.2) until the off-diagonal part is below [`JACOBI_TOL`]
/// of the trace, [`LANES`] matrices at a time: each lane runs exactly the
/// one-matrix sweeps (`jacobi`, the tests' reference; a lane that has
/// converged, or whose entry is already 0, keeps its values), so the
/// results are the same numbers, and the lanes' chains of square roots
/// and divisions overlap (and vectorize) instead of waiting on each
/// other (docs/tuning.md: much faster than one matrix at a time).
struct JacobiLanes<'a>(&'a [[[f64; 3]; 3]]);

impl fmaps_simd::Kernel for JacobiLanes<'_> {
    type Output = Vec<Option<([f64; 3], [[f64; 3]; 3])>>;

    #[inline(always)]
    fn run(self, _level: fmaps_simd::SimdLevel) -> Self::Output {
        let mut out = Vec::with_capacity(self.0.len());
        for chunk in self.0.chunks(LANES) {
            // Lane-major: a[i][j][lane], v[i][j][lane]; missing lanes 0.
            let mut a = [[[0.0f64; LANES]; 3]; 3];
            let mut v = [[[0.0f64; LANES]; 3]; 3];
            let mut thr = [0.0f64; LANES];
            let mut live = [false; LANES];
            for (l, b) in chunk.iter().enumerate() {
                for i in 0..3 {
                    for j in 0..3 {
                        a[i][j][l] = b[i][j];
                    }
                    v[i][i][l] = 1.0;
                }
                let scale = b[0][0] + b[1][1] + b[2][2];
                live[l] = scale > 0.0 && scale.is_finite();
                thr[l] = (JACOBI_TOL * scale) * (JACOBI_TOL * scale);
            }
            let valid = live;
            for _ in 0..32 {
                for l in 0..LANES {
                    let off =
                        a[0][1][l] * a[0][1][l] + a[0][2][l] * a[0][2][l] + a[1][2][l] * a[1][2][l];
                    live[l] = live[l] && !(off <= thr[l]);
                }
                if !live.iter().any(|&x| x) {
                    break;
                }
                for (p, q) in [(0, 1), (0, 2), (1, 2)] {
                    let mut c = [1.0f64; LANES];
                    let mut sn = [0.0f64; LANES];
                    let mut on = [false; LANES];
                    for l in 0..LANES {
                        let (cl, sl) = givens(a[p][p][l], a[q][q][l], a[p][q][l]);
                        on[l] = live[l] && a[p][q][l] != 0.0;
                        c[l] = cl;
                        sn[l] = sl;
                    }
                    // Columns p and q, then rows p and q, then V's columns.
                    for row in &mut a {
                        let [x, y] = row.get_disjoint_mut([p, q]).expect("p < q");
                        rotate(x, y, (&c, &sn), &on);
                    }
                    let [ap, aq] = a.get_disjoint_mut([p, q]).expect("p < q");
                    for (x, y) in ap.iter_mut().zip(aq.iter_mut()) {
                        rotate(x, y, (&c, &sn), &on);
                    }
                    for row in &mut v {
                        let [x, y] = row.get_disjoint_mut([p, q]).expect("p < q");
                        rotate(x, y, (&c, &sn), &on);
                    }
                }
            }
            for l in 0..chunk.len() {
                out.push(valid[l].then(|| {
                    (
                        [a[0][0][l], a[1][1][l], a[2][2][l]],
                        std::array::from_fn(|i| std::array::from_fn(|j| v[i][j][l])),
                    )
                }));
            }
        }
        out
    }
}

/// One matrix's rotation ([`kabsch`] after the Jacobi sweeps).
#[cfg(test)]
fn procrustes(s: &Matrix3<f64>) -> Matrix3<f64> {
    match jacobi(&gram(s)) {
        Some((d, v)) => kabsch(s, &d, &v),
        None => Matrix3::identity(),
    }
}

/// `(x, y) ← (c x − s y, s x + c y)` in the lanes that are `on` (the
/// others keep their values exactly), as [`JacobiLanes`] applies a
/// rotation (the one-matrix sweeps' products, lane by lane).
#[inline(always)]
fn rotate(
    x: &mut [f64; LANES],
    y: &mut [f64; LANES],
    (c, sn): (&[f64; LANES], &[f64; LANES]),
    on: &[bool; LANES],
) {
    for l in 0..LANES {
        let (xl, yl) = (x[l], y[l]);
        let (nx, ny) = (c[l] * xl - sn[l] * yl, sn[l] * xl + c[l] * yl);
        x[l] = if on[l] { nx } else { xl };
        y[l] = if on[l] { ny } else { yl };
    }
}

/// The rotation `R` maximising `tr(R S)` (`S = Σ e e'ᵀ` of edges `e` at
/// rest and `e'` deformed: `R e ≈ e'`): with `S = U Σ Vᵀ`, `R = V diag(1,
/// 1, δ) Uᵀ`, `δ = ±1` making it a rotation (Kabsch). `V` and `Σ²` from the
/// eigenvectors `v` (columns) and eigenvalues `d` of `SᵀS`
/// ([`JacobiLanes`]), `u₁ = S v₁ / |S v₁|`, `u₂` the unit
/// part of `S v₂` orthogonal to `u₁`, and the third columns of both the
/// cross products of the first two (which is `δ`). nalgebra's general
/// SVD (a Householder reduction and QR sweeps) was most of a Smooth Shells
/// level at 80k vertices.
/// Degenerate `S`: rank 1 completes `u₂` by any unit vector orthogonal to
/// `u₁`; `S = 0` gives the identity.
fn kabsch(s: &Matrix3<f64>, d: &[f64; 3], v: &[[f64; 3]; 3]) -> Matrix3<f64> {
    // Eigenvalues descending: the columns of V in that order.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| d[j].total_cmp(&d[i]));
    let col = |k: usize| Vector3::new(v[0][order[k]], v[1][order[k]], v[2][order[k]]);
    let (v1, v2) = (col(0), col(1));
    let v3 = v1.cross(&v2);
    let su1 = s * v1;
    let n1 = su1.norm();
    if !(n1 > 0.0) {
        return Matrix3::identity();
    }
    let u1 = su1 / n1;
    let w = s * v2;
    let w = w - u1 * u1.dot(&w);
    let u2 = match w.try_normalize(1e-300) {
        Some(u2) if w.norm() > 1e-12 * n1 => u2,
        // Rank 1: any unit vector orthogonal to u₁.
        _ => {
            let e = if u1.x.abs() < 0.9 {
                Vector3::x()
            } else {
                Vector3::y()
            };
            u1.cross(&e).normalize()
        }
    };
    let u3 = u1.cross(&u2);
    v1 * u1.transpose() + v2 * u2.transpose() + v3 * u3.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform numbers in [-1, 1) from a seed (a 64-bit LCG).
    fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        }
    }

    /// [`procrustes`] is the SVD's answer (nalgebra's, with the
    /// determinant fixed as Kabsch does) to 1e-10, a rotation to 1e-13:
    /// random matrices, nearly planar one-rings (rank ~2), rank 1 and 0.
    #[test]
    fn procrustes_is_the_svd_rotation() {
        let by_svd = |s: &Matrix3<f64>| {
            let svd = s.svd(true, true);
            let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
            let mut r = vt.transpose() * u.transpose();
            if r.determinant() < 0.0 {
                let mut v = vt.transpose();
                v.column_mut(2).neg_mut();
                r = v * u.transpose();
            }
            r
        };
        let mut rnd = uniform(12345);
        for case in 0..2000 {
            let mut s = Matrix3::from_fn(|_, _| rnd());
            if case % 2 == 1 {
                // One-ring edges in a plane, deformed: S = Σ e e'ᵀ with e
                // nearly in the xy plane.
                s = Matrix3::zeros();
                for _ in 0..6 {
                    let e = Vector3::new(rnd(), rnd(), 1e-3 * rnd());
                    let d = Vector3::new(rnd(), rnd(), rnd()) * 0.1 + e;
                    s += e * d.transpose();
                }
            }
            let r = procrustes(&s);
            assert!((r.transpose() * r - Matrix3::identity()).abs().max() < 1e-13);
            assert!((r.determinant() - 1.0).abs() < 1e-13);
            let want = by_svd(&s);
            assert!((r - want).abs().max() < 1e-10, "case {case}: {r} vs {want}");
        }
        // Rank 1: a rotation taking the one direction where it belongs.
        let (e, d) = (Vector3::new(1.0, 2.0, 0.5), Vector3::new(-0.3, 1.0, 2.0));
        let r = procrustes(&(e * d.transpose()));
        assert!((r.determinant() - 1.0).abs() < 1e-13);
        assert!((r * e.normalize() - d.normalize()).norm() < 1e-12);
        assert_eq!(procrustes(&Matrix3::zeros()), Matrix3::identity());
    }

    /// The lane-parallel Jacobi gives [`jacobi`]'s numbers exactly, at
    /// every SIMD level this CPU has, for lanes that converge after
    /// different numbers of sweeps, zero and non-finite matrices and a
    /// partial last chunk.
    #[test]
    fn jacobi_lanes_are_the_scalar_sweeps() {
        let mut rnd = uniform(99);
        let mut b: Vec<[[f64; 3]; 3]> = (0..203)
            .map(|i| {
                let s = Matrix3::from_fn(|_, _| rnd());
                // Some nearly diagonal (one sweep), some rank 1.
                let s = match i % 3 {
                    0 => Matrix3::from_diagonal(&Vector3::new(3.0, 2.0, 1.0)) + s * 1e-9,
                    1 => s.column(0) * s.row(1),
                    _ => s,
                };
                gram(&s)
            })
            .collect();
        b[5] = [[0.0; 3]; 3];
        b[17][1][1] = f64::NAN;
        let want: Vec<_> = b.iter().map(jacobi).collect();
        fmaps_simd::at_every_level(|level| {
            let got = fmaps_simd::dispatch(JacobiLanes(&b));
            assert_eq!(got.len(), want.len());
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                let bits = |x: &Option<([f64; 3], [[f64; 3]; 3])>| {
                    x.map(|(d, v)| (d.map(f64::to_bits), v.map(|r| r.map(f64::to_bits))))
                };
                assert_eq!(bits(g), bits(w), "matrix {i} at {level:?}");
            }
        });
    }
}
