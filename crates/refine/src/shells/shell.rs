//! The shape a Smooth Shells alignment moves ([`Shell`]: normalised
//! vertices, basis, mass, spectral coordinates) and the small linear
//! algebra every part of the alignment shares. A leaf: it uses no other
//! module of the alignment.

use nalgebra::{DMatrix, Matrix3, Vector3};

use fmaps_mesh_io::vec3::{cross, dot};

/// The sign that orients a mesh's normals outwards: −1 when its signed
/// volume is negative (a closed mesh whose faces turn inwards), else 1.
/// A shape's shells and deformations keep its faces' orientation, so the
/// sign is the shape's own ([`Shell::orient`]), computed once.
pub(crate) fn orientation(verts: &[[f64; 3]], faces: &[[usize; 3]]) -> f64 {
    let mut volume = 0.0;
    for f in faces {
        let (a, b, c) = (verts[f[0]], verts[f[1]], verts[f[2]]);
        volume += dot(a, cross(b, c));
    }
    if volume < 0.0 { -1.0 } else { 1.0 }
}

/// A shape prepared for the alignment: normalised vertices, basis, mass.
#[derive(Clone)]
pub(crate) struct Shell<'a> {
    /// Vertices, centred at the area-weighted centroid and scaled to unit
    /// area (and, for the shape that moves, rotated by the rigid step).
    pub verts: Vec<[f64; 3]>,
    pub faces: &'a [[usize; 3]],
    /// Φ (n x K), M-orthonormal.
    pub phi: &'a DMatrix<f64>,
    pub mass: &'a [f64],
    /// Eigenvalues times the shape's area (scale-free).
    pub evals: Vec<f64>,
    /// Φᵀ M V (K x 3): the spectral coefficients of the coordinates.
    pub xi: DMatrix<f64>,
    /// Per vertex, the neighbours (for ARAP).
    pub neighbours: Vec<Vec<usize>>,
    /// The sign orienting its normals outwards ([`orientation`] of
    /// `verts`; a reflection flips it).
    pub orient: f64,
}

impl<'a> Shell<'a> {
    pub fn new(
        verts: &[[f64; 3]],
        faces: &'a [[usize; 3]],
        phi: &'a DMatrix<f64>,
        mass: &'a [f64],
        evals: &[f64],
    ) -> Shell<'a> {
        let area = surface_area(verts, faces).max(f64::MIN_POSITIVE);
        let total: f64 = mass.iter().sum();
        let mut c = [0.0; 3];
        for (v, &m) in verts.iter().zip(mass) {
            for d in 0..3 {
                c[d] += m * v[d] / total;
            }
        }
        let s = 1.0 / area.sqrt();
        let verts: Vec<[f64; 3]> = verts
            .iter()
            .map(|v| [(v[0] - c[0]) * s, (v[1] - c[1]) * s, (v[2] - c[2]) * s])
            .collect();
        let mut neighbours = vec![Vec::new(); verts.len()];
        for f in faces {
            for e in 0..3 {
                let (i, j) = (f[e], f[(e + 1) % 3]);
                if !neighbours[i].contains(&j) {
                    neighbours[i].push(j);
                    neighbours[j].push(i);
                }
            }
        }
        let mut shell = Shell {
            verts,
            faces,
            phi,
            mass,
            evals: evals.iter().map(|l| l * total).collect(),
            xi: DMatrix::zeros(0, 3),
            neighbours,
            orient: 1.0,
        };
        shell.orient = orientation(&shell.verts, faces);
        shell.update_xi();
        shell
    }

    /// Recomputes Φᵀ M V after the vertices moved.
    pub fn update_xi(&mut self) {
        let v = DMatrix::from_fn(self.verts.len(), 3, |r, d| self.mass[r] * self.verts[r][d]);
        self.xi = mul(self.phi, true, &v);
    }

    /// A copy rotated by `r`.
    pub fn clone_rotated(&self, r: &Matrix3<f64>) -> Shell<'a> {
        let mut s = self.clone();
        s.rotate(r);
        s
    }

    /// Applies a rotation to the vertices (about the origin).
    pub fn rotate(&mut self, r: &Matrix3<f64>) {
        for v in &mut self.verts {
            let p = r * Vector3::new(v[0], v[1], v[2]);
            *v = [p[0], p[1], p[2]];
        }
        self.orient = orientation(&self.verts, self.faces);
        self.update_xi();
    }

    /// The shell with weights `w`: `Φ[:, :k'] diag(w) ξ[:k']`.
    pub fn shell(&self, w: &[f64]) -> Vec<[f64; 3]> {
        let kk = w.len().min(self.phi.ncols());
        let coef = DMatrix::from_fn(kk, 3, |i, d| w[i] * self.xi[(i, d)]);
        points(&mul_ref(view(self.phi, kk), false, view(&coef, 3)))
    }

    /// `base + Φ[:, :k] τ[:k]`.
    pub fn deform(&self, base: &[[f64; 3]], tau: &DMatrix<f64>, k: usize) -> Vec<[f64; 3]> {
        let k = k.min(tau.nrows()).min(self.phi.ncols());
        let d = mul_ref(view(self.phi, k), false, view(tau, 3).subrows(0, k));
        base.iter()
            .enumerate()
            .map(|(r, b)| [b[0] + d[(r, 0)], b[1] + d[(r, 1)], b[2] + d[(r, 2)]])
            .collect()
    }
}

/// `a b` (or `aᵀ b` with `transpose_a`) by faer's GEMM.
pub(crate) fn mul(a: &DMatrix<f64>, transpose_a: bool, b: &DMatrix<f64>) -> DMatrix<f64> {
    mul_ref(view(a, a.ncols()), transpose_a, view(b, b.ncols()))
}

/// The first `k` columns of `m` as a faer view (no copy: a column-major
/// matrix's leading columns are a prefix of its storage).
pub(crate) fn view(m: &DMatrix<f64>, k: usize) -> faer::MatRef<'_, f64> {
    faer::MatRef::from_column_major_slice(&m.as_slice()[..m.nrows() * k], m.nrows(), k)
}

/// [`mul`] on faer views.
pub(crate) fn mul_ref(
    a: faer::MatRef<'_, f64>,
    transpose_a: bool,
    b: faer::MatRef<'_, f64>,
) -> DMatrix<f64> {
    use faer::linalg::matmul::matmul;
    let a = if transpose_a { a.transpose() } else { a };
    let mut out = DMatrix::zeros(a.nrows(), b.ncols());
    let par = if a.nrows() * a.ncols() * b.ncols() >= 1 << 20 {
        faer::Par::rayon(0)
    } else {
        faer::Par::Seq
    };
    matmul(
        faer::MatMut::from_column_major_slice_mut(out.as_mut_slice(), a.nrows(), b.ncols()),
        faer::Accum::Replace,
        a,
        b,
        1.0,
        par,
    );
    out
}

fn points(m: &DMatrix<f64>) -> Vec<[f64; 3]> {
    (0..m.nrows())
        .map(|r| [m[(r, 0)], m[(r, 1)], m[(r, 2)]])
        .collect()
}

/// Total area of a triangle mesh.
pub(crate) fn surface_area(verts: &[[f64; 3]], faces: &[[usize; 3]]) -> f64 {
    faces
        .iter()
        .map(|f| {
            let (a, b, c) = (v3(verts[f[0]]), v3(verts[f[1]]), v3(verts[f[2]]));
            0.5 * (b - a).cross(&(c - a)).norm()
        })
        .sum()
}

pub(super) fn v3(p: [f64; 3]) -> Vector3<f64> {
    Vector3::new(p[0], p[1], p[2])
}
