//! A shape's points and normals where a Smooth Shells level reads them:
//! every vertex ([`Posed`]) or its samples ([`Samples`], [`AtSamples`]).
//! The samples' one-ring ([`Ring`]) holds what the points and normals at
//! the samples need, so that the levels without ARAP and the energies
//! deform and orient a few thousand vertices instead of all of them; the
//! normals are oriented by the shape's own sign ([`orientation`](super::shell::orientation)).

use fmaps_mesh_io::vec3::{cross, sub};
use nalgebra::DMatrix;

use super::shell::{Shell, mul_ref, view};

/// Rows of a product embedding from which `level::search_params` takes the
/// ball search: above the default samples (2000), so the final point map
/// on every vertex (docs/tuning.md: neutral at 5k vertices, much faster
/// at 20k and 80k, the same maps).
pub(super) const BALLS_FROM_ROWS: usize = 4096;

/// `n` scaled to length 1 and oriented by `sign` (0 for a zero vector).
fn unit(n: [f64; 3], sign: f64) -> [f64; 3] {
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let s = if l > 0.0 { sign / l } else { 0.0 };
    [n[0] * s, n[1] * s, n[2] * s]
}

/// Area-weighted vertex normals (each vertex's faces' cross products
/// summed in face order), oriented by `sign` ([`orientation`](super::shell::orientation)).
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
    /// the other vertices' normals (docs/tuning.md).
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
    /// ([`super::level::correspondences`]): patches of ~[`fmaps_nearest::PartitionParams::ball_size`]
    /// samples (searched with the previous level's correspondences as
    /// guesses), or of every vertex of a large shape (one search each).
    pub cells: Option<Vec<u32>>,
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
            cells: Some(surface_cells(
                &idx.iter().map(|&i| s.verts[i]).collect::<Vec<_>>(),
                idx.len()
                    .div_ceil(fmaps_nearest::PartitionParams::default().ball_size),
            )),
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
        let cells = (cells && n >= BALLS_FROM_ROWS)
            .then(|| surface_cells(&s.verts, crate::search_cells(n)));
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

/// The cells of `m` farthest points among `points` (each point's nearest;
/// at least one cell): patches of the surface, on which positions,
/// normals and spectral features are smooth, for the ball search.
pub(super) fn surface_cells(points: &[[f64; 3]], m: usize) -> Vec<u32> {
    let (_, nearest) = crate::farthest_point_sampling_with_nearest(points, m.max(1), 0);
    nearest.into_iter().map(|c| c as u32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, Vector3};

    /// The points and normals at the samples from their one-ring are the
    /// numbers of every vertex's (the same GEMM rows, the same sums in
    /// face order), and the normals point outwards on a sphere; a
    /// reflected shell's orientation flips.
    #[test]
    fn the_samples_ring_poses_as_every_vertex_does() {
        let mesh = fmaps_shapes::icosphere(1.0, 5);
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
}
