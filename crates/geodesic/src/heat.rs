//! The heat method (K. Crane, C. Weischedel, M. Wardetzky, "Geodesics in
//! heat", ACM TOG 32(5), 2013): integrate the heat flow `(M + tL) u = δ`
//! for a short time `t = h²` (h the mean edge length), normalize the
//! gradient field `X = −∇u / |∇u|` per face, and recover the distance from
//! the Poisson equation `L φ = −∇·X` (our L is positive semi-definite, the
//! paper's Δ is its negative). Both systems are factorized once by
//! [`HeatSolver::new`] and reused for every source.

use fmaps_eigensolve::{EigenProblem, Factorization, ShiftInvert};
use fmaps_laplacian::{LaplacianParams, cotan_laplacian_from_lengths, intrinsic_delaunay};
use fmaps_mesh_io::TriMesh;

use crate::{DistanceSolver, Error, Result};
use fmaps_mesh_io::vec3::{dot, norm, sub};

/// Options of [`HeatSolver`].
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct HeatParams {
    /// The time step is `t_factor · h²`, h the mean edge length (the
    /// paper's default is 1).
    pub t_factor: f64,
}

impl Default for HeatParams {
    fn default() -> Self {
        Self { t_factor: 1.0 }
    }
}

/// The heat method with both linear systems prefactored (see the module
/// docs): an approximation with error of the order of the mesh spacing,
/// fast for many sources.
pub struct HeatSolver {
    n: usize,
    heat: ShiftInvert,
    poisson: ShiftInvert,
    /// Per face: the three vertex indices and the in-plane vectors
    /// `N × e_k` (e_k the edge opposite corner k), for gradients.
    faces: Vec<[usize; 3]>,
    rot_edges: Vec<[[f64; 3]; 3]>,
    /// Per face: the corner cotangents and edge vectors, for divergence.
    cot: Vec<[f64; 3]>,
    edges: Vec<[[f64; 3]; 3]>,
    /// The connected component of each vertex (by faces; an unreferenced
    /// vertex is a component of its own), and the number of components.
    component: Vec<usize>,
    n_components: usize,
}

/// Connected components of the vertices through the faces: a label per
/// vertex (0-based, in order of first vertex) and their number.
fn components(n: usize, faces: &[[usize; 3]]) -> (Vec<usize>, usize) {
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    let mut parent: Vec<usize> = (0..n).collect();
    for f in faces {
        for k in 1..3 {
            let (a, b) = (find(&mut parent, f[0]), find(&mut parent, f[k]));
            if a != b {
                parent[a.max(b)] = a.min(b);
            }
        }
    }
    let mut label = vec![usize::MAX; n];
    let mut count = 0;
    let mut out = vec![0; n];
    for v in 0..n {
        let r = find(&mut parent, v);
        if label[r] == usize::MAX {
            label[r] = count;
            count += 1;
        }
        out[v] = label[r];
    }
    (out, count)
}

impl std::fmt::Debug for HeatSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HeatSolver")
            .field("n", &self.n)
            .finish_non_exhaustive()
    }
}

impl HeatSolver {
    /// Builds the Laplacian and factorizes `M + tL` and (a tiny shift of)
    /// `L`. Degenerate faces are an error (their gradient is undefined).
    pub fn new(mesh: &TriMesh, params: &HeatParams) -> Result<Self> {
        // Everything below is intrinsic, on the intrinsic Delaunay
        // triangulation: L, and gradients/divergence on the same triangles,
        // each laid out in 2D from its edge lengths.
        let tri = intrinsic_delaunay(mesh);
        let op = cotan_laplacian_from_lengths(
            mesh.n_vertices(),
            &tri.faces,
            &tri.lengths,
            &LaplacianParams::default(),
        );
        if let Some(&face) = op.skipped_faces.first() {
            return Err(Error::DegenerateFace { face });
        }
        let faces = tri.faces;
        let mut h_sum = 0.0;
        let mut rot_edges = Vec::with_capacity(faces.len());
        let mut cot = Vec::with_capacity(faces.len());
        let mut edges = Vec::with_capacity(faces.len());
        for l in &tri.lengths {
            // Corner 0 at the origin, corner 1 on the x axis, corner 2 above.
            let x = (l[1] * l[1] - l[0] * l[0] + l[2] * l[2]) / (2.0 * l[2]);
            let y = (l[1] * l[1] - x * x).max(0.0).sqrt();
            let p = [[0.0, 0.0, 0.0], [l[2], 0.0, 0.0], [x, y, 0.0]];
            // e[k]: edge opposite corner k, counter-clockwise.
            let e = [sub(p[2], p[1]), sub(p[0], p[2]), sub(p[1], p[0])];
            let a2 = l[2] * y;
            // In the plane, N × e is e turned by +90°.
            rot_edges.push(e.map(|ek| [-ek[1], ek[0], 0.0]));
            let mut c = [0.0; 3];
            for k in 0..3 {
                c[k] = -dot(e[(k + 1) % 3], e[(k + 2) % 3]) / a2;
            }
            cot.push(c);
            edges.push(e);
            h_sum += l[0] + l[1] + l[2];
        }
        let h = h_sum / (3 * faces.len()) as f64;
        let t = params.t_factor * h * h;
        if !(t > 0.0 && t.is_finite()) {
            return Err(Error::InvalidParameter(format!(
                "heat time step {t} (t_factor {})",
                params.t_factor
            )));
        }
        let problem = EigenProblem::new(op.stiffness.view(), &op.mass)
            .map_err(|e| Error::Factorization(e.to_string()))?;
        // M + tL = t (L + M/t): the shift-invert factorization with σ = −1/t.
        let heat = ShiftInvert::new(&problem, -1.0 / t, 1, Factorization::Auto)
            .map_err(|e| Error::Factorization(e.to_string()))?;
        // L is singular (constants); a shift far below its first nonzero
        // eigenvalue only adds a constant, removed at the sources.
        let total: f64 = op.mass.iter().sum();
        let eps = 1e-8 * 4.0 * std::f64::consts::PI / total;
        let poisson = ShiftInvert::new(&problem, -eps, 1, Factorization::Auto)
            .map_err(|e| Error::Factorization(e.to_string()))?;
        let (component, n_components) = components(mesh.n_vertices(), mesh.faces());
        Ok(Self {
            n: mesh.n_vertices(),
            heat,
            poisson,
            faces,
            rot_edges,
            cot,
            edges,
            component,
            n_components,
        })
    }

    fn solve(&self, sources: &[usize]) -> Vec<f64> {
        let n = self.n;
        // (M + tL) u = δ  ⇔  (L + M/t) u = δ / t; the scale of u does not
        // matter, only its gradient's direction.
        let mut u = vec![0.0; n];
        for &s in sources {
            u[s] = 1.0;
        }
        self.heat.solve_in_place(&mut u, 1);
        let mut div = vec![0.0; n];
        for (fi, f) in self.faces.iter().enumerate() {
            let r = &self.rot_edges[fi];
            let mut g = [0.0; 3];
            for k in 0..3 {
                for c in 0..3 {
                    g[c] += u[f[k]] * r[k][c];
                }
            }
            let gn = norm(g);
            if gn == 0.0 {
                continue;
            }
            // X = −∇u/|∇u| (the 1/(2A) of the gradient cancels).
            let x = [-g[0] / gn, -g[1] / gn, -g[2] / gn];
            let (c, e) = (&self.cot[fi], &self.edges[fi]);
            for k in 0..3 {
                // The edges leaving corner k are (k → k+1) = e[k+2] and
                // (k → k+2) = −e[k+1], each weighted by the cotangent of the
                // angle opposite it (at corners k+2 and k+1).
                let to_next = e[(k + 2) % 3];
                let to_prev = [-e[(k + 1) % 3][0], -e[(k + 1) % 3][1], -e[(k + 1) % 3][2]];
                div[f[k]] +=
                    0.5 * (c[(k + 2) % 3] * dot(to_next, x) + c[(k + 1) % 3] * dot(to_prev, x));
            }
        }
        // L φ = −div.
        let mut phi: Vec<f64> = div.iter().map(|d| -d).collect();
        self.poisson.solve_in_place(&mut phi, 1);
        // φ is defined up to a constant per connected component: each
        // component's is fixed by its own sources (their mean is 0), and a
        // component without a source is unreachable (infinite distance, as
        // the exact solver and Dijkstra say).
        let mut sum = vec![0.0; self.n_components];
        let mut count = vec![0usize; self.n_components];
        for &s in sources {
            sum[self.component[s]] += phi[s];
            count[self.component[s]] += 1;
        }
        for (p, &c) in phi.iter_mut().zip(&self.component) {
            *p = if count[c] == 0 {
                f64::INFINITY
            } else {
                (*p - sum[c] / count[c] as f64).max(0.0)
            };
        }
        phi
    }
}

impl DistanceSolver for HeatSolver {
    fn name(&self) -> &'static str {
        "heat"
    }

    fn n_vertices(&self) -> usize {
        self.n
    }

    fn distances(&self, sources: &[usize]) -> Result<Vec<f64>> {
        self.check(sources)?;
        if sources.is_empty() {
            return Err(Error::NoSources);
        }
        Ok(self.solve(sources))
    }

    /// The heat method has no early stop: the whole field is computed.
    fn distances_until(&self, sources: &[usize], targets: &[usize]) -> Result<Vec<f64>> {
        self.check(targets)?;
        self.distances(sources)
    }
}
