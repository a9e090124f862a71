//! The rigid part of the Smooth Shells initialisation: rotations, and ICP
//! about the main axis.

use std::time::Instant;

use nalgebra::{Matrix3, Vector3};

use super::shell::Shell;
use crate::{RefineReport, Result};

/// Rotation by `angle` about the unit `axis` (Rodrigues).
pub(super) fn axis_rotation(axis: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    let k = axis.cross_matrix();
    Matrix3::identity() * c + k * s + axis * axis.transpose() * (1.0 - c)
}

/// The rotation taking unit `a` to unit `b` (the shortest arc).
pub(super) fn align_vectors(a: &Vector3<f64>, b: &Vector3<f64>) -> Matrix3<f64> {
    let v = a.cross(b);
    let c = a.dot(b);
    if v.norm() < 1e-12 {
        if c > 0.0 {
            return Matrix3::identity();
        }
        let e = if a.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        return axis_rotation(&a.cross(&e).normalize(), std::f64::consts::PI);
    }
    axis_rotation(&v.normalize(), v.norm().atan2(c))
}

/// The proper rotation `R` (about the origin, where both shapes are
/// centred) minimising `Σ ‖R p_i − q_i‖²` (Kabsch: the SVD of `Σ q_i p_iᵀ`,
/// its last singular direction's sign chosen so that `det R = 1`).
pub(super) fn kabsch(p: &[[f64; 3]], q: &[[f64; 3]]) -> Matrix3<f64> {
    let mut h = Matrix3::zeros();
    for (a, b) in p.iter().zip(q) {
        h += Vector3::new(b[0], b[1], b[2]) * Vector3::new(a[0], a[1], a[2]).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let d = (u * vt).determinant().signum();
    u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt
}

/// ICP of `x` about the main axis `axis` (through the origin, where both
/// shapes are centred): `iterations` rounds of both directions' nearest
/// points and the closed-form best angle. Rotates `x`; returns the
/// rotation applied.
pub(super) fn axis_icp(
    x: &mut Shell<'_>,
    y: &Shell<'_>,
    sx: &[usize],
    sy: &[usize],
    axis: &Vector3<f64>,
    iterations: usize,
    report: &mut RefineReport,
) -> Result<Matrix3<f64>> {
    let mut total = Matrix3::identity();
    let pts =
        |s: &Shell<'_>, idx: &[usize]| faer::Mat::from_fn(idx.len(), 3, |r, c| s.verts[idx[r]][c]);
    let qy = pts(y, sy);
    for _ in 0..iterations {
        let qx = pts(x, sx);
        let t = Instant::now();
        let p = fmaps_nearest::NnParams::default();
        let ab = fmaps_nearest::nearest_rows(qy.as_ref(), qx.as_ref(), None, &p)
            .map_err(fmaps_solve::Error::Search)?;
        let ba = fmaps_nearest::nearest_rows(qx.as_ref(), qy.as_ref(), None, &p)
            .map_err(fmaps_solve::Error::Search)?;
        report.nn_searches += 2;
        report.nn_seconds += t.elapsed().as_secs_f64();
        let (mut sin, mut cos) = (0.0, 0.0);
        let pairs = sx
            .iter()
            .zip(&ab)
            .map(|(&i, &j)| (i, sy[j]))
            .chain(ba.iter().zip(sy).map(|(&i, &j)| (sx[i], j)));
        for (i, j) in pairs {
            let p = Vector3::from(x.verts[i]);
            let q = Vector3::from(y.verts[j]);
            let pp = p - axis * axis.dot(&p);
            let qp = q - axis * axis.dot(&q);
            sin += axis.dot(&pp.cross(&qp));
            cos += pp.dot(&qp);
        }
        let r = axis_rotation(axis, sin.atan2(cos));
        x.rotate(&r);
        total = r * total;
    }
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kabsch_recovers_a_rotation() {
        let r = axis_rotation(&Vector3::new(1.0, 2.0, -0.5).normalize(), 2.2);
        let p = [
            [1.0, 0.2, 0.0],
            [0.0, 1.0, 0.3],
            [-0.4, 0.1, 1.0],
            [0.5, -0.7, 0.2],
        ];
        let q: Vec<[f64; 3]> = p
            .iter()
            .map(|v| {
                let w = r * Vector3::new(v[0], v[1], v[2]);
                [w[0], w[1], w[2]]
            })
            .collect();
        let k = kabsch(&p, &q);
        assert!((k - r).norm() < 1e-12, "{k} vs {r}");
        // Three points of a mirror image: still a proper rotation.
        let m: Vec<[f64; 3]> = p.iter().map(|v| [-v[0], v[1], v[2]]).collect();
        assert!((kabsch(&p, &m).determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn rotations_are_proper_and_align() {
        let a = Vector3::new(1.0, 2.0, -0.5).normalize();
        let b = Vector3::new(-0.3, 0.1, 1.0).normalize();
        let r = align_vectors(&a, &b);
        assert!((r * a - b).norm() < 1e-12);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        let r = align_vectors(&a, &(-a));
        assert!((r * a + a).norm() < 1e-12);
        let q = axis_rotation(&Vector3::z(), std::f64::consts::FRAC_PI_2);
        assert!((q * Vector3::x() - Vector3::y()).norm() < 1e-12);
    }
}
