//! Triangle meshes of implicit surfaces: marching tetrahedra on a regular
//! grid, then relaxation of the vertices along the surface.
//!
//! The grid's cubes are split into the six tetrahedra of the Kuhn
//! (Freudenthal) subdivision, which is conforming across cubes, so the
//! extracted surface is a closed 2-manifold wherever the zero set does not
//! leave the box (no ambiguous cases, unlike marching cubes). Marching
//! tetrahedra leaves slivers where the surface passes near a grid node;
//! [`relax`] spreads the vertices out (uniform Laplacian steps, each
//! followed by a Newton projection back onto the zero set), which removes
//! them without changing the surface.
//!
//! Different grid spacings or offsets give independent meshes of the same
//! surface (different vertex counts and connectivity), which is how the
//! generated benchmark shapes are remeshed.
//!
//! ```
//! use fmaps_shapes::isosurface::{marching_tetrahedra, relax, Grid};
//!
//! // The unit sphere.
//! let f = |p: [f64; 3]| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 1.0;
//! let grid = Grid { min: [-1.3; 3], max: [1.3; 3], spacing: 0.15, offset: [0.02, 0.05, 0.0] };
//! let mesh = relax(&marching_tetrahedra(&f, &grid)?, &f, 10)?;
//! let report = mesh.validate();
//! assert!(report.is_closed_manifold() && report.genus == Some(0));
//! assert!(mesh.vertices().iter().all(|p| f(*p).abs() < 1e-6));
//! # Ok::<(), fmaps_shapes::Error>(())
//! ```

use std::collections::HashMap;

use fmaps_mesh_io::TriMesh;
use fmaps_mesh_io::vec3::{cross, dot, sub};

use crate::{Error, Result};

/// A regular sampling grid: nodes at `min + offset + spacing * (i, j, k)`
/// up to `max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    /// The box's lower corner.
    pub min: [f64; 3],
    /// The box's upper corner.
    pub max: [f64; 3],
    /// Distance between neighbouring nodes.
    pub spacing: f64,
    /// Shift of the nodes inside the box (in `[0, spacing)` per axis):
    /// another offset gives another mesh of the same surface.
    pub offset: [f64; 3],
}

/// Most grid nodes a [`marching_tetrahedra`] call samples.
pub const MAX_GRID_NODES: usize = 64 << 20;

/// The surface `f = 0` (inside where `f < 0`), oriented outwards. The
/// function must be positive on the box's boundary (the surface must lie
/// inside the box), so that the result is closed.
pub fn marching_tetrahedra(f: &(dyn Fn([f64; 3]) -> f64 + Sync), grid: &Grid) -> Result<TriMesh> {
    let h = grid.spacing;
    let dims: Vec<usize> = (0..3)
        .map(|a| {
            let len = grid.max[a] - grid.min[a] - grid.offset[a];
            if h > 0.0 && len.is_finite() && len > h {
                Ok((len / h).floor() as usize + 1)
            } else {
                Err(Error::Parameter(format!(
                    "isosurface grid: spacing {h} does not fit the box on axis {a}"
                )))
            }
        })
        .collect::<Result<_>>()?;
    let (nx, ny, nz) = (dims[0], dims[1], dims[2]);
    if nx.saturating_mul(ny).saturating_mul(nz) > MAX_GRID_NODES {
        return Err(Error::Parameter(format!(
            "isosurface grid of {nx} x {ny} x {nz} nodes is over the limit of {MAX_GRID_NODES}"
        )));
    }
    let node = |i: usize, j: usize, k: usize| -> [f64; 3] {
        [
            grid.min[0] + grid.offset[0] + h * i as f64,
            grid.min[1] + grid.offset[1] + h * j as f64,
            grid.min[2] + grid.offset[2] + h * k as f64,
        ]
    };
    let id = |i: usize, j: usize, k: usize| (k * ny + j) * nx + i;
    let mut values = vec![0.0; nx * ny * nz];
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let v = f(node(i, j, k));
                if !v.is_finite() {
                    return Err(Error::Parameter(format!(
                        "isosurface: the function is {v} at {:?}",
                        node(i, j, k)
                    )));
                }
                // No node exactly on the surface: every crossing is strict.
                values[id(i, j, k)] = if v == 0.0 { 1e-300 } else { v };
            }
        }
    }
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let boundary =
                    i == 0 || j == 0 || k == 0 || i + 1 == nx || j + 1 == ny || k + 1 == nz;
                if boundary && values[id(i, j, k)] < 0.0 {
                    return Err(Error::Parameter(format!(
                        "isosurface: the surface leaves the box at {:?}",
                        node(i, j, k)
                    )));
                }
            }
        }
    }
    // The six tetrahedra of a cube: paths from corner 0 to corner 7 along
    // the axes in every order.
    const PERMS: [[usize; 3]; 6] = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    let mut faces: Vec<[usize; 3]> = Vec::new();
    let mut on_edge: HashMap<(usize, usize), usize> = HashMap::new();
    for k in 0..nz - 1 {
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                for perm in PERMS {
                    let mut c = [i, j, k];
                    let mut tet = [(0usize, [0.0; 3], 0.0); 4];
                    for (step, t) in tet.iter_mut().enumerate() {
                        if step > 0 {
                            c[perm[step - 1]] += 1;
                        }
                        let g = id(c[0], c[1], c[2]);
                        *t = (g, node(c[0], c[1], c[2]), values[g]);
                    }
                    march_tet(&tet, &mut vertices, &mut faces, &mut on_edge);
                }
            }
        }
    }
    if faces.is_empty() {
        return Err(Error::Parameter(
            "isosurface: the function has no zero crossing on the grid".into(),
        ));
    }
    Ok(TriMesh::new(vertices, faces)?)
}

/// One tetrahedron's piece of the surface: a triangle (one corner on the
/// other side) or a quad (two and two), oriented from inside to outside.
fn march_tet(
    tet: &[(usize, [f64; 3], f64); 4],
    vertices: &mut Vec<[f64; 3]>,
    faces: &mut Vec<[usize; 3]>,
    on_edge: &mut HashMap<(usize, usize), usize>,
) {
    let inside: Vec<usize> = (0..4).filter(|&c| tet[c].2 < 0.0).collect();
    let outside: Vec<usize> = (0..4).filter(|&c| tet[c].2 >= 0.0).collect();
    if inside.is_empty() || outside.is_empty() {
        return;
    }
    let mut crossing = |a: usize, b: usize| -> usize {
        let (ga, pa, fa) = tet[a];
        let (gb, pb, fb) = tet[b];
        let key = (ga.min(gb), ga.max(gb));
        *on_edge.entry(key).or_insert_with(|| {
            let t = fa / (fa - fb);
            vertices.push([
                pa[0] + t * (pb[0] - pa[0]),
                pa[1] + t * (pb[1] - pa[1]),
                pa[2] + t * (pb[2] - pa[2]),
            ]);
            vertices.len() - 1
        })
    };
    // Direction from the inside to the outside of this tetrahedron.
    let centroid = |cs: &[usize]| {
        let mut c = [0.0; 3];
        for &i in cs {
            for a in 0..3 {
                c[a] += tet[i].1[a] / cs.len() as f64;
            }
        }
        c
    };
    let (ci, co) = (centroid(&inside), centroid(&outside));
    let out_dir = [co[0] - ci[0], co[1] - ci[1], co[2] - ci[2]];
    let polygon: Vec<usize> = match (inside.len(), outside.len()) {
        (1, 3) => outside.iter().map(|&o| crossing(inside[0], o)).collect(),
        (3, 1) => inside.iter().map(|&i| crossing(i, outside[0])).collect(),
        _ => {
            // Two and two: the quad's corners in cyclic order.
            let (a, b) = (inside[0], inside[1]);
            let (c, d) = (outside[0], outside[1]);
            vec![
                crossing(a, c),
                crossing(a, d),
                crossing(b, d),
                crossing(b, c),
            ]
        }
    };
    let mut emit = |p: usize, q: usize, r: usize| {
        let (vp, vq, vr) = (vertices[p], vertices[q], vertices[r]);
        let n = cross(sub(vq, vp), sub(vr, vp));
        if dot(n, out_dir) >= 0.0 {
            faces.push([p, q, r]);
        } else {
            faces.push([p, r, q]);
        }
    };
    emit(polygon[0], polygon[1], polygon[2]);
    if polygon.len() == 4 {
        emit(polygon[0], polygon[2], polygon[3]);
    }
}

/// `iterations` rounds of: move every vertex halfway to the mean of its
/// neighbours, then project it back onto `f = 0` (Newton steps along the
/// numerical gradient). Equalises edge lengths and removes the slivers of
/// [`marching_tetrahedra`]; the connectivity is kept.
pub fn relax(
    mesh: &TriMesh,
    f: &(dyn Fn([f64; 3]) -> f64 + Sync),
    iterations: usize,
) -> Result<TriMesh> {
    let n = mesh.n_vertices();
    let mut neighbours: Vec<Vec<usize>> = vec![Vec::new(); n];
    for t in mesh.faces() {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            neighbours[a].push(b);
            neighbours[b].push(a);
        }
    }
    for nb in &mut neighbours {
        nb.sort_unstable();
        nb.dedup();
    }
    let mut v = mesh.vertices().to_vec();
    let scale = bbox_diagonal(&v);
    for _ in 0..iterations {
        let mut next = v.clone();
        for (i, nb) in neighbours.iter().enumerate() {
            if nb.is_empty() {
                continue;
            }
            let mut m = [0.0; 3];
            for &j in nb {
                for a in 0..3 {
                    m[a] += v[j][a] / nb.len() as f64;
                }
            }
            for a in 0..3 {
                next[i][a] = 0.5 * (v[i][a] + m[a]);
            }
            next[i] = project(f, next[i], scale);
        }
        v = next;
    }
    for p in &mut v {
        *p = project(f, *p, scale);
    }
    Ok(TriMesh::new(v, mesh.faces().to_vec())?)
}

/// Newton steps `p -= f(p) ∇f / |∇f|²` until |f| is negligible.
pub fn project(f: &(dyn Fn([f64; 3]) -> f64 + Sync), mut p: [f64; 3], scale: f64) -> [f64; 3] {
    let eps = 1e-7 * scale.max(f64::MIN_POSITIVE);
    for _ in 0..20 {
        let value = f(p);
        if value.abs() < 1e-12 * scale {
            break;
        }
        let mut g = [0.0; 3];
        for a in 0..3 {
            let (mut hi, mut lo) = (p, p);
            hi[a] += eps;
            lo[a] -= eps;
            g[a] = (f(hi) - f(lo)) / (2.0 * eps);
        }
        let g2 = dot(g, g);
        if g2 <= 0.0 || !g2.is_finite() {
            break;
        }
        let step = value / g2;
        for a in 0..3 {
            p[a] -= step * g[a];
        }
    }
    p
}

fn bbox_diagonal(v: &[[f64; 3]]) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in v {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn torus(p: [f64; 3]) -> f64 {
        let q = (p[0] * p[0] + p[1] * p[1]).sqrt() - 1.0;
        (q * q + p[2] * p[2]).sqrt() - 0.35
    }

    #[test]
    fn a_torus_is_a_closed_genus_one_surface_with_its_area() {
        let grid = Grid {
            min: [-1.6, -1.6, -0.6],
            max: [1.6, 1.6, 0.6],
            spacing: 0.06,
            offset: [0.013, 0.029, 0.007],
        };
        let raw = marching_tetrahedra(&torus, &grid).unwrap();
        let mesh = relax(&raw, &torus, 10).unwrap();
        let report = mesh.validate();
        assert!(report.is_closed_manifold(), "{report:?}");
        assert_eq!(report.genus, Some(1));
        // Area of the torus: 4 π² R r.
        let area: f64 = mesh
            .faces()
            .iter()
            .map(|t| {
                let [p, q, r] = t.map(|i| mesh.vertices()[i]);
                0.5 * dot(cross(sub(q, p), sub(r, p)), cross(sub(q, p), sub(r, p))).sqrt()
            })
            .sum();
        let exact = 4.0 * std::f64::consts::PI.powi(2) * 0.35;
        assert!((area / exact - 1.0).abs() < 0.01, "{area} vs {exact}");
        // Relaxation removes the slivers: smallest angle over 10 degrees.
        let min_angle = min_angle_degrees(&mesh);
        assert!(min_angle > 10.0, "smallest angle {min_angle}");
        assert!(min_angle_degrees(&raw) < 5.0, "the raw mesh has slivers");
        // Outward: positive volume, 2 π² R r².
        let vol: f64 = mesh
            .faces()
            .iter()
            .map(|t| {
                let [p, q, r] = t.map(|i| mesh.vertices()[i]);
                dot(p, cross(q, r)) / 6.0
            })
            .sum();
        let exact_vol = 2.0 * std::f64::consts::PI.powi(2) * 0.35 * 0.35;
        assert!((vol / exact_vol - 1.0).abs() < 0.02, "{vol} vs {exact_vol}");
    }

    fn min_angle_degrees(m: &TriMesh) -> f64 {
        let v = m.vertices();
        let mut worst = f64::INFINITY;
        for t in m.faces() {
            for c in 0..3 {
                let (p, q, r) = (v[t[c]], v[t[(c + 1) % 3]], v[t[(c + 2) % 3]]);
                let (a, b) = (sub(q, p), sub(r, p));
                let cos = dot(a, b) / (dot(a, a) * dot(b, b)).sqrt();
                worst = worst.min(cos.clamp(-1.0, 1.0).acos().to_degrees());
            }
        }
        worst
    }

    #[test]
    fn another_offset_gives_another_mesh_of_the_same_surface() {
        let f = |p: [f64; 3]| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 1.0;
        let g = |offset| Grid {
            min: [-1.3; 3],
            max: [1.3; 3],
            spacing: 0.1,
            offset,
        };
        let a = marching_tetrahedra(&f, &g([0.0; 3])).unwrap();
        let b = marching_tetrahedra(&f, &g([0.031, 0.047, 0.011])).unwrap();
        assert_ne!(a.n_vertices(), b.n_vertices());
        assert!(b.validate().is_closed_manifold());
    }

    #[test]
    fn bad_grids_are_errors() {
        let f = |p: [f64; 3]| p[0];
        let g = Grid {
            min: [-1.0; 3],
            max: [1.0; 3],
            spacing: 0.5,
            offset: [0.0; 3],
        };
        // The plane leaves the box.
        assert!(marching_tetrahedra(&f, &g).is_err());
        assert!(marching_tetrahedra(&|_| 1.0, &g).is_err());
        assert!(marching_tetrahedra(&|_| f64::NAN, &g).is_err());
        let tiny = Grid { spacing: 1e-9, ..g };
        assert!(marching_tetrahedra(&|_| 1.0, &tiny).is_err());
    }
}
