//! Small geometry of the body generator: bones' affine maps, capsule
//! distances, the smooth minimum, 3 x 3 rotations.

use super::Capsule;
use fmaps_mesh_io::vec3::{dot, rotate, sub};

#[derive(Debug, Clone, Copy)]
pub(super) struct Affine {
    pub(super) rot: [[f64; 3]; 3],
    pub(super) lin: [[f64; 3]; 3],
    pub(super) origin: [f64; 3],
    pub(super) joint: [f64; 3],
}

impl Affine {
    pub(super) fn apply(&self, x: [f64; 3]) -> [f64; 3] {
        let y = mat_vec(&self.lin, sub(x, self.origin));
        [
            y[0] + self.joint[0],
            y[1] + self.joint[1],
            y[2] + self.joint[2],
        ]
    }
}

/// Distance to a tapered capsule (radius interpolated along the segment).
pub(super) fn capsule_distance(c: &Capsule, p: [f64; 3]) -> f64 {
    let ab = sub(c.b, c.a);
    let t = (dot(sub(p, c.a), ab) / dot(ab, ab)).clamp(0.0, 1.0);
    let q = [c.a[0] + t * ab[0], c.a[1] + t * ab[1], c.a[2] + t * ab[2]];
    let d = sub(p, q);
    dot(d, d).sqrt() - (c.ra + t * (c.rb - c.ra))
}

/// Polynomial smooth minimum of width `k`.
pub(super) fn smooth_min(a: f64, b: f64, k: f64) -> f64 {
    if !a.is_finite() {
        return b;
    }
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - h * h * k / 4.0
}

pub(super) fn rotation_matrix(v: [f64; 3]) -> [[f64; 3]; 3] {
    let angle = dot(v, v).sqrt();
    let mut m = [[0.0; 3]; 3];
    if angle == 0.0 {
        for (i, row) in m.iter_mut().enumerate() {
            row[i] = 1.0;
        }
        return m;
    }
    let axis = [v[0] / angle, v[1] / angle, v[2] / angle];
    for c in 0..3 {
        let mut e = [0.0; 3];
        e[c] = 1.0;
        let r = rotate(e, axis, angle);
        for (row, x) in m.iter_mut().zip(r) {
            row[c] = x;
        }
    }
    m
}

pub(super) fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            m[r][c] = (0..3).map(|k| a[r][k] * b[k][c]).sum();
        }
    }
    m
}

fn mat_vec(a: &[[f64; 3]; 3], x: [f64; 3]) -> [f64; 3] {
    [dot(a[0], x), dot(a[1], x), dot(a[2], x)]
}
