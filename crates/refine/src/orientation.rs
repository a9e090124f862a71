//! Does a point map preserve orientation? A measure that needs no ground
//! truth, used to tell a correspondence from its mirror image.
//!
//! Intrinsically symmetric shapes (people, animals) have two near-isometric
//! maps to each other: the right one and the one composed with the
//! left/right symmetry. Descriptors such as WKS cannot tell them apart, and
//! the spectral refiners converge to whichever they start near. But a
//! reflection reverses orientation: a triangle `(i, j, k)` of the source,
//! carried to `(T(i), T(j), T(k))` on the target, turns the wrong way
//! round relative to the target's outward normals.

use fmaps_mesh_io::vec3::{cross, dot, sub};

use crate::{Error, Result};

/// Area-weighted orientation agreement of the point map `map` (one target
/// vertex per source vertex) between two meshes with consistently oriented
/// triangles, in `[-1, 1]`.
///
/// Each source triangle counts with its area and the sign of
/// `n_T · (p_j − p_i) × (p_k − p_i)`, where `p` are the target positions of
/// its three image vertices and `n_T` the sum of the target's
/// (area-weighted) vertex normals there; triangles whose image is
/// degenerate (two corners on the same vertex, or a zero product) count
/// zero. An orientation-preserving map scores near 1, its mirror image
/// near −1, and noise near 0.
///
/// ```
/// use fmaps_refine::orientation_score;
/// let mesh = fmaps_shapes::icosphere(1.0, 2);
/// let (v, f) = (mesh.vertices(), mesh.faces());
/// let identity: Vec<usize> = (0..v.len()).collect();
/// assert!(orientation_score(&identity, v, f, v, f)? > 0.999);
/// // The mirror x -> -x as a vertex map of the sphere onto itself.
/// let mirror: Vec<usize> = v
///     .iter()
///     .map(|p| {
///         let q = [-p[0], p[1], p[2]];
///         (0..v.len())
///             .min_by(|&a, &b| dist(&v[a], &q).total_cmp(&dist(&v[b], &q)))
///             .unwrap()
///     })
///     .collect();
/// # fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 { (0..3).map(|i| (a[i] - b[i]).powi(2)).sum() }
/// assert!(orientation_score(&mirror, v, f, v, f)? < -0.999);
/// # Ok::<(), fmaps_refine::Error>(())
/// ```
pub fn orientation_score(
    map: &[usize],
    source_vertices: &[[f64; 3]],
    source_faces: &[[usize; 3]],
    target_vertices: &[[f64; 3]],
    target_faces: &[[usize; 3]],
) -> Result<f64> {
    let nt = target_vertices.len();
    check_map(
        "orientation score",
        map,
        source_vertices,
        source_faces,
        target_vertices,
        target_faces,
    )?;
    let mut normals = vec![[0.0f64; 3]; nt];
    for f in target_faces {
        let n = cross_at(target_vertices, f[0], f[1], f[2]);
        for &v in f {
            for d in 0..3 {
                normals[v][d] += n[d];
            }
        }
    }
    let (mut signed, mut total) = (0.0, 0.0);
    for f in source_faces {
        let n = cross_at(source_vertices, f[0], f[1], f[2]);
        let area = dot(n, n).sqrt();
        total += area;
        let (i, j, k) = (map[f[0]], map[f[1]], map[f[2]]);
        if i == j || j == k || i == k {
            continue;
        }
        let m = cross_at(target_vertices, i, j, k);
        let mut r = [0.0; 3];
        for d in 0..3 {
            r[d] = normals[i][d] + normals[j][d] + normals[k][d];
        }
        let s = dot(m, r);
        if s > 0.0 {
            signed += area;
        } else if s < 0.0 {
            signed -= area;
        }
    }
    Ok(if total > 0.0 { signed / total } else { 0.0 })
}

/// Area-weighted mean of `|ln(image area / face area)|` over the source
/// triangles whose image is a proper triangle (three distinct vertices, non-zero
/// area), both meshes scaled to unit area: 0 when every triangle keeps its
/// share of the surface. A map aligned the wrong way round (a body matched
/// facing backwards, a limb onto the wrong limb) stretches and squeezes
/// the surface far more than the right one, whichever way its triangles
/// turn; [`orientation_score`] sees the turning, this the stretching.
///
/// ```
/// use fmaps_refine::area_distortion;
/// let mesh = fmaps_shapes::icosphere(1.0, 2);
/// let (v, f) = (mesh.vertices(), mesh.faces());
/// let identity: Vec<usize> = (0..v.len()).collect();
/// assert!(area_distortion(&identity, v, f, v, f)?.abs() < 1e-12);
/// // Scaling the target changes nothing: both are measured at unit area.
/// let big: Vec<[f64; 3]> = v.iter().map(|p| p.map(|c| 3.0 * c)).collect();
/// assert!(area_distortion(&identity, v, f, &big, f)?.abs() < 1e-12);
/// # Ok::<(), fmaps_refine::Error>(())
/// ```
pub fn area_distortion(
    map: &[usize],
    source_vertices: &[[f64; 3]],
    source_faces: &[[usize; 3]],
    target_vertices: &[[f64; 3]],
    target_faces: &[[usize; 3]],
) -> Result<f64> {
    check_map(
        "area distortion",
        map,
        source_vertices,
        source_faces,
        target_vertices,
        target_faces,
    )?;
    let area = |v: &[[f64; 3]], f: &[usize; 3]| {
        let n = cross_at(v, f[0], f[1], f[2]);
        0.5 * dot(n, n).sqrt()
    };
    let total_s: f64 = source_faces.iter().map(|f| area(source_vertices, f)).sum();
    let total_t: f64 = target_faces.iter().map(|f| area(target_vertices, f)).sum();
    if total_s <= 0.0 || total_t <= 0.0 {
        return Ok(0.0);
    }
    let (mut sum, mut weight) = (0.0, 0.0);
    for f in source_faces {
        let g = [map[f[0]], map[f[1]], map[f[2]]];
        if g[0] == g[1] || g[1] == g[2] || g[0] == g[2] {
            continue;
        }
        let (a, b) = (area(source_vertices, f), area(target_vertices, &g));
        if a > 0.0 && b > 0.0 {
            sum += a * ((b / total_t) / (a / total_s)).ln().abs();
            weight += a;
        }
    }
    Ok(if weight > 0.0 { sum / weight } else { 0.0 })
}

fn check_map(
    what: &str,
    map: &[usize],
    source_vertices: &[[f64; 3]],
    source_faces: &[[usize; 3]],
    target_vertices: &[[f64; 3]],
    target_faces: &[[usize; 3]],
) -> Result<()> {
    if map.len() != source_vertices.len() {
        return Err(Error::InvalidParameter(format!(
            "{what}: the point map has {} entries for {} source vertices",
            map.len(),
            source_vertices.len()
        )));
    }
    let nt = target_vertices.len();
    if let Some((at, &index)) = map.iter().enumerate().find(|(_, t)| **t >= nt) {
        return Err(Error::InvalidParameter(format!(
            "{what}: source vertex {at} maps to vertex {index}, but the target has {nt}"
        )));
    }
    for (name, faces, n) in [
        ("source", source_faces, source_vertices.len()),
        ("target", target_faces, nt),
    ] {
        if let Some((at, f)) = faces
            .iter()
            .enumerate()
            .find(|(_, f)| f.iter().any(|&v| v >= n))
        {
            return Err(Error::InvalidParameter(format!(
                "{what}: {name} face {at} {f:?} refers to a vertex beyond {n}"
            )));
        }
    }
    Ok(())
}

fn cross_at(v: &[[f64; 3]], i: usize, j: usize, k: usize) -> [f64; 3] {
    cross(sub(v[j], v[i]), sub(v[k], v[i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 x 4 grid of unit squares in the plane z = 0, normals +z.
    fn grid() -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
        let m = 5;
        let v = (0..m * m)
            .map(|i| [(i % m) as f64, (i / m) as f64, 0.0])
            .collect();
        let mut f = Vec::new();
        for y in 0..m - 1 {
            for x in 0..m - 1 {
                let i = y * m + x;
                f.push([i, i + 1, i + m + 1]);
                f.push([i, i + m + 1, i + m]);
            }
        }
        (v, f)
    }

    #[test]
    fn rotations_preserve_reflections_reverse_collapses_count_zero() {
        let (v, f) = grid();
        let m = 5;
        let rot: Vec<usize> = (0..m * m).map(|i| (m - 1 - i % m) * m + i / m).collect();
        let mirror: Vec<usize> = (0..m * m).map(|i| (i / m) * m + (m - 1 - i % m)).collect();
        assert_eq!(orientation_score(&rot, &v, &f, &v, &f).unwrap(), 1.0);
        assert_eq!(orientation_score(&mirror, &v, &f, &v, &f).unwrap(), -1.0);
        assert_eq!(
            orientation_score(&vec![3; m * m], &v, &f, &v, &f).unwrap(),
            0.0
        );
        // Columns x <= 2 fixed, x >= 3 mirrored: the squares in [0, 2] keep
        // their orientation, [2, 3] folds over and [3, 4] is mirrored, so
        // the two halves cancel exactly.
        let half: Vec<usize> = (0..m * m)
            .map(|i| if i % m <= 2 { i } else { mirror[i] })
            .collect();
        assert_eq!(orientation_score(&half, &v, &f, &v, &f).unwrap(), 0.0);
    }

    #[test]
    fn area_distortion_has_its_closed_form() {
        let (v, f) = grid();
        let id: Vec<usize> = (0..v.len()).collect();
        // A uniform stretch keeps every triangle's share of the area.
        let wide: Vec<[f64; 3]> = v.iter().map(|p| [3.0 * p[0], p[1], 0.0]).collect();
        assert!(area_distortion(&id, &v, &f, &wide, &f).unwrap().abs() < 1e-12);
        // Columns x >= 2 stretched 3x: the target's area is 8 + 24 = 32
        // against 16, so the left half keeps 1/2 of its share and the right
        // half gets 3/2: (ln 2 + ln 1.5) / 2 = ln(3) / 2.
        let half: Vec<[f64; 3]> = v
            .iter()
            .map(|p| {
                [
                    if p[0] <= 2.0 {
                        p[0]
                    } else {
                        2.0 + 3.0 * (p[0] - 2.0)
                    },
                    p[1],
                    0.0,
                ]
            })
            .collect();
        let d = area_distortion(&id, &v, &f, &half, &f).unwrap();
        assert!((d - 3f64.ln() / 2.0).abs() < 1e-12, "{d}");
        // Collapsed triangles do not count; a map onto one vertex scores 0.
        assert_eq!(area_distortion(&[3; 25], &v, &f, &v, &f).unwrap(), 0.0);
        let e = area_distortion(&[0; 3], &v, &f, &v, &f).unwrap_err();
        assert!(
            e.to_string()
                .contains("area distortion: the point map has 3"),
            "{e}"
        );
    }

    #[test]
    fn bad_input_is_an_error_naming_the_entry() {
        let (v, f) = grid();
        let e = orientation_score(&[0; 3], &v, &f, &v, &f).unwrap_err();
        assert!(e.to_string().contains("3 entries for 25"), "{e}");
        let mut t: Vec<usize> = (0..25).collect();
        t[7] = 25;
        let e = orientation_score(&t, &v, &f, &v, &f).unwrap_err();
        assert!(e.to_string().contains("vertex 7 maps to vertex 25"), "{e}");
        let mut g = f.clone();
        g[2] = [0, 1, 99];
        let e = orientation_score(&(0..25).collect::<Vec<_>>(), &v, &g, &v, &f).unwrap_err();
        assert!(e.to_string().contains("source face 2"), "{e}");
    }
}
