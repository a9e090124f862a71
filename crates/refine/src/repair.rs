//! A repair refinement of the BCICP class (Ren, Poulenard, Wonka,
//! Ovsjanikov, "Continuous and Orientation-preserving Correspondences via
//! Functional Maps", SIGGRAPH Asia 2018): a pair of point maps `T_BA`,
//! `T_AB` alternately made bijective in the spectral domain and
//! continuous, covering and smooth in the point domain.
//!
//! Our reconstruction from the paper (the paper's point-domain steps use
//! all-pairs geodesic matrices; here every step is local or one
//! multi-source graph search, so it scales to any mesh size):
//!
//! 1. **Start**: `T_BA` from C and `T_AB` from Cᵀ (nearest neighbours),
//!    then a few rounds of both maps re-fitted to each other's functional
//!    map (the paper's smoothing in the functional domain).
//! 2. **Spectral step** (bijective ICP): with `C_AB`, `C_BA` the
//!    functional maps of the current point maps, both maps are updated by
//!    one nearest-neighbour search each in the concatenated embeddings of
//!    the orthogonality and bijectivity terms (`C_AB C_BA = I`), as in
//!    [`crate::DiscreteOp`]'s bijective ZoomOut at a fixed size.
//! 3. **Point-domain steps**, on each map with the other as its inverse:
//!    - *coverage*: a vertex `x` that no vertex maps to takes over the
//!      preimage `y = T_AB(x)` proposed by the inverse map when `T_BA(y)`
//!      has other preimages (so nothing else is uncovered);
//!    - *continuity*: an edge whose two ends map farther apart than three
//!      of the target's longest edges is torn; the vertices of torn edges
//!      and every component of the remaining edge graph smaller than 8% of
//!      the vertices (the paper's threshold) are outliers, and each takes
//!      the image of its nearest inlier (one multi-source Dijkstra over
//!      the edges);
//!    - *smoothness*: each vertex's image becomes the discrete geometric
//!      median of its one-ring's images (the candidate among them with the
//!      least summed distance to the others).
//!
//! Steps 2-3 are repeated `iterations` times. It needs the shapes'
//! geometry ([`RefineInput::with_geometry`](crate::RefineInput::with_geometry)); `fmaps match --refine
//! bcicp` and [`crate::Refiner`] pipelines pass it.

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::time::Instant;

use fmaps_solve::convert::{BasisRows, pullback};
use nalgebra::DMatrix;

use crate::discrete::{Shape, embeddings, search_rows};
use crate::{
    DiscreteWeights, Error, Iteration, RefineReport, Refined, Refiner, Result, ShapeGeometry,
    check_k, count_changed,
};

/// The repair refinement (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Repair {
    /// Size of the functional maps (the leading block of the input; `None`:
    /// the input's size).
    pub k: Option<usize>,
    /// Rounds of the spectral step followed by the point-domain steps.
    pub iterations: usize,
    /// Rounds of the functional-domain smoothing at the start.
    pub smoothing: usize,
}

impl Default for Repair {
    fn default() -> Self {
        Repair {
            k: None,
            iterations: 5,
            smoothing: 5,
        }
    }
}

/// Edges and edge lengths of a shape.
struct Graph {
    /// Neighbours of each vertex with the edge length.
    adj: Vec<Vec<(usize, f64)>>,
    longest: f64,
}

impl Graph {
    fn new(g: &ShapeGeometry<'_>) -> Graph {
        let n = g.vertices.len();
        let mut adj: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
        let mut longest = 0.0f64;
        for t in g.faces {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                let l = dist(g.vertices[a], g.vertices[b]);
                longest = longest.max(l);
                if !adj[a].iter().any(|e| e.0 == b) {
                    adj[a].push((b, l));
                    adj[b].push((a, l));
                }
            }
        }
        Graph { adj, longest }
    }
}

fn dist(p: [f64; 3], q: [f64; 3]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

/// Coverage from the inverse: `t` maps `src` vertices to `dst` vertices,
/// `inv` the other way.
fn cover_from_inverse(t: &mut [usize], inv: &[usize], n_dst: usize) {
    let mut count = vec![0usize; n_dst];
    for &x in t.iter() {
        count[x] += 1;
    }
    for (x, &y) in inv.iter().enumerate() {
        if count[x] == 0 && count[t[y]] > 1 {
            count[t[y]] -= 1;
            t[y] = x;
            count[x] += 1;
        }
    }
}

/// Continuity: outliers (see the module docs) take their nearest inlier's
/// image. `src` is the shape `t` maps from, `dst` the one it maps to.
fn fix_outliers(t: &mut [usize], src: &Graph, dst: &ShapeGeometry<'_>, dst_longest: f64) {
    let n = t.len();
    let tear = 3.0 * dst_longest;
    let mut torn = vec![false; n];
    for (x, nb) in src.adj.iter().enumerate() {
        for &(y, _) in nb {
            if dist(dst.vertices[t[x]], dst.vertices[t[y]]) > tear {
                torn[x] = true;
                torn[y] = true;
            }
        }
    }
    // Components of the graph without torn vertices.
    let mut comp = vec![usize::MAX; n];
    let mut sizes = Vec::new();
    for s in 0..n {
        if torn[s] || comp[s] != usize::MAX {
            continue;
        }
        let id = sizes.len();
        let mut stack = vec![s];
        comp[s] = id;
        let mut size = 0;
        while let Some(x) = stack.pop() {
            size += 1;
            for &(y, _) in &src.adj[x] {
                if !torn[y] && comp[y] == usize::MAX {
                    comp[y] = id;
                    stack.push(y);
                }
            }
        }
        sizes.push(size);
    }
    let small = (0.08 * n as f64).ceil() as usize;
    let inlier = |x: usize| !torn[x] && sizes[comp[x]] >= small;
    if !(0..n).any(inlier) {
        return;
    }
    // Multi-source Dijkstra from the inliers: each outlier takes the image
    // of the inlier it is reached from.
    let mut best = vec![f64::INFINITY; n];
    let mut from = vec![usize::MAX; n];
    let mut heap = BinaryHeap::new();
    for x in (0..n).filter(|&x| inlier(x)) {
        best[x] = 0.0;
        from[x] = x;
        heap.push(Entry(0.0, x));
    }
    while let Some(Entry(d, x)) = heap.pop() {
        if d > best[x] {
            continue;
        }
        for &(y, l) in &src.adj[x] {
            if d + l < best[y] {
                best[y] = d + l;
                from[y] = from[x];
                heap.push(Entry(d + l, y));
            }
        }
    }
    let old = t.to_vec();
    for x in 0..n {
        if from[x] != usize::MAX {
            t[x] = old[from[x]];
        }
    }
}

/// Min-heap entry (distance, vertex).
#[derive(PartialEq)]
struct Entry(f64, usize);
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

/// Smoothness: each image becomes the geometric median of the one-ring's
/// images (among those candidates).
fn smooth(t: &[usize], src: &Graph, dst: &ShapeGeometry<'_>) -> Vec<usize> {
    (0..t.len())
        .map(|x| {
            let mut cands: Vec<usize> = src.adj[x].iter().map(|e| t[e.0]).collect();
            cands.push(t[x]);
            let cost = |c: usize| -> f64 {
                cands
                    .iter()
                    .map(|&o| dist(dst.vertices[c], dst.vertices[o]))
                    .sum()
            };
            let mut best = (cost(t[x]), t[x]);
            for &c in &cands {
                let v = cost(c);
                if v < best.0 - 1e-15 {
                    best = (v, c);
                }
            }
            best.1
        })
        .collect()
}

impl Repair {
    fn size(&self, c_ab: &DMatrix<f64>) -> usize {
        self.k
            .unwrap_or(c_ab.nrows().min(c_ab.ncols()))
            .min(c_ab.nrows())
            .min(c_ab.ncols())
    }
}

impl Refiner for Repair {
    fn name(&self) -> String {
        format!(
            "bcicp-class repair{} {} rounds",
            self.k.map_or(String::new(), |k| format!(" k = {k}")),
            self.iterations
        )
    }

    fn for_initial_size(&self, k: usize) -> Option<Box<dyn Refiner>> {
        Some(Box::new(Repair {
            k: self.k.map(|own| own.min(k)),
            ..self.clone()
        }))
    }

    fn refine(&self, input: &crate::RefineInput<'_>) -> Result<Refined> {
        let (c_ab, basis_a, basis_b) = (input.c_ab, input.basis_a, input.basis_b);
        let (geo_a, geo_b) = input.geometry_for("the BCICP-class repair")?;
        let t0 = Instant::now();
        let k = self.size(c_ab);
        if k == 0 {
            return Err(Error::InvalidParameter(
                "the functional map is empty".into(),
            ));
        }
        check_k(basis_a, "A", k)?;
        check_k(basis_b, "B", k)?;
        crate::check_geometry(basis_a, basis_b, &geo_a, &geo_b)?;
        let (ga, gb) = (Graph::new(&geo_a), Graph::new(&geo_b));
        let a = Shape {
            phi: BasisRows::new(basis_a, k),
            mass: basis_a.mass.as_slice(),
            evals: basis_a.eigenvalues.as_slice(),
        };
        let b = Shape {
            phi: BasisRows::new(basis_b, k),
            mass: basis_b.mass.as_slice(),
            evals: basis_b.eigenvalues.as_slice(),
        };
        let mut report = RefineReport::start(self.name());
        let proper = DiscreteWeights {
            coupling: 0.0,
            bijectivity: 0.0,
            orthogonality: 1.0,
            laplacian: 0.0,
        };
        let bijective = DiscreteWeights {
            bijectivity: 1.0,
            ..proper
        };
        // 1. Start and functional smoothing.
        let c0 = c_ab.view((0, 0), (k, k)).into_owned();
        let c0t = c0.transpose();
        let (d, q) = embeddings(&proper, k, &a, &b, &c0, &c0t);
        let mut t_ba = search_rows(&d, &q, None, None, &mut report)?;
        let (d, q) = embeddings(&proper, k, &b, &a, &c0t, &c0);
        let mut t_ab = search_rows(&d, &q, None, None, &mut report)?;
        for _ in 0..self.smoothing {
            let c = pullback(&t_ba, &a.phi, k, &b.phi, k, b.mass)?;
            let c_ba = pullback(&t_ab, &b.phi, k, &a.phi, k, a.mass)?;
            let (d, q) = embeddings(&proper, k, &a, &b, &c, &c_ba);
            t_ba = search_rows(&d, &q, Some(&t_ba), None, &mut report)?;
            let (d, q) = embeddings(&proper, k, &b, &a, &c_ba, &c);
            t_ab = search_rows(&d, &q, Some(&t_ab), None, &mut report)?;
        }
        let point_domain = |t_ba: &mut Vec<usize>, t_ab: &mut Vec<usize>| {
            fix_outliers(t_ba, &gb, &geo_a, ga.longest);
            fix_outliers(t_ab, &ga, &geo_b, gb.longest);
            *t_ba = smooth(t_ba, &gb, &geo_a);
            *t_ab = smooth(t_ab, &ga, &geo_b);
            cover_from_inverse(t_ba, t_ab, a.phi.n());
            cover_from_inverse(t_ab, t_ba, b.phi.n());
        };
        point_domain(&mut t_ba, &mut t_ab);
        // 2-3. Spectral bijective step, then the point-domain steps.
        for _ in 0..self.iterations {
            let ti = Instant::now();
            let c = pullback(&t_ba, &a.phi, k, &b.phi, k, b.mass)?;
            let c_ba = pullback(&t_ab, &b.phi, k, &a.phi, k, a.mass)?;
            let (d, q) = embeddings(&bijective, k, &a, &b, &c, &c_ba);
            let mut next_ba = search_rows(&d, &q, Some(&t_ba), None, &mut report)?;
            let (d, q) = embeddings(&bijective, k, &b, &a, &c_ba, &c);
            let mut next_ab = search_rows(&d, &q, Some(&t_ab), None, &mut report)?;
            point_domain(&mut next_ba, &mut next_ab);
            report.iterations.push(Iteration {
                k: (k, k),
                changed: count_changed(Some(&t_ba), &next_ba),
                seconds: ti.elapsed().as_secs_f64(),
            });
            let same = next_ba == t_ba && next_ab == t_ab;
            t_ba = next_ba;
            t_ab = next_ab;
            if same {
                report.converged = true;
                break;
            }
        }
        let c = pullback(&t_ba, &a.phi, k, &b.phi, k, b.mass)?;
        report.seconds = t0.elapsed().as_secs_f64();
        Ok(Refined {
            c_ab: c,
            t_ba,
            report,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strip of `n` x 2 vertices (a ladder of triangles) along x.
    fn strip(n: usize) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
        let mut v = Vec::new();
        for i in 0..n {
            v.push([i as f64, 0.0, 0.0]);
            v.push([i as f64, 1.0, 0.0]);
        }
        let mut f = Vec::new();
        for i in 0..n - 1 {
            let (a, b, c, d) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
            f.push([a, c, b]);
            f.push([b, c, d]);
        }
        (v, f)
    }

    #[test]
    fn coverage_from_the_inverse_never_uncovers() {
        // t: 4 -> 4 hitting {0, 0, 1, 2}; the inverse proposes 3 <- 1.
        let mut t = vec![0, 0, 1, 2];
        let inv = vec![0, 2, 3, 1];
        cover_from_inverse(&mut t, &inv, 4);
        assert_eq!(t, vec![0, 3, 1, 2]);
        // A bijection stays as it is.
        let mut b = vec![1, 0, 3, 2];
        cover_from_inverse(&mut b, &[1, 0, 3, 2], 4);
        assert_eq!(b, vec![1, 0, 3, 2]);
    }

    #[test]
    fn an_island_takes_the_map_of_its_surroundings_and_smoothing_keeps_a_shift() {
        let (v, f) = strip(30);
        let g = ShapeGeometry {
            vertices: &v,
            faces: &f,
        };
        let graph = Graph::new(&g);
        // The identity with vertices 20 and 21 sent to the far end.
        let mut t: Vec<usize> = (0..60).collect();
        t[20] = 58;
        t[21] = 59;
        fix_outliers(&mut t, &graph, &g, graph.longest);
        // Both ends of a torn edge are outliers, so the island and its
        // rim take the image of the nearest vertex beyond the rim: within
        // two rungs of the truth instead of 19 away.
        assert!(dist(v[t[20]], v[20]) <= 2.5, "{}", t[20]);
        assert!(dist(v[t[21]], v[21]) <= 2.5, "{}", t[21]);
        // Away from the island nothing moves.
        assert!((0..60).filter(|x| !(16..26).contains(x)).all(|x| t[x] == x));
        // A shift by one rung is smooth: the median keeps it inside.
        let shift: Vec<usize> = (0..60).map(|x| (x + 2).min(58 + x % 2)).collect();
        let s = smooth(&shift, &graph, &g);
        assert!((4..54).all(|x| s[x] == shift[x]));
    }
}
