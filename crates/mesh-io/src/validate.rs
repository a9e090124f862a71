//! The mesh validation report.

use crate::TriMesh;
use crate::vec3::{cross, norm, sub};

/// Combinatorics and defects of a triangle mesh, from [`TriMesh::validate`].
///
/// Element lists hold 0-based indices. Euler characteristic and genus count
/// only referenced vertices (an isolated vertex is not part of the surface).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[non_exhaustive]
pub struct MeshReport {
    /// Number of vertices (including unreferenced ones).
    pub n_vertices: usize,
    /// Number of triangles.
    pub n_faces: usize,
    /// Number of distinct undirected edges.
    pub n_edges: usize,
    /// Total surface area.
    pub area: f64,
    /// Axis-aligned bounding box: `[min, max]`.
    pub bounding_box: [[f64; 3]; 2],
    /// Faces with zero area: a repeated vertex index, or a cross product of
    /// norm at most `1e-14` times the squared longest edge.
    pub degenerate_faces: Vec<usize>,
    /// Faces with the same three vertices as an earlier face (any order);
    /// the later copies are listed.
    pub duplicate_faces: Vec<usize>,
    /// Edges shared by more than two faces, as `[min, max]` vertex pairs.
    pub non_manifold_edges: Vec<[usize; 2]>,
    /// Vertices whose incident faces form more than one fan (bow-ties).
    pub non_manifold_vertices: Vec<usize>,
    /// Number of edges with exactly one incident face.
    pub boundary_edges: usize,
    /// Number of connected components of the boundary-edge graph.
    pub boundary_loops: usize,
    /// Number of connected components of the surface (edge-connected).
    pub connected_components: usize,
    /// Vertices no face uses.
    pub unreferenced_vertices: Vec<usize>,
    /// Manifold edges whose two faces traverse them in the same direction.
    pub inconsistently_oriented_edges: usize,
    /// V - E + F over referenced vertices.
    pub euler_characteristic: i64,
    /// Total genus `sum_c (2 - chi_c - b_c) / 2`, when the mesh is an
    /// edge- and vertex-manifold; `None` otherwise.
    pub genus: Option<i64>,
}

impl MeshReport {
    /// True when the mesh is an edge- and vertex-manifold.
    pub fn is_manifold(&self) -> bool {
        self.non_manifold_edges.is_empty() && self.non_manifold_vertices.is_empty()
    }

    /// True for a manifold without boundary.
    pub fn is_closed_manifold(&self) -> bool {
        self.is_manifold() && self.boundary_edges == 0
    }

    /// True when nothing needs attention: manifold, consistently oriented,
    /// one component, no degenerate, duplicate or unreferenced elements.
    pub fn is_clean(&self) -> bool {
        self.is_manifold()
            && self.inconsistently_oriented_edges == 0
            && self.connected_components == 1
            && self.degenerate_faces.is_empty()
            && self.duplicate_faces.is_empty()
            && self.unreferenced_vertices.is_empty()
    }
}

struct Dsu(Vec<usize>);

impl Dsu {
    fn new(n: usize) -> Self {
        Dsu((0..n).collect())
    }
    fn find(&mut self, mut x: usize) -> usize {
        while self.0[x] != x {
            self.0[x] = self.0[self.0[x]];
            x = self.0[x];
        }
        x
    }
    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.0[ra.max(rb)] = ra.min(rb);
        }
    }
}

pub(crate) fn report(mesh: &TriMesh) -> MeshReport {
    let v = mesh.vertices();
    let f = mesh.faces();
    let n = v.len();

    let mut bbox = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
    for p in v {
        for c in 0..3 {
            bbox[0][c] = bbox[0][c].min(p[c]);
            bbox[1][c] = bbox[1][c].max(p[c]);
        }
    }

    let mut area = 0.0;
    let mut degenerate_faces = Vec::new();
    for (fi, t) in f.iter().enumerate() {
        let [a, b, c] = t.map(|i| v[i]);
        let cr = norm(cross(sub(b, a), sub(c, a)));
        area += 0.5 * cr;
        let longest = [norm(sub(b, a)), norm(sub(c, b)), norm(sub(a, c))]
            .into_iter()
            .fold(0.0, f64::max);
        let repeated = t[0] == t[1] || t[1] == t[2] || t[0] == t[2];
        if repeated || cr <= 1e-14 * longest * longest {
            degenerate_faces.push(fi);
        }
    }

    let mut sorted: Vec<([usize; 3], usize)> = f
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let mut s = *t;
            s.sort_unstable();
            (s, i)
        })
        .collect();
    sorted.sort_unstable();
    let mut duplicate_faces: Vec<usize> = sorted
        .windows(2)
        .filter(|w| w[0].0 == w[1].0)
        .map(|w| w[1].1)
        .collect();
    duplicate_faces.sort_unstable();

    // Directed half-edges (a -> b) of every face, grouped by undirected edge.
    let mut half: Vec<(usize, usize, usize, usize)> = Vec::with_capacity(3 * f.len());
    for (fi, t) in f.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a != b {
                half.push((a.min(b), a.max(b), fi, usize::from(a > b)));
            }
        }
    }
    half.sort_unstable();

    let mut referenced = vec![false; n];
    for t in f {
        for &i in t {
            referenced[i] = true;
        }
    }
    let unreferenced_vertices: Vec<usize> = (0..n).filter(|&i| !referenced[i]).collect();

    // Corner union-find: corner (face, vertex) ids are 3*face + slot.
    let corner = |fi: usize, vtx: usize| -> usize {
        let t = f[fi];
        3 * fi + t.iter().position(|&x| x == vtx).unwrap_or(0)
    };
    let mut corners = Dsu::new(3 * f.len());
    let mut vdsu = Dsu::new(n);
    let mut bdsu = Dsu::new(n);
    let mut on_boundary = vec![false; n];
    let mut n_edges = 0;
    let mut boundary_edges = 0;
    let mut non_manifold_edges = Vec::new();
    let mut inconsistently_oriented_edges = 0;
    let mut i = 0;
    while i < half.len() {
        let (a, b) = (half[i].0, half[i].1);
        let mut j = i;
        while j < half.len() && half[j].0 == a && half[j].1 == b {
            j += 1;
        }
        let group = &half[i..j];
        n_edges += 1;
        vdsu.union(a, b);
        match group.len() {
            1 => {
                boundary_edges += 1;
                bdsu.union(a, b);
                on_boundary[a] = true;
                on_boundary[b] = true;
            }
            2 => {
                if group[0].3 == group[1].3 {
                    inconsistently_oriented_edges += 1;
                }
            }
            _ => non_manifold_edges.push([a, b]),
        }
        // Faces across a manifold edge belong to the same fan of both its
        // ends; across a non-manifold edge they do not.
        if group.len() == 2 {
            let (f0, f1) = (group[0].2, group[1].2);
            corners.union(corner(f0, a), corner(f1, a));
            corners.union(corner(f0, b), corner(f1, b));
        }
        i = j;
    }

    let mut fan_root: Vec<Option<usize>> = vec![None; n];
    let mut non_manifold_vertices = Vec::new();
    for (fi, t) in f.iter().enumerate() {
        for (slot, &vtx) in t.iter().enumerate() {
            let r = corners.find(3 * fi + slot);
            match fan_root[vtx] {
                None => fan_root[vtx] = Some(r),
                Some(r0) if r0 != r => non_manifold_vertices.push(vtx),
                _ => {}
            }
        }
    }
    non_manifold_vertices.sort_unstable();
    non_manifold_vertices.dedup();

    let mut comp_of = vec![usize::MAX; n];
    let mut connected_components = 0;
    for i in 0..n {
        if referenced[i] {
            let r = vdsu.find(i);
            if comp_of[r] == usize::MAX {
                comp_of[r] = connected_components;
                connected_components += 1;
            }
        }
    }
    let mut boundary_loops = 0;
    let mut seen = vec![false; n];
    for i in 0..n {
        if on_boundary[i] {
            let r = bdsu.find(i);
            if !seen[r] {
                seen[r] = true;
                boundary_loops += 1;
            }
        }
    }

    let n_ref = (n - unreferenced_vertices.len()) as i64;
    let euler_characteristic = n_ref - n_edges as i64 + f.len() as i64;
    let manifold = non_manifold_edges.is_empty() && non_manifold_vertices.is_empty();
    // Summing 2 - chi_c - b_c over components gives 2C - chi - B.
    let genus = manifold.then(|| {
        (2 * connected_components as i64 - euler_characteristic - boundary_loops as i64) / 2
    });

    MeshReport {
        n_vertices: n,
        n_faces: f.len(),
        n_edges,
        area,
        bounding_box: bbox,
        degenerate_faces,
        duplicate_faces,
        non_manifold_edges,
        non_manifold_vertices,
        boundary_edges,
        boundary_loops,
        connected_components,
        unreferenced_vertices,
        inconsistently_oriented_edges,
        euler_characteristic,
        genus,
    }
}
