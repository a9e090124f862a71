//! Geodesic distances on triangle meshes, from one or several source
//! vertices to every vertex (or only to chosen targets, stopping early).
//!
//! - [`ExactSolver`]: exact polyhedral distances by window propagation:
//!   vertex-oriented triangle propagation (VTP, Qin et al. 2016) with
//!   windows cast only into saddle shadows, or the window-ordered scheme
//!   (Chen and Han 1990 with the filtering of Xin and Wang 2009, and
//!   MMP-style trimming) as an independent reference, see
//!   [`ExactAlgorithm`]. Needs an edge-manifold mesh without degenerate
//!   faces; works with boundaries.
//! - [`HeatSolver`]: the heat method (Crane et al. 2013) with both linear
//!   systems prefactored, an approximation for many sources.
//! - [`DijkstraSolver`]: shortest paths along mesh edges, an upper bound of
//!   the geodesic distance (a fast baseline).
//!
//! All implement [`DistanceSolver`]; unreachable vertices (another
//! connected component) get `f64::INFINITY`, never NaN. Per source, memory
//! is O(n) for Dijkstra and the heat method, and O(n + pending windows)
//! for the exact solver (VTP holds at most 2-3.5k windows of 56 bytes at
//! once on 5k-vertex FAUST and TOSCA meshes; the window-ordered reference
//! keeps every window, 110-170k); [`DistanceSolver::fields`] runs many
//! sources in parallel (rayon).
//!
//! ```
//! use fmaps_geodesic::{DistanceSolver, ExactSolver};
//! use fmaps_shapes::grid;
//!
//! // On a flat grid exact geodesic distance is Euclidean distance.
//! let mesh = grid(2.0, 1.0, 8, 4);
//! let d = ExactSolver::new(&mesh)?.distances(&[0])?;
//! for (p, di) in mesh.vertices().iter().zip(&d) {
//!     assert!((di - (p[0] * p[0] + p[1] * p[1]).sqrt()).abs() < 1e-12);
//! }
//! # Ok::<(), fmaps_geodesic::Error>(())
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

mod exact;
mod heat;
mod topology;
mod vtp;

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use fmaps_mesh_io::TriMesh;
use rayon::prelude::*;

pub use exact::ExactStats;
pub use heat::{HeatParams, HeatSolver};
use topology::Topology;

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A source or target vertex index is out of range.
    #[error("vertex {index} is out of range: the mesh has {n_vertices} vertices")]
    VertexOutOfRange {
        /// The index.
        index: usize,
        /// Number of vertices.
        n_vertices: usize,
    },
    /// No source vertex was given.
    #[error("no source vertex given")]
    NoSources,
    /// A face has (numerically) zero area: it cannot be unfolded.
    #[error("face {face} is degenerate (zero area); exact geodesics need non-degenerate triangles")]
    DegenerateFace {
        /// The face.
        face: usize,
    },
    /// A parameter is out of range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
    /// A linear system of the heat method could not be factorized.
    #[error("heat method factorization failed: {0}")]
    Factorization(String),
    /// An edge is shared by more than two faces.
    #[error(
        "edge ({a}, {b}) is shared by more than two faces; exact geodesics need an edge-manifold mesh"
    )]
    NonManifoldEdge {
        /// One end.
        a: usize,
        /// The other end.
        b: usize,
    },
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A geodesic distance method, prepared for one mesh and reusable for many
/// sources.
pub trait DistanceSolver: Sync {
    /// A short name for reports ("exact", "dijkstra").
    fn name(&self) -> &'static str;

    /// Number of vertices of the mesh.
    fn n_vertices(&self) -> usize;

    /// Distance from the nearest of `sources` to every vertex.
    fn distances(&self, sources: &[usize]) -> Result<Vec<f64>>;

    /// Propagates from `sources` only until every vertex of `targets` is
    /// final, and returns the whole distance array at that point: exact for
    /// the targets and for every vertex no farther than the farthest
    /// target; elsewhere an upper bound (possibly infinity) that is at
    /// least the farthest target's distance.
    fn distances_until(&self, sources: &[usize], targets: &[usize]) -> Result<Vec<f64>>;

    /// Distances from the nearest of `sources` to each of `targets`, in
    /// order; stops as soon as all targets are final.
    fn distances_to(&self, sources: &[usize], targets: &[usize]) -> Result<Vec<f64>> {
        let d = self.distances_until(sources, targets)?;
        Ok(targets.iter().map(|&t| d[t]).collect())
    }

    /// One full distance field per source, computed in parallel.
    fn fields(&self, sources: &[usize]) -> Result<Vec<Vec<f64>>> {
        sources.par_iter().map(|&s| self.distances(&[s])).collect()
    }

    /// Checks source/target indices.
    fn check(&self, vertices: &[usize]) -> Result<()> {
        let n = self.n_vertices();
        match vertices.iter().find(|&&v| v >= n) {
            Some(&index) => Err(Error::VertexOutOfRange {
                index,
                n_vertices: n,
            }),
            None => Ok(()),
        }
    }
}

/// The propagation scheme of [`ExactSolver`]; both are exact and agree to
/// rounding (tested against each other and against tvb-gdist).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum ExactAlgorithm {
    /// Vertex-oriented triangle propagation (Qin et al. 2016): window lists
    /// per half-edge propagated a whole list at a time, vertices in a
    /// priority queue, pseudo-source windows cast only into a saddle's
    /// shadow. The faster (about 3x).
    #[default]
    Vtp,
    /// Windows one at a time in order of distance (Chen-Han as improved by
    /// Xin and Wang, with MMP-style trimming against accepted windows,
    /// casting all around saddles): the reference the other is tested
    /// against.
    WindowOrdered,
}

/// Exact polyhedral geodesic distances (see the crate docs).
#[derive(Debug, Clone)]
pub struct ExactSolver {
    topo: Topology,
    fans: vtp::Fans,
    algorithm: ExactAlgorithm,
}

impl ExactSolver {
    /// Prepares the mesh: edge lengths, adjacency, saddle and boundary
    /// vertices. Fails on degenerate faces and non-manifold edges.
    pub fn new(mesh: &TriMesh) -> Result<Self> {
        let topo = Topology::new(mesh, true)?;
        let fans = vtp::Fans::new(&topo);
        Ok(Self {
            topo,
            fans,
            algorithm: ExactAlgorithm::default(),
        })
    }

    /// The same solver computing whole fields with `algorithm`.
    pub fn with_algorithm(mut self, algorithm: ExactAlgorithm) -> Self {
        self.algorithm = algorithm;
        self
    }

    /// The scheme used for whole fields.
    pub fn algorithm(&self) -> ExactAlgorithm {
        self.algorithm
    }

    /// Like [`DistanceSolver::distances`], also returning propagation
    /// statistics.
    pub fn distances_with_stats(&self, sources: &[usize]) -> Result<(Vec<f64>, ExactStats)> {
        self.check(sources)?;
        if sources.is_empty() {
            return Err(Error::NoSources);
        }
        match self.algorithm {
            ExactAlgorithm::WindowOrdered => {
                let mut p = exact::Propagation::new(&self.topo);
                p.run(sources, None);
                Ok((p.dist, p.stats))
            }
            ExactAlgorithm::Vtp => {
                let mut p = vtp::Vtp::new(&self.topo, &self.fans);
                p.run(sources, None);
                Ok((p.dist, p.stats))
            }
        }
    }
}

impl DistanceSolver for ExactSolver {
    /// "exact" (VTP), or "exact-ordered" for the reference scheme.
    fn name(&self) -> &'static str {
        match self.algorithm {
            ExactAlgorithm::Vtp => "exact",
            ExactAlgorithm::WindowOrdered => "exact-ordered",
        }
    }

    fn n_vertices(&self) -> usize {
        self.topo.ring.len()
    }

    fn distances(&self, sources: &[usize]) -> Result<Vec<f64>> {
        Ok(self.distances_with_stats(sources)?.0)
    }

    fn distances_until(&self, sources: &[usize], targets: &[usize]) -> Result<Vec<f64>> {
        self.check(sources)?;
        self.check(targets)?;
        if sources.is_empty() {
            return Err(Error::NoSources);
        }
        Ok(match self.algorithm {
            ExactAlgorithm::WindowOrdered => {
                let mut p = exact::Propagation::new(&self.topo);
                p.run(sources, Some(targets));
                p.dist
            }
            ExactAlgorithm::Vtp => {
                let mut p = vtp::Vtp::new(&self.topo, &self.fans);
                p.run(sources, Some(targets));
                p.dist
            }
        })
    }
}

/// Exact distances from one source to every vertex.
pub fn exact_distance(mesh: &TriMesh, source: usize) -> Result<Vec<f64>> {
    ExactSolver::new(mesh)?.distances(&[source])
}

/// Shortest paths along mesh edges (Dijkstra). An upper bound of the
/// geodesic distance; it works on any mesh, manifold or not.
#[derive(Debug, Clone)]
pub struct DijkstraSolver {
    topo: Topology,
}

impl DijkstraSolver {
    /// Prepares the edge graph.
    pub fn new(mesh: &TriMesh) -> Self {
        Self {
            topo: Topology::new(mesh, false).expect("the non-exact topology cannot fail"),
        }
    }

    fn run(&self, sources: &[usize], targets: Option<&[usize]>) -> Vec<f64> {
        #[derive(PartialEq)]
        struct Q(f64, usize);
        impl Eq for Q {}
        impl PartialOrd for Q {
            fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
                Some(self.cmp(o))
            }
        }
        impl Ord for Q {
            fn cmp(&self, o: &Self) -> Ordering {
                o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
            }
        }
        let n = self.topo.ring.len();
        let mut dist = vec![f64::INFINITY; n];
        let mut done = vec![false; n];
        let mut heap = BinaryHeap::new();
        for &s in sources {
            dist[s] = 0.0;
            heap.push(Q(0.0, s));
        }
        let mut remaining = targets.map(|t| {
            let mut want = vec![false; n];
            t.iter().for_each(|&v| want[v] = true);
            (want, t.len())
        });
        while let Some(Q(d, v)) = heap.pop() {
            if done[v] {
                continue;
            }
            done[v] = true;
            if let Some((want, left)) = remaining.as_mut()
                && want[v]
            {
                want[v] = false;
                *left -= 1;
                if *left == 0 {
                    break;
                }
            }
            for &(u, l) in &self.topo.neighbours[v] {
                if d + l < dist[u] {
                    dist[u] = d + l;
                    heap.push(Q(d + l, u));
                }
            }
        }
        dist
    }
}

impl DistanceSolver for DijkstraSolver {
    fn name(&self) -> &'static str {
        "dijkstra"
    }

    fn n_vertices(&self) -> usize {
        self.topo.ring.len()
    }

    fn distances(&self, sources: &[usize]) -> Result<Vec<f64>> {
        self.check(sources)?;
        if sources.is_empty() {
            return Err(Error::NoSources);
        }
        Ok(self.run(sources, None))
    }

    fn distances_until(&self, sources: &[usize], targets: &[usize]) -> Result<Vec<f64>> {
        self.check(sources)?;
        self.check(targets)?;
        if sources.is_empty() {
            return Err(Error::NoSources);
        }
        Ok(self.run(sources, Some(targets)))
    }
}
