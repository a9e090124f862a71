//! One level of the Smooth Shells alignment: shells, product embedding,
//! correspondences, deformation and functional map; the geometry helpers
//! (normals, ARAP rotations) it needs.

use faer::{Mat, MatRef};
use fmaps_nn::{NnParams, nearest_rows};
use nalgebra::{DMatrix, Matrix3, Vector3};

use crate::icp::nearest_orthonormal;
use crate::{RefineReport, Result};

/// The sigmoid weights of the shell of size `k` (the paper's smooth
/// truncation of the spectrum): 1/2 at eigenfunction `k`, rising to ≈ 1
/// below it and falling to 1% at `k + 9` (at `2k − 1` for `k < 10`).
pub(crate) fn shell_weights(k: usize) -> Vec<f64> {
    const TRUNCATION: f64 = 1e-2;
    const WIDTH: usize = 10;
    if k <= 1 {
        return vec![1.0];
    }
    let half = if k >= WIDTH { WIDTH - 1 } else { k - 1 };
    let t = -(1.0 / (1.0 - TRUNCATION) - 1.0).ln() / half as f64;
    (-(k as i64 - 1)..=half as i64)
        .map(|j| 1.0 / (1.0 + (t * j as f64).exp()))
        .collect()
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
fn mul_ref(a: faer::MatRef<'_, f64>, transpose_a: bool, b: faer::MatRef<'_, f64>) -> DMatrix<f64> {
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

fn v3(p: [f64; 3]) -> Vector3<f64> {
    Vector3::new(p[0], p[1], p[2])
}

fn sub(p: [f64; 3], q: [f64; 3]) -> [f64; 3] {
    [p[0] - q[0], p[1] - q[1], p[2] - q[2]]
}

fn cross(p: [f64; 3], q: [f64; 3]) -> [f64; 3] {
    [
        p[1] * q[2] - p[2] * q[1],
        p[2] * q[0] - p[0] * q[2],
        p[0] * q[1] - p[1] * q[0],
    ]
}

/// The sign that orients a mesh's normals outwards: −1 when its signed
/// volume is negative (a closed mesh whose faces turn inwards), else 1.
/// A shape's shells and deformations keep its faces' orientation, so the
/// sign is the shape's own ([`Shell::orient`]), computed once.
pub(crate) fn orientation(verts: &[[f64; 3]], faces: &[[usize; 3]]) -> f64 {
    let mut volume = 0.0;
    for f in faces {
        let (a, b, c) = (verts[f[0]], verts[f[1]], verts[f[2]]);
        let bc = cross(b, c);
        volume += a[0] * bc[0] + a[1] * bc[1] + a[2] * bc[2];
    }
    if volume < 0.0 { -1.0 } else { 1.0 }
}

/// `n` scaled to length 1 and oriented by `sign` (0 for a zero vector).
fn unit(n: [f64; 3], sign: f64) -> [f64; 3] {
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let s = if l > 0.0 { sign / l } else { 0.0 };
    [n[0] * s, n[1] * s, n[2] * s]
}

/// Area-weighted vertex normals (each vertex's faces' cross products
/// summed in face order), oriented by `sign` ([`orientation`]).
pub(crate) fn normals(verts: &[[f64; 3]], faces: &[[usize; 3]], sign: f64) -> Vec<[f64; 3]> {
    let mut n = vec![[0.0f64; 3]; verts.len()];
    for f in faces {
        let (a, b, c) = (verts[f[0]], verts[f[1]], verts[f[2]]);
        let fnrm = cross(sub(b, a), sub(c, a));
        for &i in f {
            for d in 0..3 {
                n[i][d] += fnrm[d];
            }
        }
    }
    for v in &mut n {
        *v = unit(*v, sign);
    }
    n
}

/// Points of a shape (its shell, deformed or not) with their normals.
pub(crate) struct Posed {
    pub pts: Vec<[f64; 3]>,
    pub nrm: Vec<[f64; 3]>,
}

impl Posed {
    /// `pts` with their normals on `faces`, oriented by `sign`.
    pub fn new(pts: Vec<[f64; 3]>, faces: &[[usize; 3]], sign: f64) -> Posed {
        let nrm = normals(&pts, faces, sign);
        Posed { pts, nrm }
    }

    /// The points and normals at the samples `s` (borrowed when `s` is
    /// every vertex: [`Samples::all`]).
    pub fn at<'p>(&'p self, s: &Samples) -> AtSamples<'p> {
        use std::borrow::Cow;
        if s.len() == self.pts.len() {
            // Sorted distinct vertices, as many as there are: all, in order.
            return AtSamples {
                pts: Cow::Borrowed(&self.pts),
                nrm: Cow::Borrowed(&self.nrm),
            };
        }
        let gather = |v: &[[f64; 3]]| {
            if v.is_empty() {
                Vec::new()
            } else {
                s.iter().map(|&i| v[i]).collect()
            }
        };
        AtSamples {
            pts: Cow::Owned(gather(&self.pts)),
            nrm: Cow::Owned(gather(&self.nrm)),
        }
    }
}

/// Points and normals of a shape at its samples, in sample order (the
/// normals empty where their weight is 0).
pub(crate) struct AtSamples<'p> {
    pub pts: std::borrow::Cow<'p, [[f64; 3]]>,
    pub nrm: std::borrow::Cow<'p, [[f64; 3]]>,
}

/// The samples' one-ring: what the points and normals at the samples need
/// of a shape (the positions of the samples and their neighbours, the
/// samples' faces), so that the levels that need nothing else (no ARAP)
/// and the energies deform and orient a few thousand vertices instead of
/// all of them (80k-vertex meshes: ~1000-2000 samples, ~7 vertices each).
struct Ring {
    /// The samples and their neighbours, ascending.
    verts: Vec<usize>,
    /// `Φ[verts, :]`.
    phi: DMatrix<f64>,
    /// Each sample's position in `verts`.
    at: Vec<u32>,
    /// Each sample's faces in face order (sample `i`'s from
    /// `face_start[i]` to `face_start[i + 1]`), as positions in `verts`.
    face_start: Vec<usize>,
    faces: Vec<[u32; 3]>,
}

impl Ring {
    /// The ring of the samples `idx` of `s` (sorted, distinct). Even where
    /// it holds most vertices (FAUST at 5k: 1000 samples, ~80%) it saves
    /// the other vertices' normals (the default `fmaps match` ~2.5%
    /// faster there than every vertex's; neutral at 20k).
    fn new(s: &Shell<'_>, idx: &[usize]) -> Ring {
        let n = s.verts.len();
        let mut pos = vec![u32::MAX; n];
        for &i in idx {
            pos[i] = 0;
            for &j in &s.neighbours[i] {
                pos[j] = 0;
            }
        }
        let verts: Vec<usize> = (0..n).filter(|&i| pos[i] == 0).collect();
        for (p, &v) in verts.iter().enumerate() {
            pos[v] = p as u32;
        }
        let mut sample_of = vec![u32::MAX; n];
        for (k, &i) in idx.iter().enumerate() {
            sample_of[i] = k as u32;
        }
        // Each sample's faces, in face order (a counting sort by sample).
        let mut face_start = vec![0usize; idx.len() + 1];
        for f in s.faces {
            for &i in f {
                if sample_of[i] != u32::MAX {
                    face_start[sample_of[i] as usize + 1] += 1;
                }
            }
        }
        for k in 0..idx.len() {
            face_start[k + 1] += face_start[k];
        }
        let mut next = face_start.clone();
        let mut faces = vec![[0u32; 3]; face_start[idx.len()]];
        for f in s.faces {
            for &i in f {
                if sample_of[i] != u32::MAX {
                    let k = sample_of[i] as usize;
                    faces[next[k]] = [pos[f[0]], pos[f[1]], pos[f[2]]];
                    next[k] += 1;
                }
            }
        }
        Ring {
            phi: DMatrix::from_fn(verts.len(), s.phi.ncols(), |r, c| s.phi[(verts[r], c)]),
            at: idx.iter().map(|&i| pos[i]).collect(),
            verts,
            face_start,
            faces,
        }
    }

    /// The points and normals (when `normals`, oriented by `sign`) at the
    /// samples, of the points `p` of the ring's vertices.
    fn at_samples(&self, p: &[[f64; 3]], normals: bool, sign: f64) -> AtSamples<'static> {
        use std::borrow::Cow;
        let pts = self.at.iter().map(|&r| p[r as usize]).collect();
        let nrm = if normals {
            // Each sample's faces' cross products summed in face order, as
            // [`normals`] sums them.
            (0..self.at.len())
                .map(|i| {
                    let mut n = [0.0f64; 3];
                    for f in &self.faces[self.face_start[i]..self.face_start[i + 1]] {
                        let (a, b, c) = (p[f[0] as usize], p[f[1] as usize], p[f[2] as usize]);
                        let fnrm = cross(sub(b, a), sub(c, a));
                        for d in 0..3 {
                            n[d] += fnrm[d];
                        }
                    }
                    unit(n, sign)
                })
                .collect()
        } else {
            Vec::new()
        };
        AtSamples {
            pts: Cow::Owned(pts),
            nrm: Cow::Owned(nrm),
        }
    }
}

/// Sample vertices of a shape (`Deref` to their indices) with their rows
/// of Φ, gathered once: every level reads them for its correspondences and
/// fits, and rows of the whole Φ would be a cache miss each. Every vertex
/// ([`Samples::all`]) borrows Φ itself (a copy would be n x K).
pub(crate) struct Samples<'a> {
    pub idx: Vec<usize>,
    /// `Φ[idx, :]` (samples x K).
    pub phi: std::borrow::Cow<'a, DMatrix<f64>>,
    /// `√M` at the samples.
    pub sqrt_mass: Vec<f64>,
    /// Their one-ring ([`Samples::pose`]; none for every vertex).
    ring: Option<Ring>,
    /// Clusters of the rows for the ball search among them
    /// ([`search_params`]), when they are every vertex of a large shape.
    cells: Option<Vec<u32>>,
}

impl<'a> Samples<'a> {
    /// The samples `idx` (sorted, distinct) of `s`.
    pub fn new(s: &Shell<'_>, idx: Vec<usize>) -> Samples<'a> {
        Samples {
            phi: std::borrow::Cow::Owned(DMatrix::from_fn(idx.len(), s.phi.ncols(), |r, c| {
                s.phi[(idx[r], c)]
            })),
            sqrt_mass: idx.iter().map(|&i| s.mass[i].sqrt()).collect(),
            ring: Some(Ring::new(s, &idx)),
            cells: None,
            idx,
        }
    }

    /// Every vertex of `s`, in order (Φ borrowed); with `cells`, from
    /// [`BALLS_FROM_ROWS`] vertices, clusters for searching among their
    /// rows: the cells of [`crate::search_cells`] farthest points (each
    /// vertex's nearest), patches of the surface, on which the rows'
    /// positions, normals and spectral features are smooth. (A k-means
    /// of the rows themselves took longer than the search it saved: 80k
    /// vertices.)
    pub fn all(s: &Shell<'a>, cells: bool) -> Samples<'a> {
        let n = s.verts.len();
        let cells = (cells && n >= BALLS_FROM_ROWS).then(|| {
            let (_, nearest) =
                crate::farthest_point_sampling_with_nearest(&s.verts, crate::search_cells(n), 0);
            nearest.into_iter().map(|c| c as u32).collect()
        });
        Samples {
            phi: std::borrow::Cow::Borrowed(s.phi),
            sqrt_mass: s.mass.iter().map(|m| m.sqrt()).collect(),
            idx: (0..n).collect(),
            ring: None,
            cells,
        }
    }

    /// The points `base + Φ[:, :k] τ[:k]` of `s` (`base` without `tau`;
    /// the same numbers as [`Shell::deform`]) at the samples, with their
    /// normals when `normals` (else none), oriented by `s.orient`: on the
    /// samples' one-ring only (on every vertex for [`Samples::all`]).
    pub fn pose(
        &self,
        s: &Shell<'_>,
        base: &[[f64; 3]],
        tau: Option<(&DMatrix<f64>, usize)>,
        normals: bool,
    ) -> AtSamples<'static> {
        use std::borrow::Cow;
        let Some(ring) = &self.ring else {
            let pts = match tau {
                Some((t, k)) => s.deform(base, t, k),
                None => base.to_vec(),
            };
            let posed = if normals {
                Posed::new(pts, s.faces, s.orient)
            } else {
                Posed {
                    pts,
                    nrm: Vec::new(),
                }
            };
            let at = posed.at(self);
            return AtSamples {
                pts: Cow::Owned(at.pts.into_owned()),
                nrm: Cow::Owned(at.nrm.into_owned()),
            };
        };
        // The ring's points: each row of Φ τ by the same GEMM as every
        // vertex's (a row's products do not depend on the other rows).
        let p: Vec<[f64; 3]> = match tau {
            Some((t, k)) => {
                let k = k.min(t.nrows()).min(ring.phi.ncols());
                let d = mul_ref(view(&ring.phi, k), false, view(t, 3).subrows(0, k));
                ring.verts
                    .iter()
                    .enumerate()
                    .map(|(r, &v)| {
                        let b = base[v];
                        [b[0] + d[(r, 0)], b[1] + d[(r, 1)], b[2] + d[(r, 2)]]
                    })
                    .collect()
            }
            None => ring.verts.iter().map(|&v| base[v]).collect(),
        };
        ring.at_samples(&p, normals, s.orient)
    }

    /// [`Samples::pose`] of the points `pts` of every vertex of `s`.
    pub fn at_points(&self, s: &Shell<'_>, pts: &[[f64; 3]], normals: bool) -> AtSamples<'static> {
        match &self.ring {
            Some(ring) => {
                let p: Vec<[f64; 3]> = ring.verts.iter().map(|&v| pts[v]).collect();
                ring.at_samples(&p, normals, s.orient)
            }
            None => self.pose(s, pts, None, normals),
        }
    }
}

impl std::ops::Deref for Samples<'_> {
    type Target = [usize];
    fn deref(&self) -> &[usize] {
        &self.idx
    }
}

/// The normals' weight in the product space: `normals` times the ratio
/// of the coordinates' to the normals' norms on the samples, averaged
/// over both shapes.
fn normal_scale(px: &AtSamples, py: &AtSamples, normals: f64) -> f64 {
    if normals == 0.0 {
        // The normals may not have been computed (see [`level`]).
        return 0.0;
    }
    let part = |p: &AtSamples| normals * frob(&p.pts) / frob(&p.nrm).max(f64::MIN_POSITIVE);
    0.5 * (part(px) + part(py))
}

/// Weights of one level's energies.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LevelWeights {
    /// Spectral features relative to the coordinates (the paper's 0.25).
    pub features: f64,
    /// Normals relative to the coordinates (0 at k ≤ 10).
    pub normals: f64,
    /// Laplacian commutativity in the functional map fit (0: none).
    pub laplacian: f64,
    /// ARAP weight relative to the data term (0: none).
    pub arap: f64,
}

impl LevelWeights {
    /// The main alignment's weights (the paper's feature weight 0.25; its
    /// ARAP weight grows with the level and is set there).
    pub const MAIN: LevelWeights = LevelWeights {
        features: 0.25,
        normals: 0.04,
        laplacian: 0.0,
        arap: 0.0,
    };
}

/// The functional map the features come from: `C` (k' x k' with
/// `Φ_X C ≈ Φ_Y ∘ π`), the shell size `k` it was fitted at and that
/// level's weights.
#[derive(Debug, Clone)]
pub(crate) struct FeatureMap {
    pub c: DMatrix<f64>,
    pub k: usize,
    pub weights: Vec<f64>,
}

/// Rows `[p, fn · n, ff · F]` of the product embedding (a row per
/// sample).
fn embed(p: &AtSamples, fn_: f64, feat: Option<(&DMatrix<f64>, f64)>) -> Mat<f64> {
    let kf = feat.map_or(0, |(f, _)| f.ncols());
    // Normals at weight 0 are left out (their columns would be 0).
    let kn = if fn_ == 0.0 { 0 } else { 3 };
    let (pts, nrm) = (&p.pts, &p.nrm);
    Mat::from_fn(pts.len(), 3 + kn + kf, |r, c| {
        if c < 3 {
            pts[r][c]
        } else if c < 3 + kn {
            fn_ * nrm[r][c - 3]
        } else {
            let (f, s) = feat.expect("features");
            s * f[(r, c - 3 - kn)]
        }
    })
}

fn frob(p: &[[f64; 3]]) -> f64 {
    p.iter()
        .map(|v| v[0].powi(2) + v[1].powi(2) + v[2].powi(2))
        .sum::<f64>()
        .sqrt()
}

/// The spectral features of the samples of one shape: rows of
/// `Φ[:, :k'] C[:, :k] diag(w)` (X, with `c`) or `Φ[:, :k] diag(w)` (Y).
fn features(s: &Samples, fm: &FeatureMap, c: Option<&DMatrix<f64>>) -> DMatrix<f64> {
    let k = fm.k;
    match c {
        Some(c) => {
            let kk = c.nrows();
            let mut f = mul_ref(view(&s.phi, kk), false, view(c, k));
            for j in 0..k {
                f.column_mut(j).scale_mut(fm.weights[j]);
            }
            f
        }
        None => DMatrix::from_fn(s.len(), k, |r, j| s.phi[(r, j)] * fm.weights[j]),
    }
}

/// The state carried from level to level.
#[derive(Clone)]
pub(crate) struct Alignment {
    /// Deformation coefficients (K x 3) of X's shell.
    pub tau: DMatrix<f64>,
    /// The functional map of the last level.
    pub fmap: Option<FeatureMap>,
    /// A functional map block fixed while k ≤ 20 (from the initialisation).
    pub cfix: Option<DMatrix<f64>>,
}

/// Rows of a product embedding from which [`search_params`] takes the
/// ball search: above the default samples (2000), so the final point map
/// on every vertex (FAUST pairs, two threads: neutral at 5k
/// vertices, 7.9 → 6.4 s of refinement at 20k, 44 → 17 s at 80k, the
/// same maps).
const BALLS_FROM_ROWS: usize = 4096;

/// The search among the rows `data` of a product embedding. On the
/// samples (a few thousand rows, 6 to 200+ columns) brute force: it
/// measured twice as fast as the tree the automatic choice takes. From
/// [`BALLS_FROM_ROWS`] rows (the final point map on every vertex),
/// without matrix tiles, the ball search (exact: the same answers) over
/// k-means clusters sized for one search without guesses
/// ([`fmaps_nn::Partition::for_one_search`]): positions, normals and
/// spectral features are smooth on the surface, so the clusters are
/// compact (FAUST pair subdivided twice, 80k vertices, 197 columns: brute
/// force compared all 6.4·10⁹ pairs per finalist).
fn search_params(data: MatRef<'_, f64>, cells: Option<&[u32]>) -> NnParams {
    let partition = match cells {
        Some(c) => fmaps_nn::Partition::for_balls_from_labels(data, BALLS_FROM_ROWS, c.to_vec()),
        None => fmaps_nn::Partition::for_one_search(data, BALLS_FROM_ROWS),
    };
    match partition {
        Some(p) => NnParams::with_strategy(fmaps_nn::NnStrategy::Balls).with_partition(p),
        None => NnParams::with_strategy(fmaps_nn::NnStrategy::Brute),
    }
}

/// Correspondences of the samples in the product embedding: for each X
/// sample a Y sample (left empty unless `both`) and for each Y sample an X
/// sample (positions in the other shape's samples).
pub(crate) fn correspondences(
    px: &AtSamples,
    py: &AtSamples,
    (sx, sy): (&Samples, &Samples),
    w: &LevelWeights,
    fmap: Option<&FeatureMap>,
    both: bool,
    report: &mut RefineReport,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let (vx, vy) = (frob(&px.pts), frob(&py.pts));
    let fnm = normal_scale(px, py, w.normals);
    let feats = fmap.map(|fm| (features(sx, fm, Some(&fm.c)), features(sy, fm, None)));
    let (fx, fy) = match &feats {
        Some((fx, fy)) => {
            let (nfx, nfy) = (fx.norm(), fy.norm());
            let s = 0.5
                * (w.features * vx / nfx.max(f64::MIN_POSITIVE)
                    + w.features * vy / nfy.max(f64::MIN_POSITIVE));
            (Some((fx, s)), Some((fy, s)))
        }
        None => (None, None),
    };
    let ex = embed(px, fnm, fx);
    let ey = embed(py, fnm, fy);
    let t = std::time::Instant::now();
    let search = |d: &Mat<f64>, q: &Mat<f64>, cells: Option<&[u32]>| {
        nearest_rows(
            d.as_ref(),
            q.as_ref(),
            None,
            &search_params(d.as_ref(), cells),
        )
        .map_err(fmaps_solve::Error::Search)
    };
    let (ab, ba) = if both {
        report.nn_searches += 2;
        rayon::join(
            || search(&ey, &ex, sy.cells.as_deref()),
            || search(&ex, &ey, sx.cells.as_deref()),
        )
    } else {
        report.nn_searches += 1;
        (Ok(Vec::new()), search(&ex, &ey, sx.cells.as_deref()))
    };
    report.nn_seconds += t.elapsed().as_secs_f64();
    Ok((ab?, ba?))
}

/// Per-vertex ARAP rotations from `rest` to `cur` (one-ring Procrustes).
fn rotations(rest: &[[f64; 3]], cur: &[[f64; 3]], nb: &[Vec<usize>]) -> Vec<Matrix3<f64>> {
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
/// other: 80k FAUST pair, two threads, the default `fmaps match`'s
/// refinement 12.5-13.0 → 10.5 s (one matrix at a time before).
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
                    for k in 0..3 {
                        for l in 0..LANES {
                            let (akp, akq) = (a[k][p][l], a[k][q][l]);
                            let (np, nq) = (c[l] * akp - sn[l] * akq, sn[l] * akp + c[l] * akq);
                            a[k][p][l] = if on[l] { np } else { akp };
                            a[k][q][l] = if on[l] { nq } else { akq };
                        }
                    }
                    for k in 0..3 {
                        for l in 0..LANES {
                            let (apk, aqk) = (a[p][k][l], a[q][k][l]);
                            let (np, nq) = (c[l] * apk - sn[l] * aqk, sn[l] * apk + c[l] * aqk);
                            a[p][k][l] = if on[l] { np } else { apk };
                            a[q][k][l] = if on[l] { nq } else { aqk };
                        }
                    }
                    for row in &mut v {
                        for l in 0..LANES {
                            let (vp, vq) = (row[p][l], row[q][l]);
                            let (np, nq) = (c[l] * vp - sn[l] * vq, sn[l] * vp + c[l] * vq);
                            row[p][l] = if on[l] { np } else { vp };
                            row[q][l] = if on[l] { nq } else { vq };
                        }
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

/// The rotation `R` maximising `tr(R S)` (`S = Σ e e'ᵀ` of edges `e` at
/// rest and `e'` deformed: `R e ≈ e'`): with `S = U Σ Vᵀ`, `R = V diag(1,
/// 1, δ) Uᵀ`, `δ = ±1` making it a rotation (Kabsch). `V` and `Σ²` from the
/// eigenvectors `v` (columns) and eigenvalues `d` of `SᵀS`
/// ([`JacobiLanes`]), `u₁ = S v₁ / |S v₁|`, `u₂` the unit
/// part of `S v₂` orthogonal to `u₁`, and the third columns of both the
/// cross products of the first two (which is `δ`). A general SVD
/// (nalgebra's: a Householder reduction and QR sweeps) cost ~0.75 µs per
/// vertex and level: most of a Smooth Shells level at 80k vertices.
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

/// Both shapes' shells of one size and its weights.
pub(crate) struct Shells {
    pub weights: Vec<f64>,
    pub x: Vec<[f64; 3]>,
    pub y: Posed,
}

impl Shells {
    pub fn new(x: &Shell<'_>, y: &Shell<'_>, k: usize) -> Shells {
        let weights = shell_weights(k);
        Shells {
            x: x.shell(&weights),
            y: Posed::new(y.shell(&weights), y.faces, y.orient),
            weights,
        }
    }
}

/// One level of the alignment at shell size `k` (weights `wk`): the
/// correspondences, then the deformation τ (least squares of both
/// directions' residuals, plus ARAP), then the functional map (least
/// squares on the correspondences, made orthonormal).
#[allow(clippy::too_many_arguments)]
pub(crate) fn level(
    x: &Shell<'_>,
    y: &Shell<'_>,
    shells: &Shells,
    sx: &Samples,
    sy: &Samples,
    k: usize,
    w: &LevelWeights,
    arap_gram: Option<&DMatrix<f64>>,
    state: &mut Alignment,
    report: &mut RefineReport,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let (wk, xs, ys) = (&shells.weights, &shells.x, &shells.y);
    let kk = wk.len().min(x.phi.ncols()).min(y.phi.ncols());
    let kd = k.min(kk);
    let arap = arap_gram.filter(|_| w.arap > 0.0);
    // X deformed: on every vertex for ARAP, else at the samples only;
    // normals at the samples (at weight 0 they do not enter the
    // correspondences).
    let cur = arap.map(|_| x.deform(xs, &state.tau, kd));
    let px = match &cur {
        Some(pts) => sx.at_points(x, pts, w.normals > 0.0),
        None => sx.pose(x, xs, Some((&state.tau, kd)), w.normals > 0.0),
    };
    let (ab, ba) = correspondences(
        &px,
        &ys.at(sy),
        (sx, sy),
        w,
        state.fmap.as_ref(),
        true,
        report,
    )?;

    // Deformation: Σ ‖XS(s) + Φ(s)τ − YS(π s)‖² over both directions
    // (pairs of sample positions). Each X sample's pairs share its row of
    // Φ: the normal equations weight the row by its number of pairs and
    // sum its residuals (and, for the map, its partners' rows of Φ_Y).
    let pairs: Vec<(usize, usize)> = (0..sx.len())
        .zip(ab.iter().copied())
        .chain(ba.iter().copied().zip(0..sy.len()))
        .collect();
    let mut count = vec![0.0f64; sx.len()];
    let mut res = DMatrix::<f64>::zeros(sx.len(), 3);
    for &(xi, yi) in &pairs {
        count[xi] += 1.0;
        for d in 0..3 {
            res[(xi, d)] += ys.pts[sy[yi]][d] - xs[sx[xi]][d];
        }
    }
    let mut partners = DMatrix::<f64>::zeros(sx.len(), kk);
    for c in 0..kk {
        let (from, to) = (sy.phi.column(c), &mut partners.column_mut(c));
        for &(xi, yi) in &pairs {
            to[xi] += sx.sqrt_mass[xi] * from[yi];
        }
    }
    let a = view(&sx.phi, kd);
    let weighted = |w: &dyn Fn(usize) -> f64, cols: usize| {
        DMatrix::from_fn(sx.len(), cols, |r, c| w(r) * sx.phi[(r, c)])
    };
    let ca = weighted(&|r| count[r], kd);
    let mut m = mul_ref(view(&ca, kd), true, a);
    let mut z = mul_ref(a, true, view(&res, 3));
    if let (Some(g), Some(cur)) = (arap, &cur) {
        let ga = g.view((0, 0), (kd, kd));
        let rot = rotations(xs, cur, &x.neighbours);
        let mut b = vec![Vector3::zeros(); xs.len()];
        for (i, nb) in x.neighbours.iter().enumerate() {
            for &j in nb {
                let e = v3(xs[i]) - v3(xs[j]);
                let t = (rot[i] - Matrix3::identity()) * e;
                b[i] += t;
                b[j] -= t;
            }
        }
        let bm = DMatrix::from_fn(b.len(), 3, |r, d| b[r][d]);
        let za = mul_ref(view(x.phi, kd), true, view(&bm, 3));
        let s = w.arap * inf_norm(&m) / inf_norm(&ga.into_owned()).max(f64::MIN_POSITIVE);
        m += ga * s;
        z += za * s;
    }
    let reg = 1e-10 * inf_norm(&m).max(1e-300);
    m += DMatrix::identity(kd, kd) * reg;
    if let Some(sol) = m.clone().cholesky().map(|c| c.solve(&z)) {
        state.tau.view_mut((0, 0), (kd, 3)).copy_from(&sol);
    }

    // Functional map on the correspondences (area weighted).
    let ax = view(&sx.phi, kk);
    let cm = weighted(&|r| count[r] * sx.sqrt_mass[r] * sx.sqrt_mass[r], kk);
    let mm = mul_ref(view(&cm, kk), true, ax);
    let wx = weighted(&|r| sx.sqrt_mass[r], kk);
    let zz = mul_ref(view(&wx, kk), true, view(&partners, kk));
    let mut c = DMatrix::<f64>::zeros(kk, kk);
    if w.laplacian > 0.0 {
        let l = DMatrix::from_fn(kk, kk, |i, j| (x.evals[i] - y.evals[j]).abs().sqrt());
        let lmean = l.mean().max(f64::MIN_POSITIVE);
        let mabs = mm.abs().mean();
        for j in 0..kk {
            let mut a = mm.clone();
            for i in 0..kk {
                a[(i, i)] += w.laplacian / lmean * mabs * l[(i, j)];
            }
            if let Some(ch) = a.cholesky() {
                c.set_column(j, &ch.solve(&zz.column(j).into_owned()));
            }
        }
    } else if let Some(ch) =
        (mm.clone() + DMatrix::identity(kk, kk) * 1e-12 * inf_norm(&mm)).cholesky()
    {
        c = ch.solve(&zz);
    }
    let mut c = nearest_orthonormal(c);
    if let Some(fix) = state.cfix.as_ref().filter(|_| k <= 20) {
        let f = fix.nrows().min(kk);
        c.view_mut((0, 0), (f, kk)).fill(0.0);
        c.view_mut((0, 0), (kk, f)).fill(0.0);
        c.view_mut((0, 0), (f, f))
            .copy_from(&fix.view((0, 0), (f, f)));
        if kk > f {
            let rest = nearest_orthonormal(c.view((f, f), (kk - f, kk - f)).into_owned());
            c.view_mut((f, f), (kk - f, kk - f)).copy_from(&rest);
        }
    }
    state.fmap = Some(FeatureMap {
        c,
        k: kd,
        weights: wk[..kk].to_vec(),
    });
    Ok((ab, ba))
}

fn inf_norm(m: &DMatrix<f64>) -> f64 {
    m.row_iter()
        .map(|r| r.iter().map(|x| x.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// `2 Φᵀ L Φ` for the uniform graph Laplacian L of the mesh edges: the
/// Gram matrix of the ARAP term's Jacobian in the deformation basis.
pub(crate) fn arap_gram(x: &Shell<'_>, k: usize) -> DMatrix<f64> {
    let k = k.min(x.phi.ncols());
    let n = x.verts.len();
    let lphi = DMatrix::from_fn(n, k, |i, c| {
        x.neighbours[i]
            .iter()
            .map(|&j| x.phi[(i, c)] - x.phi[(j, c)])
            .sum::<f64>()
    });
    mul_ref(view(x.phi, k), true, view(&lphi, k)) * 2.0
}

/// The alignment energy of a result (the initialisation's score): the
/// area-weighted mean distance, over both directions' correspondences,
/// between matched points and normals of the deformed X and of Y at full
/// detail. Also returns the correspondences.
pub(crate) fn alignment_energy(
    x: &Shell<'_>,
    y: &Shell<'_>,
    sx: &Samples,
    sy: &Samples,
    state: &Alignment,
    w: &LevelWeights,
    report: &mut RefineReport,
) -> Result<f64> {
    let k = state.fmap.as_ref().map_or(state.tau.nrows(), |f| f.k);
    let cur = sx.pose(x, &x.verts, Some((&state.tau, k)), true);
    let full_y = sy.pose(y, &y.verts, None, true);
    let (ab, ba) = correspondences(
        &cur,
        &full_y,
        (sx, sy),
        w,
        state.fmap.as_ref(),
        true,
        report,
    )?;
    let fn_ = normal_scale(&cur, &full_y, w.normals);
    let (cur, nx, yv, ny) = (&cur.pts, &cur.nrm, &full_y.pts, &full_y.nrm);
    let dist = |i: usize, j: usize| {
        let mut s = 0.0;
        for d in 0..3 {
            s += (cur[i][d] - yv[j][d]).powi(2) + (fn_ * (nx[i][d] - ny[j][d])).powi(2);
        }
        s.sqrt()
    };
    // (Positions in the samples.)
    let mut e = 0.0;
    for (&i, (si, &j)) in sx.iter().zip(ab.iter().enumerate()) {
        e += x.mass[i] * dist(si, j);
    }
    for (&i, (sj, &j)) in ba.iter().zip(sy.iter().enumerate()) {
        e += y.mass[j] * dist(i, sj);
    }
    Ok(e / (sx.len() + sy.len()) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shell_weights_are_a_sigmoid_cut_at_k() {
        let w = shell_weights(30);
        assert_eq!(w.len(), 39);
        assert!((w[29] - 0.5).abs() < 1e-12, "1/2 at eigenfunction k");
        assert!((w[38] - 0.01).abs() < 1e-9, "1% at k + 9");
        assert!(w[0] > 0.9999);
        assert!(w.windows(2).all(|p| p[0] > p[1]));
        let w = shell_weights(4);
        assert_eq!(w.len(), 7);
        assert!((w[3] - 0.5).abs() < 1e-12 && (w[6] - 0.01).abs() < 1e-9);
        assert_eq!(shell_weights(1), vec![1.0]);
    }

    /// The points and normals at the samples from their one-ring are the
    /// numbers of every vertex's (the same GEMM rows, the same sums in
    /// face order), and the normals point outwards on a sphere; a
    /// reflected shell's orientation flips.
    #[test]
    fn the_samples_ring_poses_as_every_vertex_does() {
        let mesh = fmaps_mesh_io::generate::icosphere(1.0, 5);
        let (verts, faces) = (mesh.vertices(), mesh.faces());
        let n = verts.len();
        // Any smooth functions as the "basis", a uniform mass.
        let phi = DMatrix::from_fn(n, 40, |i, c| {
            let p = verts[i];
            ((c + 1) as f64 * p[0] + 0.3 * c as f64 * p[1] - p[2]).sin()
        });
        let mass = vec![1.0 / n as f64; n];
        let evals: Vec<f64> = (0..40).map(|c| c as f64).collect();
        let mut x = Shell::new(verts, faces, &phi, &mass, &evals);
        assert_eq!(x.orient, 1.0, "an icosphere is outward-oriented");
        let samples = Samples::new(&x, (0..n).step_by(40).collect());
        assert!(samples.ring.is_some());
        let tau = DMatrix::from_fn(49, 3, |r, d| 0.01 * ((r * 3 + d) as f64).cos());
        for k in [6, 40] {
            let ring = samples.pose(&x, &x.verts, Some((&tau, k)), true);
            let full = Posed::new(x.deform(&x.verts, &tau, k), x.faces, x.orient);
            let full = full.at(&samples);
            assert_eq!(ring.pts, full.pts, "k = {k}");
            assert_eq!(ring.nrm, full.nrm, "k = {k}");
        }
        // (The shell is centred and scaled to unit area: the radial
        // direction is the point over its length.)
        let outward = |a: &AtSamples| {
            a.pts.iter().zip(a.nrm.iter()).all(|(p, m)| {
                let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                (p[0] * m[0] + p[1] * m[1] + p[2] * m[2]) / r > 0.99
            })
        };
        assert!(outward(&samples.pose(&x, &x.verts, None, true)));
        x.rotate(&Matrix3::from_diagonal(&Vector3::new(-1.0, 1.0, 1.0)));
        assert_eq!(x.orient, -1.0, "a mirror image turns its faces inwards");
        assert!(outward(&samples.pose(&x, &x.verts, None, true)));
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
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
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
        let mut seed = 99u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
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
        for level in fmaps_simd::SimdLevel::ALL
            .into_iter()
            .filter(|l| l.detected())
        {
            fmaps_simd::set_simd_cap(Some(level));
            let got = fmaps_simd::dispatch(JacobiLanes(&b));
            fmaps_simd::set_simd_cap(None);
            assert_eq!(got.len(), want.len());
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                let bits = |x: &Option<([f64; 3], [[f64; 3]; 3])>| {
                    x.map(|(d, v)| (d.map(f64::to_bits), v.map(|r| r.map(f64::to_bits))))
                };
                assert_eq!(bits(g), bits(w), "matrix {i} at {level:?}");
            }
        }
        let skipped: Vec<_> = fmaps_simd::SimdLevel::ALL
            .into_iter()
            .filter(|l| !l.detected())
            .map(|l| l.name())
            .collect();
        if !skipped.is_empty() {
            eprintln!("skipped (this CPU lacks them): {skipped:?}");
        }
    }

    /// The final point map's search on many rows (the ball search where
    /// it pays) answers as brute force does: rows of a product embedding
    /// of a sphere (points, normals, smooth "spectral" features), queries
    /// from a perturbed copy.
    #[test]
    fn the_search_on_every_vertex_agrees_with_brute_force() {
        let n = BALLS_FROM_ROWS + 904;
        let embed = |shift: f64| {
            Mat::from_fn(n, 3 + 3 + 20, |i, c| {
                // A Fibonacci sphere: evenly spread points.
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let t = i as f64 * 2.399_963_229_728_653 + shift;
                let r = (1.0 - z * z).sqrt();
                let p = [r * t.cos(), r * t.sin(), z];
                match c {
                    0..3 => p[c],
                    3..6 => 0.3 * p[c - 3],
                    _ => 0.2 * ((c - 5) as f64 * (p[0] + 0.5 * p[1]) + shift).sin(),
                }
            })
        };
        let (data, queries) = (embed(0.0), embed(0.013));
        let want = nearest_rows(
            data.as_ref(),
            queries.as_ref(),
            None,
            &NnParams::with_strategy(fmaps_nn::NnStrategy::Brute),
        )
        .unwrap();
        // k-means clusters of the rows, and cells of farthest points on
        // the surface (as `Samples::all` makes them).
        let points: Vec<[f64; 3]> = (0..n)
            .map(|i| [data[(i, 0)], data[(i, 1)], data[(i, 2)]])
            .collect();
        let (_, nearest) =
            crate::farthest_point_sampling_with_nearest(&points, crate::search_cells(n), 0);
        let cells: Vec<u32> = nearest.into_iter().map(|c| c as u32).collect();
        for cells in [None, Some(cells.as_slice())] {
            let params = search_params(data.as_ref(), cells);
            if params.strategy != fmaps_nn::NnStrategy::Balls {
                eprintln!(
                    "skipped: the ball search is not chosen on this CPU (matrix tiles) or with \
                     FMAPS_NO_BALLS; brute force alone was compared with itself"
                );
            }
            let got = nearest_rows(data.as_ref(), queries.as_ref(), None, &params).unwrap();
            assert_eq!(got, want, "cells: {}", cells.is_some());
        }
    }
}
