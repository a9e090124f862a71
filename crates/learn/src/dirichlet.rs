//! The Dirichlet energy of the soft point maps: a smoothness term for
//! non-isometric pairs (ULRSSM's non-isometric setting, Cao, Roetzer,
//! Bernard, SIGGRAPH 2023; the soft maps of [`crate::coupling`]).
//!
//! The soft map from x to y, `P_xy = softmax(G_x G_yᵀ / τ)` by rows (the
//! cosine similarity of the normalised features), transports y's vertex
//! positions to x: `A = P_xy V_y`, one point of space per vertex of x. A
//! map that tears x apart sends neighbouring vertices far from each
//! other; its Dirichlet energy on x,
//!
//! `E_x = (1/d) Σ_c A_cᵀ L_x A_c = (1/d) Σ_{edges ij} w_ij ‖A_i − A_j‖²`
//!
//! (`L_x` the cotangent stiffness matrix, `w_ij = −L_ij` its edge
//! weights, `d` the number of coordinates, the mean over them as the
//! reference takes it), measures how much. The loss is `E_x + E_y`, both
//! directions. For the identity map of a shape onto itself it is
//! `2 · area / 3` per side: the coordinate functions' gradients on a
//! surface have squared norms summing to 2.
//!
//! The soft maps are n_x x n_y; on meshes of thousands of vertices the
//! energy is estimated on the edges around a sample of centre vertices
//! ([`DirichletShape::centres`]: each edge of a centre counted with the
//! weight `n / (2m)` for `m` centres of `n`, so the estimate's mean is
//! the energy), the soft map then going from the centres and their
//! neighbours onto a sample of the other shape's vertices
//! ([`DirichletShape::targets`]). With every vertex as a centre and as a
//! target it is the energy above exactly.

use nalgebra::DMatrix;
use sprs::CsMat;

use crate::coupling::{softmax_columns, softmax_columns_backward};
use crate::gemm::Op::{N, T};
use crate::gemm::mul;

/// One shape's side of the Dirichlet loss.
#[derive(Debug, Clone, Copy)]
pub struct DirichletShape<'a> {
    /// Per-vertex features (n x p), as the network outputs them.
    pub features: &'a DMatrix<f64>,
    /// Vertex positions (n x d; the unit-area shape's, d = 3).
    pub positions: &'a DMatrix<f64>,
    /// The cotangent stiffness matrix (n x n, compressed rows; its
    /// off-diagonal entries are minus the edge weights).
    pub stiffness: &'a CsMat<f64>,
    /// The centre vertices whose edges estimate this shape's energy
    /// (every vertex when `None`).
    pub centres: Option<&'a [usize]>,
    /// The vertices the other shape's soft map goes to (every vertex when
    /// `None`).
    pub targets: Option<&'a [usize]>,
}

/// The loss and its gradients.
#[derive(Debug, Clone)]
pub struct DirichletGrad {
    /// The loss `E_x + E_y`.
    pub loss: f64,
    /// d loss / d features of x (n_x x p).
    pub features_x: DMatrix<f64>,
    /// d loss / d features of y.
    pub features_y: DMatrix<f64>,
}

/// Normalised rows `rows` of `f`, and their norms before.
fn normalized_rows(f: &DMatrix<f64>, rows: &[usize]) -> (DMatrix<f64>, Vec<f64>) {
    let mut out = DMatrix::zeros(rows.len(), f.ncols());
    let mut norms = Vec::with_capacity(rows.len());
    for (r, &v) in rows.iter().enumerate() {
        let row = f.row(v);
        let norm = row.norm().max(1e-12);
        norms.push(norm);
        out.row_mut(r).copy_from(&(row / norm));
    }
    (out, norms)
}

/// Adds d loss / d features of rows `rows` to `out`, from d loss / d
/// their normalised rows `dg`.
fn add_unnormalized(
    out: &mut DMatrix<f64>,
    rows: &[usize],
    g: &DMatrix<f64>,
    norms: &[f64],
    dg: &DMatrix<f64>,
) {
    for (r, &v) in rows.iter().enumerate() {
        let dot = g.row(r).dot(&dg.row(r));
        for c in 0..out.ncols() {
            out[(v, c)] += (dg[(r, c)] - g[(r, c)] * dot) / norms[r];
        }
    }
}

/// One direction: the energy on `s` of the soft map from `s` to `t`;
/// adds the gradients to `ds` and `dt`.
fn one_side(
    s: &DirichletShape<'_>,
    t: &DirichletShape<'_>,
    tau: f64,
    ds: &mut DMatrix<f64>,
    dt: &mut DMatrix<f64>,
) -> f64 {
    let n = s.features.nrows();
    let all: Vec<usize>;
    let centres = match s.centres {
        Some(c) => c,
        None => {
            all = (0..n).collect();
            &all
        }
    };
    // The rows the soft map is needed at: the centres and their
    // neighbours, each once.
    let mut row_of = vec![usize::MAX; n];
    let mut rows = Vec::new();
    let mut edges = Vec::new();
    let mut touch = |v: usize, rows: &mut Vec<usize>| {
        if row_of[v] == usize::MAX {
            row_of[v] = rows.len();
            rows.push(v);
        }
        row_of[v]
    };
    for &i in centres {
        let ri = touch(i, &mut rows);
        if let Some(row) = s.stiffness.outer_view(i) {
            for (j, &l) in row.iter() {
                if j != i && l != 0.0 {
                    let rj = touch(j, &mut rows);
                    edges.push((ri, rj, -l));
                }
            }
        }
    }
    let scale = n as f64 / (2.0 * centres.len().max(1) as f64);
    let all_t: Vec<usize>;
    let targets = match t.targets {
        Some(c) => c,
        None => {
            all_t = (0..t.features.nrows()).collect();
            &all_t
        }
    };
    let (gs, norms_s) = normalized_rows(s.features, &rows);
    let (gt, norms_t) = normalized_rows(t.features, targets);
    // q = P_stᵀ (targets x rows): each column a distribution over the
    // targets.
    let q = softmax_columns(&mul(&gt, N, &gs, T), tau);
    let d = t.positions.ncols();
    let vt = DMatrix::from_fn(targets.len(), d, |r, c| t.positions[(targets[r], c)]);
    // A = P V_t (rows x d).
    let a = mul(&q, T, &vt, N);
    let mut loss = 0.0;
    let mut da = DMatrix::zeros(a.nrows(), d);
    let w_all = scale / d as f64;
    for &(ri, rj, w) in &edges {
        for c in 0..d {
            let diff = a[(ri, c)] - a[(rj, c)];
            loss += w_all * w * diff * diff;
            let g = 2.0 * w_all * w * diff;
            da[(ri, c)] += g;
            da[(rj, c)] -= g;
        }
    }
    // dq = V_t dAᵀ, then through the column softmax: dz (targets x rows)
    // is d (G_t G_sᵀ).
    let dq = mul(&vt, N, &da, T);
    let dz = softmax_columns_backward(&q, &dq, tau);
    let dgt = mul(&dz, N, &gs, N);
    let dgs = mul(&dz, T, &gt, N);
    add_unnormalized(ds, &rows, &gs, &norms_s, &dgs);
    add_unnormalized(dt, targets, &gt, &norms_t, &dgt);
    loss
}

/// The Dirichlet loss of the soft maps between `x` and `y` at
/// temperature `tau` (ULRSSM: 0.07), and its gradients.
///
/// ```
/// use fmaps_learn::dirichlet::{DirichletShape, dirichlet};
/// use nalgebra::DMatrix;
///
/// // A shape matched to itself by one-hot features at a low temperature:
/// // the identity map, whose energy is 2 · area / 3 per side.
/// let pair = fmaps_shapes::creature_pair(1);
/// let mesh = &pair.source;
/// let n = mesh.n_vertices();
/// let positions = DMatrix::from_fn(n, 3, |i, c| mesh.vertices()[i][c]);
/// let stiffness = fmaps_laplacian::cotan_stiffness(mesh);
/// let features = DMatrix::<f64>::identity(n, n);
/// let side = DirichletShape {
///     features: &features,
///     positions: &positions,
///     stiffness: &stiffness,
///     centres: None,
///     targets: None,
/// };
/// let g = dirichlet(&side, &side, 1e-3);
/// let area: f64 = fmaps_laplacian::mass_diagonal(mesh, fmaps_laplacian::MassKind::Lumped).iter().sum();
/// assert!((g.loss - 4.0 * area / 3.0).abs() < 1e-9 * area);
/// ```
pub fn dirichlet(x: &DirichletShape<'_>, y: &DirichletShape<'_>, tau: f64) -> DirichletGrad {
    let mut features_x = DMatrix::zeros(x.features.nrows(), x.features.ncols());
    let mut features_y = DMatrix::zeros(y.features.nrows(), y.features.ncols());
    let loss = one_side(x, y, tau, &mut features_x, &mut features_y)
        + one_side(y, x, tau, &mut features_y, &mut features_x);
    DirichletGrad {
        loss,
        features_x,
        features_y,
    }
}

/// The per-vertex positions of `mesh` as an n x 3 matrix.
pub fn positions(mesh: &fmaps_mesh_io::TriMesh) -> DMatrix<f64> {
    let v = mesh.vertices();
    DMatrix::from_fn(v.len(), 3, |i, c| v[i][c])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::SplitMix;

    fn shape() -> (fmaps_mesh_io::TriMesh, DMatrix<f64>, CsMat<f64>) {
        let pair = fmaps_shapes::creature_pair(1);
        let mesh = pair.source.to_unit_area().unwrap().0;
        let p = positions(&mesh);
        let l = fmaps_laplacian::cotan_stiffness(&mesh);
        (mesh, p, l)
    }

    fn random(n: usize, p: usize, seed: u64) -> DMatrix<f64> {
        let mut rng = SplitMix(seed);
        DMatrix::from_fn(n, p, |_, _| rng.unit() - 0.5)
    }

    /// The gradient against central finite differences, every centre and
    /// target and a sample of each.
    #[test]
    fn gradients_match_finite_differences() {
        let (mesh, pos, l) = shape();
        let n = mesh.n_vertices();
        let fx = random(n, 6, 3);
        let fy = random(n, 6, 4);
        let centres: Vec<usize> = (0..n).step_by(7).collect();
        let targets: Vec<usize> = (0..n).step_by(3).collect();
        for sampled in [false, true] {
            let (cs, ts) = (
                sampled.then_some(&centres[..]),
                sampled.then_some(&targets[..]),
            );
            fn side<'a>(
                pos: &'a DMatrix<f64>,
                l: &'a CsMat<f64>,
                c: Option<&'a [usize]>,
                t: Option<&'a [usize]>,
                f: &'a DMatrix<f64>,
            ) -> DirichletShape<'a> {
                DirichletShape {
                    features: f,
                    positions: pos,
                    stiffness: l,
                    centres: c,
                    targets: t,
                }
            }

            let tau = 0.2;
            let g = dirichlet(
                &side(&pos, &l, cs, ts, &fx),
                &side(&pos, &l, cs, ts, &fy),
                tau,
            );
            let h = 1e-6;
            for &(which, i, c) in &[(0, 0, 0), (0, 14, 3), (1, 3, 5), (1, 30, 1), (0, 7, 2)] {
                let (mut p, mut m) = (fx.clone(), fx.clone());
                let (mut q, mut r) = (fy.clone(), fy.clone());
                if which == 0 {
                    p[(i, c)] += h;
                    m[(i, c)] -= h;
                } else {
                    q[(i, c)] += h;
                    r[(i, c)] -= h;
                }
                let fd = (dirichlet(
                    &side(&pos, &l, cs, ts, &p),
                    &side(&pos, &l, cs, ts, &q),
                    tau,
                )
                .loss
                    - dirichlet(
                        &side(&pos, &l, cs, ts, &m),
                        &side(&pos, &l, cs, ts, &r),
                        tau,
                    )
                    .loss)
                    / (2.0 * h);
                let an = if which == 0 {
                    g.features_x[(i, c)]
                } else {
                    g.features_y[(i, c)]
                };
                assert!(
                    (fd - an).abs() <= 1e-6 * (1.0 + fd.abs()),
                    "sampled {sampled}, side {which}, ({i}, {c}): {fd} vs {an}"
                );
            }
        }
    }

    /// Every vertex given as centres and targets is the exact energy.
    #[test]
    fn all_vertices_sampled_is_the_energy() {
        let (mesh, pos, l) = shape();
        let n = mesh.n_vertices();
        let fx = random(n, 5, 8);
        let fy = random(n, 5, 9);
        let all: Vec<usize> = (0..n).collect();
        let side = |f, s: bool| DirichletShape {
            features: f,
            positions: &pos,
            stiffness: &l,
            centres: s.then_some(&all[..]),
            targets: s.then_some(&all[..]),
        };
        let a = dirichlet(&side(&fx, false), &side(&fy, false), 0.1);
        let b = dirichlet(&side(&fx, true), &side(&fy, true), 0.1);
        assert!((a.loss - b.loss).abs() < 1e-12 * a.loss);
        assert!((&a.features_x - &b.features_x).norm() < 1e-10 * a.features_x.norm());
    }

    /// The energy through the edges equals the quadratic form of the
    /// stiffness matrix on the transported positions (two computations),
    /// and a constant map (identical features everywhere) has none.
    #[test]
    fn energy_is_the_quadratic_form() {
        let (mesh, pos, l) = shape();
        let n = mesh.n_vertices();
        let fx = random(n, 4, 1);
        let fy = random(n, 4, 2);
        let tau = 0.3;
        let side = |f| DirichletShape {
            features: f,
            positions: &pos,
            stiffness: &l,
            centres: None,
            targets: None,
        };
        let g = dirichlet(&side(&fx), &side(&fy), tau);
        let transported = |a: &DMatrix<f64>, b: &DMatrix<f64>| {
            let (ga, _) = normalized_rows(a, &(0..n).collect::<Vec<_>>());
            let (gb, _) = normalized_rows(b, &(0..n).collect::<Vec<_>>());
            softmax_columns(&mul(&gb, N, &ga, T), tau).transpose() * &pos
        };
        let dense = DMatrix::from_fn(n, n, |i, j| *l.get(i, j).unwrap_or(&0.0));
        let form = |a: DMatrix<f64>| (a.transpose() * &dense * &a).trace() / 3.0;
        let expected = form(transported(&fx, &fy)) + form(transported(&fy, &fx));
        assert!(
            (g.loss - expected).abs() < 1e-10 * expected,
            "{} vs {expected}",
            g.loss
        );
        let flat = DMatrix::from_element(n, 4, 1.0);
        assert!(dirichlet(&side(&flat), &side(&flat), tau).loss.abs() < 1e-20);
    }
}
