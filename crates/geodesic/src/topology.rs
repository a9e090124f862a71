//! Intrinsic mesh data shared by the solvers: edge lengths per face corner,
//! face adjacency across edges, vertex one-rings, saddle/boundary flags.

use fmaps_mesh_io::TriMesh;

use crate::{Error, Result};

/// Edge `k` of face `f` joins corners `k+1` and `k+2` (mod 3), i.e. it is
/// the edge opposite corner `k`, oriented from `f[k+1]` to `f[k+2]`.
#[derive(Debug, Clone)]
pub(crate) struct Topology {
    pub faces: Vec<[usize; 3]>,
    /// `len[f][k]`: length of edge k of face f.
    pub len: Vec<[f64; 3]>,
    /// Per face and edge k: `3 g + j` for the face g across edge k and
    /// that edge's index j there, `u32::MAX` on the boundary (compact: the
    /// exact propagation reads it for every window).
    across: Vec<[u32; 3]>,
    /// Faces around each vertex, with the vertex's corner index in each.
    pub ring: Vec<Vec<(usize, usize)>>,
    /// Geodesics can bend at saddle (angle sum > 2π) and boundary vertices.
    pub pseudo_source: Vec<bool>,
    /// Undirected edges with lengths, for Dijkstra: per vertex, neighbours.
    pub neighbours: Vec<Vec<(usize, f64)>>,
}

impl Topology {
    pub(crate) fn new(mesh: &TriMesh, exact: bool) -> Result<Self> {
        let v = mesh.vertices();
        let faces = mesh.faces().to_vec();
        let n = mesh.n_vertices();
        let dist = |a: usize, b: usize| {
            let (p, q) = (v[a], v[b]);
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        };
        let mut len = Vec::with_capacity(faces.len());
        for (fi, f) in faces.iter().enumerate() {
            let l = [dist(f[1], f[2]), dist(f[2], f[0]), dist(f[0], f[1])];
            if exact {
                // Strict triangle inequality: the face can be unfolded.
                let s = (l[0] + l[1] + l[2]) * 0.5;
                let area2 = s * (s - l[0]) * (s - l[1]) * (s - l[2]);
                let longest = l[0].max(l[1]).max(l[2]);
                if !(area2 > 1e-24 * longest.powi(4)) {
                    return Err(Error::DegenerateFace { face: fi });
                }
            }
            len.push(l);
        }
        let fa = mesh.face_adjacency();
        if exact && let Some(&[a, b]) = fa.non_manifold_edges.first() {
            return Err(Error::NonManifoldEdge { a, b });
        }
        let adj = fa.across;
        let mut ring = vec![Vec::new(); n];
        let mut angle = vec![0.0f64; n];
        let mut boundary = vec![false; n];
        for (fi, f) in faces.iter().enumerate() {
            for k in 0..3 {
                ring[f[k]].push((fi, k));
                if exact {
                    angle[f[k]] += corner_angle(len[fi], k);
                }
                if adj[fi][k].is_none() {
                    boundary[f[(k + 1) % 3]] = true;
                    boundary[f[(k + 2) % 3]] = true;
                }
            }
        }
        let two_pi = 2.0 * std::f64::consts::PI;
        let pseudo_source = (0..n)
            .map(|i| boundary[i] || angle[i] > two_pi + 1e-10)
            .collect();
        let mut neighbours = vec![Vec::new(); n];
        for (fi, f) in faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (f[(k + 1) % 3], f[(k + 2) % 3]);
                // Each undirected edge once: from the face with the smaller
                // index (or the only face, on the boundary).
                let owner = adj[fi][k].is_none_or(|(g, _)| fi < g);
                if owner {
                    neighbours[a].push((b, len[fi][k]));
                    neighbours[b].push((a, len[fi][k]));
                }
            }
        }
        let across = adj
            .iter()
            .map(|a| a.map(|x| x.map_or(u32::MAX, |(g, j)| (3 * g + j) as u32)))
            .collect();
        Ok(Self {
            faces,
            len,
            across,
            ring,
            pseudo_source,
            neighbours,
        })
    }
}

impl Topology {
    /// The face across edge `k` of face `f`, and that edge's index there.
    #[inline]
    pub(crate) fn adj(&self, f: usize, k: usize) -> Option<(usize, usize)> {
        let c = self.across[f][k];
        (c != u32::MAX).then_some((c as usize / 3, c as usize % 3))
    }
}

/// The angle at corner k of a triangle with edge lengths `l` (edge k
/// opposite corner k), by the law of cosines, clamped for rounding.
pub(crate) fn corner_angle(l: [f64; 3], k: usize) -> f64 {
    let (a, b, c) = (l[k], l[(k + 1) % 3], l[(k + 2) % 3]);
    ((b * b + c * c - a * a) / (2.0 * b * c))
        .clamp(-1.0, 1.0)
        .acos()
}
