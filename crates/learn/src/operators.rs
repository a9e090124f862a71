//! DiffusionNet's per-shape operators (Sharp, Attaiki, Crane, Ovsjanikov,
//! "DiffusionNet: Discretization Agnostic Learning on Surfaces", ToG
//! 2022, section 3 and its supplement): what the network needs of a mesh,
//! computed once (they depend on the mesh only):
//!
//! - the lumped mass `M` and the first `k` eigenpairs of the cotangent
//!   Laplacian (`L φ = λ M φ`), for the learned diffusion in the spectral
//!   domain;
//! - a tangent frame per vertex (X, Y, normal);
//! - the gradient operators `G_X`, `G_Y` (n x n, sparse): for a function
//!   `f` on the vertices, `(G_X f)_i + i (G_Y f)_i` is its gradient at
//!   vertex `i` in the frame's coordinates, fitted by least squares to the
//!   differences along the vertex's edges.
//!
//! The frames and the least-squares fit follow the paper's reference
//! implementation: the vertex normal is the normalised sum of the unit
//! normals of the incident faces; X is the world axis x (or y, where the
//! normal is within `acos 0.9` of x) projected onto the tangent plane and
//! normalised, Y = normal × X; each vertex's gradient minimises
//! `Σ_j (g · e_ij − (f_j − f_i))² + ε |g|²` over its neighbours j, with
//! `e_ij` the edge vector in the frame and ε = 1e-5 ([`GRAD_REGULARIZATION`]).

use fmaps_eigensolve::{EigenProblem, EigenSolver, NativeSolver};
use fmaps_laplacian::{LaplacianParams, MassKind, cotan_laplacian};
use fmaps_mesh_io::TriMesh;
use fmaps_mesh_io::vec3::{cross, dot, sub};
use nalgebra::{DMatrix, DVector};
use sprs::{CsMat, TriMat};

use fmaps_mesh_io::operators::{OperatorsFile, SparseRows, read_operators, write_operators};

use crate::{Error, Result};

/// The ridge term ε of each vertex's least-squares gradient fit (as in
/// the reference implementation): keeps the 2 x 2 normal equations
/// invertible at vertices whose edges are (nearly) collinear.
pub const GRAD_REGULARIZATION: f64 = 1e-5;

/// An orthonormal frame at a vertex: two tangent directions and the unit
/// normal, `y = normal × x`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// First tangent direction.
    pub x: [f64; 3],
    /// Second tangent direction.
    pub y: [f64; 3],
    /// Unit normal.
    pub normal: [f64; 3],
}

/// The operators DiffusionNet needs of one shape.
#[derive(Debug, Clone)]
pub struct ShapeOperators {
    /// Lumped (barycentric) vertex areas, the diagonal of `M`.
    pub mass: DVector<f64>,
    /// The first `k` eigenvalues of `L φ = λ M φ`, ascending.
    pub eigenvalues: DVector<f64>,
    /// The eigenvectors (n x k), M-orthonormal.
    pub eigenvectors: DMatrix<f64>,
    /// A tangent frame per vertex.
    pub frames: Vec<Frame>,
    /// X components of the gradient (n x n, CSR).
    pub grad_x: CsMat<f64>,
    /// Y components of the gradient (n x n, CSR).
    pub grad_y: CsMat<f64>,
}

impl ShapeOperators {
    /// The operators of `mesh` with `k` eigenpairs (DiffusionNet's
    /// default: 128).
    ///
    /// Errors: `k` not below the vertex count, a vertex without a normal
    /// (in no face, or in degenerate faces only), the eigensolver's.
    ///
    /// ```
    /// let mesh = fmaps_shapes::icosphere(1.0, 2);
    /// let ops = fmaps_learn::ShapeOperators::compute(&mesh, 16)?;
    /// assert_eq!(ops.eigenvectors.shape(), (mesh.n_vertices(), 16));
    /// // A constant has no gradient: every row sums to zero.
    /// for row in ops.grad_x.outer_iterator().chain(ops.grad_y.outer_iterator()) {
    ///     assert!(row.iter().map(|(_, v)| v).sum::<f64>().abs() < 1e-9);
    /// }
    /// # Ok::<(), fmaps_learn::Error>(())
    /// ```
    pub fn compute(mesh: &TriMesh, k: usize) -> Result<ShapeOperators> {
        let n = mesh.n_vertices();
        if k == 0 || k >= n {
            return Err(Error::Parameter(format!(
                "{k} eigenpairs of a mesh of {n} vertices: expected 1 <= k < {n}"
            )));
        }
        let normals = vertex_normals(mesh)?;
        let frames = tangent_frames(&normals);
        let (grad_x, grad_y) = gradient_operators(mesh.vertices(), &edges(mesh), &frames);
        let op = cotan_laplacian(mesh, &LaplacianParams::with_mass(MassKind::Lumped));
        let problem = EigenProblem::new(op.stiffness.view(), &op.mass)?;
        let basis = NativeSolver::default().solve(&problem, k)?;
        Ok(ShapeOperators {
            mass: basis.mass,
            eigenvalues: basis.eigenvalues,
            eigenvectors: basis.eigenvectors,
            frames,
            grad_x,
            grad_y,
        })
    }
}

impl ShapeOperators {
    /// The operators of `mesh` around an eigenbasis computed elsewhere
    /// (`mass`, `eigenvalues`, `eigenvectors` of its cotangent Laplacian
    /// with lumped mass, as [`compute`](Self::compute) solves for, e.g. a
    /// matching pipeline's): only the frames and the gradients are
    /// computed. The features do not depend on the signs or the rotation
    /// within an eigenspace of the given vectors.
    ///
    /// Errors: sizes that do not match the mesh, a vertex without a
    /// normal.
    ///
    /// ```
    /// let mesh = fmaps_shapes::icosphere(1.0, 2);
    /// let ops = fmaps_learn::ShapeOperators::compute(&mesh, 16)?;
    /// let again = fmaps_learn::ShapeOperators::with_basis(
    ///     &mesh,
    ///     ops.mass.clone(),
    ///     ops.eigenvalues.clone(),
    ///     ops.eigenvectors.clone(),
    /// )?;
    /// assert_eq!(again.grad_x, ops.grad_x);
    /// # Ok::<(), fmaps_learn::Error>(())
    /// ```
    pub fn with_basis(
        mesh: &TriMesh,
        mass: DVector<f64>,
        eigenvalues: DVector<f64>,
        eigenvectors: DMatrix<f64>,
    ) -> Result<ShapeOperators> {
        let n = mesh.n_vertices();
        if mass.len() != n || eigenvectors.nrows() != n || eigenvectors.ncols() != eigenvalues.len()
        {
            return Err(Error::Parameter(format!(
                "a basis of {} masses, {} x {} eigenvectors and {} eigenvalues for a mesh of {n} vertices",
                mass.len(),
                eigenvectors.nrows(),
                eigenvectors.ncols(),
                eigenvalues.len()
            )));
        }
        let normals = vertex_normals(mesh)?;
        let frames = tangent_frames(&normals);
        let (grad_x, grad_y) = gradient_operators(mesh.vertices(), &edges(mesh), &frames);
        Ok(ShapeOperators {
            mass,
            eigenvalues,
            eigenvectors,
            frames,
            grad_x,
            grad_y,
        })
    }

    /// The cache key of `mesh`'s operators with `k` eigenpairs: the sizes,
    /// a 64-bit FNV-1a hash of the coordinates' and faces' bits, and the
    /// operators' version.
    pub fn key(mesh: &TriMesh, k: usize) -> String {
        let mut h: u64 = 0xcbf29ce484222325;
        let mut eat = |x: u64| {
            for b in x.to_le_bytes() {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x100000001b3);
            }
        };
        for p in mesh.vertices() {
            p.iter().for_each(|c| eat(c.to_bits()));
        }
        for f in mesh.faces() {
            f.iter().for_each(|&i| eat(i as u64));
        }
        format!(
            "diffusionnet-operators-1 n={} faces={} k={k} hash={h:016x}",
            mesh.n_vertices(),
            mesh.n_faces()
        )
    }

    /// The operators as a cache file ([`fmaps_mesh_io::operators`]) under
    /// `key`.
    pub fn to_file(&self, key: String) -> OperatorsFile {
        let sparse = |m: &CsMat<f64>| SparseRows {
            indptr: m.indptr().raw_storage().to_vec(),
            indices: m.indices().to_vec(),
            data: m.data().to_vec(),
        };
        OperatorsFile {
            key,
            mass: self.mass.as_slice().to_vec(),
            eigenvalues: self.eigenvalues.as_slice().to_vec(),
            eigenvectors: self.eigenvectors.as_slice().to_vec(),
            frames: self
                .frames
                .iter()
                .map(|f| std::array::from_fn(|i| [f.x, f.y, f.normal][i / 3][i % 3]))
                .collect(),
            grad_x: sparse(&self.grad_x),
            grad_y: sparse(&self.grad_y),
        }
    }

    /// The operators of a cache file (checked by its reader).
    ///
    /// Errors: a sparse structure `sprs` refuses (unsorted columns).
    pub fn from_file(f: OperatorsFile) -> Result<ShapeOperators> {
        let (n, k) = (f.n(), f.k());
        let sparse = |name: &str, m: SparseRows| {
            CsMat::try_new((n, n), m.indptr, m.indices, m.data)
                .map_err(|(_, _, _, e)| Error::Parameter(format!("{name}: {e}")))
        };
        Ok(ShapeOperators {
            eigenvectors: DMatrix::from_vec(n, k, f.eigenvectors),
            mass: DVector::from_vec(f.mass),
            eigenvalues: DVector::from_vec(f.eigenvalues),
            frames: f
                .frames
                .iter()
                .map(|r| Frame {
                    x: [r[0], r[1], r[2]],
                    y: [r[3], r[4], r[5]],
                    normal: [r[6], r[7], r[8]],
                })
                .collect(),
            grad_x: sparse("grad_x", f.grad_x)?,
            grad_y: sparse("grad_y", f.grad_y)?,
        })
    }

    /// [`compute`](Self::compute) through the cache file `path`: read
    /// when it holds this mesh's operators with `k` eigenpairs (its key,
    /// [`key`](Self::key), matches), else computed and written there
    /// (atomically). A damaged or foreign file is recomputed, never
    /// trusted. Returns the operators and whether they came from the file.
    ///
    /// Errors: [`compute`](Self::compute)'s, and a file that cannot be
    /// written.
    pub fn cached(
        mesh: &TriMesh,
        k: usize,
        path: &std::path::Path,
    ) -> Result<(ShapeOperators, bool)> {
        let key = ShapeOperators::key(mesh, k);
        if let Ok(f) = read_operators(path)
            && f.key == key
            && f.n() == mesh.n_vertices()
            && let Ok(ops) = ShapeOperators::from_file(f)
        {
            return Ok((ops, true));
        }
        let ops = ShapeOperators::compute(mesh, k)?;
        write_operators(path, &ops.to_file(key))?;
        Ok((ops, false))
    }
}

/// Unit vertex normals: the normalised sum of the unit normals of the
/// faces around each vertex (degenerate faces left out). Where those
/// cancel (a vertex whose faces fold back onto each other, as some
/// registered scans have), the normalised sum of the neighbours' normals
/// along the edges, repeated outwards until defined.
///
/// Errors: a vertex in no face (or in degenerate faces only) whose
/// connected part of the mesh has no normal anywhere.
pub fn vertex_normals(mesh: &TriMesh) -> Result<Vec<[f64; 3]>> {
    let v = mesh.vertices();
    let mut sum = vec![[0.0; 3]; v.len()];
    for f in mesh.faces() {
        let n = cross(sub(v[f[1]], v[f[0]]), sub(v[f[2]], v[f[0]]));
        let len = dot(n, n).sqrt();
        if !(len > 0.0 && len.is_finite()) {
            continue;
        }
        for &i in f {
            for c in 0..3 {
                sum[i][c] += n[c] / len;
            }
        }
    }
    let unit = |s: [f64; 3]| {
        let len = dot(s, s).sqrt();
        (len > 1e-12).then(|| s.map(|c| c / len))
    };
    let mut normals: Vec<Option<[f64; 3]>> = sum.into_iter().map(unit).collect();
    let neighbours = edges(mesh);
    loop {
        let missing: Vec<usize> = (0..normals.len())
            .filter(|&i| normals[i].is_none())
            .collect();
        if missing.is_empty() {
            break;
        }
        let filled: Vec<(usize, [f64; 3])> = missing
            .iter()
            .filter_map(|&i| {
                let mut s = [0.0; 3];
                for &j in &neighbours[i] {
                    if let Some(n) = normals[j] {
                        (0..3).for_each(|c| s[c] += n[c]);
                    }
                }
                unit(s).map(|n| (i, n))
            })
            .collect();
        if filled.is_empty() {
            return Err(Error::Mesh {
                vertex: missing[0],
                problem: "it has no normal: it is in no face or in degenerate faces only, and no neighbour has one".into(),
            });
        }
        for (i, n) in filled {
            normals[i] = Some(n);
        }
    }
    Ok(normals.into_iter().flatten().collect())
}

/// A frame per unit normal: X is the world axis x projected onto the
/// tangent plane (the axis y where `|normal · x| >= 0.9`), normalised;
/// `Y = normal × X`.
pub fn tangent_frames(normals: &[[f64; 3]]) -> Vec<Frame> {
    normals
        .iter()
        .map(|&n| {
            let axis = if n[0].abs() < 0.9 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            };
            let d = dot(axis, n);
            let t = [axis[0] - d * n[0], axis[1] - d * n[1], axis[2] - d * n[2]];
            let len = dot(t, t).sqrt();
            let x = t.map(|c| c / len);
            Frame {
                x,
                y: cross(n, x),
                normal: n,
            }
        })
        .collect()
}

/// The neighbours of every vertex along the mesh's edges, ascending.
pub fn edges(mesh: &TriMesh) -> Vec<Vec<usize>> {
    let mut nb = vec![Vec::new(); mesh.n_vertices()];
    for f in mesh.faces() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if a != b {
                nb[a].push(b);
                nb[b].push(a);
            }
        }
    }
    for l in &mut nb {
        l.sort_unstable();
        l.dedup();
    }
    nb
}

/// The gradient operators `(G_X, G_Y)` for vertices `vertices`, each
/// vertex's neighbours `neighbours` and frames `frames` (see the module
/// docs): row i holds, for each neighbour j, the coefficients of `f_j`,
/// and at i minus their sum, so a constant has zero gradient exactly. A
/// vertex without neighbours has a zero row.
pub fn gradient_operators(
    vertices: &[[f64; 3]],
    neighbours: &[Vec<usize>],
    frames: &[Frame],
) -> (CsMat<f64>, CsMat<f64>) {
    let n = vertices.len();
    let nnz: usize = neighbours.iter().map(|l| l.len() + 1).sum();
    let (mut gx, mut gy) = (
        TriMat::with_capacity((n, n), nnz),
        TriMat::with_capacity((n, n), nnz),
    );
    for (i, nb) in neighbours.iter().enumerate() {
        if nb.is_empty() {
            continue;
        }
        let fr = &frames[i];
        // The edge vectors in the frame: the rows of A.
        let a: Vec<[f64; 2]> = nb
            .iter()
            .map(|&j| {
                let e = sub(vertices[j], vertices[i]);
                [dot(e, fr.x), dot(e, fr.y)]
            })
            .collect();
        // (AᵀA + εI)⁻¹, 2 x 2.
        let (mut s00, mut s01, mut s11) = (GRAD_REGULARIZATION, 0.0, GRAD_REGULARIZATION);
        for r in &a {
            s00 += r[0] * r[0];
            s01 += r[0] * r[1];
            s11 += r[1] * r[1];
        }
        let det = s00 * s11 - s01 * s01;
        let inv = [[s11 / det, -s01 / det], [-s01 / det, s00 / det]];
        let (mut sum_x, mut sum_y) = (0.0, 0.0);
        for (r, &j) in a.iter().zip(nb) {
            // Column j of (AᵀA + εI)⁻¹ Aᵀ.
            let cx = inv[0][0] * r[0] + inv[0][1] * r[1];
            let cy = inv[1][0] * r[0] + inv[1][1] * r[1];
            gx.add_triplet(i, j, cx);
            gy.add_triplet(i, j, cy);
            sum_x += cx;
            sum_y += cy;
        }
        gx.add_triplet(i, i, -sum_x);
        gy.add_triplet(i, i, -sum_y);
    }
    (gx.to_csr(), gy.to_csr())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames are orthonormal and right-handed, with X from the world x
    /// axis except near it.
    #[test]
    fn frames_are_orthonormal_and_right_handed() {
        let normals: Vec<[f64; 3]> = [
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
            [0.6, 0.0, 0.8],
            [0.95, 0.3122498999199199, 0.0],
        ]
        .to_vec();
        for (n, f) in normals.iter().zip(tangent_frames(&normals)) {
            for (u, v, want) in [
                (f.x, f.x, 1.0),
                (f.y, f.y, 1.0),
                (f.normal, f.normal, 1.0),
                (f.x, f.y, 0.0),
                (f.x, f.normal, 0.0),
                (f.y, f.normal, 0.0),
            ] {
                assert!((dot(u, v) - want).abs() < 1e-12, "{n:?}");
            }
            // Right-handed: x × y = normal.
            let z = cross(f.x, f.y);
            assert!((dot(z, f.normal) - 1.0).abs() < 1e-12);
        }
        // The normal (0, 0, 1) keeps X = world x; (1, 0, 0) takes y.
        let f = tangent_frames(&normals);
        assert_eq!(f[0].x, [1.0, 0.0, 0.0]);
        assert_eq!(f[1].x, [0.0, 1.0, 0.0]);
    }
}
