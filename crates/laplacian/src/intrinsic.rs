//! The intrinsic Delaunay triangulation of a mesh's metric: edges are
//! flipped *intrinsically* (on edge lengths, the surface unchanged) until
//! every interior edge is Delaunay, i.e. the two angles opposite it sum to
//! at most π (cot α + cot β ≥ 0). Its cotangent Laplacian has non-negative
//! edge weights and is the robust replacement of the plain cotan Laplacian
//! on poorly shaped meshes (A. Bobenko, B. Springborn, "A discrete
//! Laplace–Beltrami operator for simplicial surfaces", DCG 38, 2007;
//! M. Fisher et al., "An algorithm for the construction of intrinsic
//! Delaunay triangulations with applications to digital geometry
//! processing", Computing 81, 2007).

use fmaps_mesh_io::TriMesh;

/// Faces (same vertex set, new connectivity) and their edge lengths (edge
/// k opposite corner k) of the intrinsic Delaunay triangulation, and the
/// number of flips.
pub(crate) fn intrinsic_delaunay(mesh: &TriMesh) -> (Vec<[usize; 3]>, Vec<[f64; 3]>, usize) {
    let v = mesh.vertices();
    let mut faces = mesh.faces().to_vec();
    let dist = |a: usize, b: usize| {
        let (p, q) = (v[a], v[b]);
        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
    };
    let mut len: Vec<[f64; 3]> = faces
        .iter()
        .map(|f| [dist(f[1], f[2]), dist(f[2], f[0]), dist(f[0], f[1])])
        .collect();
    // Only manifold edges whose two faces traverse them in opposite
    // directions (consistent orientation) can be flipped.
    let mut adj = mesh.face_adjacency().across;
    for f in 0..faces.len() {
        for k in 0..3 {
            if let Some((g, j)) = adj[f][k]
                && (g == f || faces[f][(k + 1) % 3] != faces[g][(j + 2) % 3])
            {
                adj[f][k] = None;
            }
        }
    }
    let mut stack: Vec<(usize, usize)> = (0..faces.len())
        .flat_map(|f| (0..3).map(move |k| (f, k)))
        .collect();
    let mut flips = 0;
    // Every flip strictly improves the triangulation, so this terminates;
    // the cap only guards against rounding cycles.
    let max_flips = 50 * faces.len() + 1000;
    while let Some((f, k)) = stack.pop() {
        let Some((g, j)) = adj[f][k] else { continue };
        let (lf, lg) = (len[f], len[g]);
        let cot_f = cot_at(lf, k);
        let cot_g = cot_at(lg, j);
        if !(cot_f + cot_g < -1e-12) || flips >= max_flips {
            continue;
        }
        // f = (a, b, c) with edge k = b -> c; g = (d, c, b) with edge j = c -> b.
        let (a, b, c) = (faces[f][k], faces[f][(k + 1) % 3], faces[f][(k + 2) % 3]);
        let d = faces[g][j];
        if a == d {
            continue;
        }
        let l_bc = lf[k];
        let l_ab = lf[(k + 2) % 3];
        let l_ca = lf[(k + 1) % 3];
        let l_cd = lg[(j + 2) % 3]; // g = (d, c, b): edge j+2 joins d and c
        let l_db = lg[(j + 1) % 3]; // edge j+1 joins b and d
        // Unfold: b at the origin, c on the x axis, a above, d below.
        let ax = (l_ab * l_ab - l_ca * l_ca + l_bc * l_bc) / (2.0 * l_bc);
        let ay = (l_ab * l_ab - ax * ax).max(0.0).sqrt();
        let dx = (l_db * l_db - l_cd * l_cd + l_bc * l_bc) / (2.0 * l_bc);
        let dy = -(l_db * l_db - dx * dx).max(0.0).sqrt();
        let l_ad = ((ax - dx).powi(2) + (ay - dy).powi(2)).sqrt();
        // Neighbours across the four outer edges before the flip.
        let n_ab = adj[f][(k + 2) % 3];
        let n_ca = adj[f][(k + 1) % 3];
        let n_bd = adj[g][(j + 1) % 3];
        let n_dc = adj[g][(j + 2) % 3];
        // New faces: f = (a, b, d), g = (a, d, c).
        faces[f] = [a, b, d];
        len[f] = [l_db, l_ad, l_ab];
        faces[g] = [a, d, c];
        len[g] = [l_cd, l_ca, l_ad];
        adj[f] = [n_bd, Some((g, 2)), n_ab];
        adj[g] = [n_dc, n_ca, Some((f, 1))];
        for (slot, nb) in [
            ((f, 0), n_bd),
            ((f, 2), n_ab),
            ((g, 0), n_dc),
            ((g, 1), n_ca),
        ] {
            if let Some((h, e)) = nb {
                adj[h][e] = Some(slot);
            }
            stack.push(slot);
        }
        flips += 1;
    }
    (faces, len, flips)
}

/// Cotangent of the angle at corner k of a triangle with edge lengths `l`.
fn cot_at(l: [f64; 3], k: usize) -> f64 {
    let a = crate::triangle_area(l);
    if a <= 0.0 {
        return 0.0;
    }
    let (x, y, z) = (l[k], l[(k + 1) % 3], l[(k + 2) % 3]);
    (y * y + z * z - x * x) / (4.0 * a)
}
