//! Simple meshes generated in code, with known geometry: for tests,
//! examples and benchmarks that must not depend on data files.

use std::collections::HashMap;

use fmaps_mesh_io::TriMesh;

use crate::Result;

/// An icosphere of the given radius: the icosahedron subdivided 1-to-4
/// `subdivisions` times with new vertices projected onto the sphere.
/// `10 * 4^s + 2` vertices, `20 * 4^s` faces, outward-oriented, genus 0.
pub fn icosphere(radius: f64, subdivisions: u32) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let f: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let project = |p: &mut [f64; 3]| {
        let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        *p = [radius * p[0] / n, radius * p[1] / n, radius * p[2] / n];
    };
    v.iter_mut().for_each(project);
    let mut mesh = TriMesh::new(v, f).expect("the icosahedron is valid");
    for _ in 0..subdivisions {
        // Midpoints of vertices on the sphere, pushed back onto it.
        let (mut v, f) = subdivide(&mesh).into_parts();
        v.iter_mut().for_each(project);
        mesh = TriMesh::new(v, f).expect("icosphere construction is valid");
    }
    mesh
}

/// A torus around the z axis with tube radius `r` and centre-line radius
/// `big_r`, sampled `nu` times around the axis and `nv` times around the
/// tube (`nu * nv` vertices, genus 1). Needs `nu, nv >= 3`.
pub fn torus(big_r: f64, r: f64, nu: usize, nv: usize) -> TriMesh {
    assert!(
        nu >= 3 && nv >= 3,
        "torus needs at least 3 samples per direction"
    );
    let mut v = Vec::with_capacity(nu * nv);
    for i in 0..nu {
        let u = 2.0 * std::f64::consts::PI * i as f64 / nu as f64;
        for j in 0..nv {
            let w = 2.0 * std::f64::consts::PI * j as f64 / nv as f64;
            let rr = big_r + r * w.cos();
            v.push([rr * u.cos(), rr * u.sin(), r * w.sin()]);
        }
    }
    let id = |i: usize, j: usize| (i % nu) * nv + (j % nv);
    let mut f = Vec::with_capacity(2 * nu * nv);
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            f.push([a, b, c]);
            f.push([a, c, d]);
        }
    }
    TriMesh::new(v, f).expect("torus construction is valid")
}

/// A flat `width x height` rectangle in the z = 0 plane, with `nx x ny`
/// cells each split into two triangles along the same diagonal:
/// `(nx+1)(ny+1)` vertices, vertex `(i, j)` at index `j*(nx+1) + i` and
/// position `(i*width/nx, j*height/ny, 0)`. Needs `nx, ny >= 1`.
pub fn grid(width: f64, height: f64, nx: usize, ny: usize) -> TriMesh {
    assert!(
        nx >= 1 && ny >= 1,
        "grid needs at least one cell per direction"
    );
    let mut v = Vec::with_capacity((nx + 1) * (ny + 1));
    for j in 0..=ny {
        for i in 0..=nx {
            v.push([
                width * i as f64 / nx as f64,
                height * j as f64 / ny as f64,
                0.0,
            ]);
        }
    }
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    let mut f = Vec::with_capacity(2 * nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::new(v, f).expect("grid construction is valid")
}

/// The disjoint union of two meshes (vertices of `b` follow those of `a`).
pub fn disjoint_union(a: &TriMesh, b: &TriMesh) -> TriMesh {
    let mut v = a.vertices().to_vec();
    v.extend_from_slice(b.vertices());
    let off = a.n_vertices();
    let mut f = a.faces().to_vec();
    f.extend(b.faces().iter().map(|t| t.map(|i| i + off)));
    TriMesh::new(v, f).expect("union of valid meshes is valid")
}

/// Moves every vertex by `offset`. Errors when a coordinate leaves the
/// finite range (a non-finite or huge offset).
pub fn translated(mesh: &TriMesh, offset: [f64; 3]) -> Result<TriMesh> {
    let v = mesh
        .vertices()
        .iter()
        .map(|p| [p[0] + offset[0], p[1] + offset[1], p[2] + offset[2]])
        .collect();
    Ok(TriMesh::new(v, mesh.faces().to_vec())?)
}

/// One step of 1-to-4 midpoint subdivision: a new vertex at the midpoint of
/// every edge (appended after the original vertices, in order of first
/// appearance over the faces), each triangle split into four. The surface
/// (and its area) is unchanged; `V + E` vertices and `4F` faces.
pub fn subdivide(mesh: &TriMesh) -> TriMesh {
    let mut v = mesh.vertices().to_vec();
    let mut mid: HashMap<(usize, usize), usize> = HashMap::with_capacity(3 * mesh.n_faces() / 2);
    let mut f = Vec::with_capacity(4 * mesh.n_faces());
    for t in mesh.faces() {
        let mut m = [0; 3];
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            m[k] = *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let (pa, pb) = (v[a], v[b]);
                // Halves first: finite for any finite endpoints (the sum of
                // two coordinates near f64::MAX would overflow).
                v.push([
                    pa[0] / 2.0 + pb[0] / 2.0,
                    pa[1] / 2.0 + pb[1] / 2.0,
                    pa[2] / 2.0 + pb[2] / 2.0,
                ]);
                v.len() - 1
            });
        }
        f.push([t[0], m[0], m[2]]);
        f.push([t[1], m[1], m[0]]);
        f.push([t[2], m[2], m[1]]);
        f.push(m);
    }
    // Finite midpoints and indices below the new vertex count: the checks
    // of `TriMesh::new` (finite coordinates, indices in range, not empty)
    // hold by construction.
    TriMesh::new(v, f).expect("subdivision of a valid mesh is valid")
}
