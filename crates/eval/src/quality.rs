//! Scores of a point map that need no ground truth: how much of the target
//! it reaches, how many triangles it collapses, how it distorts areas and
//! angles, and (given the reverse map) how far the round trip lands from
//! where it started. Cheap (one pass over faces and vertices) and meant to
//! compare maps of one pair (starts, hypotheses, refiners) without ground
//! truth; both shapes are measured at unit area, so the scores do not
//! depend on either mesh's units.

use fmaps_mesh_io::TriMesh;

use crate::{Error, Result};
use fmaps_mesh_io::vec3::{cross, dot, norm, sub};

/// The scores of [`map_quality`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct MapQuality {
    /// Fraction of the target's vertices that are the image of some source
    /// vertex (1 for a bijection between equal vertex counts).
    pub coverage: f64,
    /// Fraction of the target's area (lumped vertex areas) at the image
    /// vertices.
    pub area_coverage: f64,
    /// Fraction of the source's faces whose three vertices go to fewer than
    /// three distinct target vertices.
    pub collapsed_faces: f64,
    /// Area-weighted mean of `|ln(image area / face area)|` over the faces
    /// that are not collapsed, both shapes at unit area (0: every face keeps
    /// its share of the area).
    pub area_distortion: f64,
    /// Area-weighted mean of the MIPS energy minus one,
    /// `(σ₁² + σ₂²) / (2 σ₁ σ₂) − 1` of each face's affine map to its image
    /// (0: conformal; faces collapsed or with a degenerate image excluded:
    /// an image whose area is below 1e-12 times its longest edge
    /// squared is three collinear vertices up to rounding, such as an edge's
    /// endpoints and midpoint on a subdivided mesh, whose MIPS energy would
    /// be rounding noise of order 1e11).
    pub conformal_distortion: f64,
    /// With the reverse map: the mean distance from each source vertex to
    /// where `T_BA(T_AB(x))` lands, over √(source area) (0: the maps are
    /// inverse to each other). `None` without the reverse map.
    pub round_trip: Option<f64>,
}

/// Image triangles with an area below this fraction of their longest edge
/// squared are degenerate for [`MapQuality::conformal_distortion`] (rounding
/// leaves ~1e-16 for collinear vertices; a real triangle that thin would
/// have a MIPS energy of ~1e12).
pub(crate) const COLLINEAR: f64 = 1e-12;

/// Scores the map `t_ab` (for every vertex of `a`, a vertex of `b`) and,
/// given `t_ba`, the pair of maps (see [`MapQuality`]).
///
/// Errors: maps of the wrong length or with an index out of range.
pub fn map_quality(
    t_ab: &[usize],
    a: &TriMesh,
    b: &TriMesh,
    t_ba: Option<&[usize]>,
) -> Result<MapQuality> {
    check_map("T_AB", t_ab, a.n_vertices(), b.n_vertices())?;
    if let Some(t) = t_ba {
        check_map("T_BA", t, b.n_vertices(), a.n_vertices())?;
    }
    let (va, vb) = (a.vertices(), b.vertices());
    let area_a = a.area();
    let area_b = b.area();
    // Lumped vertex areas of B.
    let mut lumped = vec![0.0; b.n_vertices()];
    for (f, ar) in b.faces().iter().zip(b.face_areas()) {
        for &v in f {
            lumped[v] += ar / 3.0;
        }
    }
    let mut hit = vec![false; b.n_vertices()];
    for &t in t_ab {
        hit[t] = true;
    }
    let coverage = hit.iter().filter(|&&h| h).count() as f64 / b.n_vertices() as f64;
    let area_coverage = if area_b > 0.0 {
        hit.iter()
            .zip(&lumped)
            .filter(|(h, _)| **h)
            .map(|(_, a)| a)
            .sum::<f64>()
            / area_b
    } else {
        0.0
    };
    let (mut collapsed, mut w_area, mut sum_area, mut w_conf, mut sum_conf) =
        (0usize, 0.0, 0.0, 0.0, 0.0);
    for (f, ar) in a.faces().iter().zip(a.face_areas()) {
        let g = [t_ab[f[0]], t_ab[f[1]], t_ab[f[2]]];
        if g[0] == g[1] || g[1] == g[2] || g[0] == g[2] {
            collapsed += 1;
            continue;
        }
        if ar <= 0.0 || area_a <= 0.0 || area_b <= 0.0 {
            continue;
        }
        let p = f.map(|v| va[v]);
        let q = g.map(|v| vb[v]);
        let image = 0.5 * norm(cross(sub(q[1], q[0]), sub(q[2], q[0])));
        if image <= 0.0 {
            continue;
        }
        let (ra, rb) = (ar / area_a, image / area_b);
        sum_area += ar * (rb / ra).ln().abs();
        w_area += ar;
        // The affine map in each triangle's own orthonormal frame, both at
        // unit total area: J = F E⁻¹ with E, F the 2 x 2 edge matrices.
        let (e, fm) = (frame(p, area_a.sqrt()), frame(q, area_b.sqrt()));
        let det_e = e[0][0] * e[1][1] - e[0][1] * e[1][0];
        if det_e == 0.0 {
            continue;
        }
        let inv = [
            [e[1][1] / det_e, -e[0][1] / det_e],
            [-e[1][0] / det_e, e[0][0] / det_e],
        ];
        let mut j = [[0.0; 2]; 2];
        for (r, row) in j.iter_mut().enumerate() {
            for (c, x) in row.iter_mut().enumerate() {
                *x = fm[r][0] * inv[0][c] + fm[r][1] * inv[1][c];
            }
        }
        let det = (j[0][0] * j[1][1] - j[0][1] * j[1][0]).abs();
        let longest2 = [sub(q[1], q[0]), sub(q[2], q[1]), sub(q[0], q[2])]
            .map(|e| dot(e, e))
            .into_iter()
            .fold(0.0, f64::max);
        if det > 0.0 && image > COLLINEAR * longest2 {
            let fro: f64 = j.iter().flatten().map(|x| x * x).sum();
            sum_conf += ar * (fro / (2.0 * det) - 1.0);
            w_conf += ar;
        }
    }
    let round_trip = t_ba.map(|t_ba| {
        let scale = area_a.sqrt().max(f64::MIN_POSITIVE);
        t_ab.iter()
            .enumerate()
            .map(|(i, &t)| norm(sub(va[t_ba[t]], va[i])) / scale)
            .sum::<f64>()
            / t_ab.len() as f64
    });
    let mean = |s: f64, w: f64| if w > 0.0 { s / w } else { 0.0 };
    Ok(MapQuality {
        coverage,
        area_coverage,
        collapsed_faces: collapsed as f64 / a.n_faces() as f64,
        area_distortion: mean(sum_area, w_area),
        conformal_distortion: mean(sum_conf, w_conf),
        round_trip,
    })
}

pub(crate) fn check_map(what: &str, t: &[usize], n_from: usize, n_to: usize) -> Result<()> {
    if t.len() != n_from {
        return Err(Error::SizeMismatch {
            what: format!("{what} (one target per vertex)"),
            found: t.len(),
            expected: n_from,
        });
    }
    if let Some(&index) = t.iter().find(|&&x| x >= n_to) {
        return Err(Error::OutOfRange {
            what: what.to_string(),
            index,
            size: n_to,
        });
    }
    Ok(())
}

/// The two edges from corner 0 of triangle `p` in an orthonormal frame of
/// its plane, divided by `scale`: columns are the edges.
fn frame(p: [[f64; 3]; 3], scale: f64) -> [[f64; 2]; 2] {
    let e1 = sub(p[1], p[0]);
    let e2 = sub(p[2], p[0]);
    let l1 = norm(e1);
    if l1 == 0.0 {
        return [[0.0; 2]; 2];
    }
    let u = [e1[0] / l1, e1[1] / l1, e1[2] / l1];
    let x2 = dot(e2, u);
    let y2 = norm(sub(e2, [u[0] * x2, u[1] * x2, u[2] * x2]));
    [[l1 / scale, x2 / scale], [0.0, y2 / scale]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use fmaps_shapes::{grid, icosphere};

    fn stretched(m: &TriMesh, s: [f64; 3]) -> TriMesh {
        let (v, f) = m.clone().into_parts();
        TriMesh::new(
            v.into_iter()
                .map(|p| [p[0] * s[0], p[1] * s[1], p[2] * s[2]])
                .collect(),
            f,
        )
        .unwrap()
    }

    #[test]
    fn identity_scaling_and_stretch_have_their_closed_forms() {
        let g = grid(1.0, 1.0, 6, 6);
        let n = g.n_vertices();
        let id: Vec<usize> = (0..n).collect();
        let q = map_quality(&id, &g, &g, Some(&id)).unwrap();
        assert_eq!((q.coverage, q.collapsed_faces), (1.0, 0.0));
        assert!((q.area_coverage - 1.0).abs() < 1e-12);
        assert!(q.area_distortion.abs() < 1e-12 && q.conformal_distortion.abs() < 1e-12);
        assert_eq!(q.round_trip, Some(0.0));
        // A uniformly scaled copy: nothing changes at unit area.
        let big = stretched(&g, [1000.0, 1000.0, 1000.0]);
        let q = map_quality(&id, &g, &big, None).unwrap();
        assert!(q.area_distortion.abs() < 1e-12 && q.conformal_distortion.abs() < 1e-12);
        // Stretched x2 along x: areas keep their shares (ln 1 = 0), the
        // angles do not: J = diag(2, 1)/√2, MIPS (4 + 1)/(2·2) = 1.25.
        let wide = stretched(&g, [2.0, 1.0, 1.0]);
        let q = map_quality(&id, &g, &wide, None).unwrap();
        assert!(q.area_distortion.abs() < 1e-12, "{q:?}");
        assert!((q.conformal_distortion - 0.25).abs() < 1e-12, "{q:?}");
    }

    /// A face mapped onto three collinear vertices (the third placed a third
    /// of the way along the other two, so rounding leaves a tiny nonzero
    /// area) is a degenerate image: no conformal term, where its MIPS
    /// energy would be ~1e12 or more.
    #[test]
    fn collinear_images_are_degenerate() {
        let a = TriMesh::new(
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            vec![[0, 1, 2]],
        )
        .unwrap();
        let (q0, q1) = ([0.1, 0.7, 0.3], [1.3, 0.2, 0.9]);
        let q2 = [0, 1, 2].map(|i| q0[i] + (q1[i] - q0[i]) / 3.0);
        let image = 0.5 * norm(cross(sub(q1, q0), sub(q2, q0)));
        assert!(
            image > 0.0 && image < 1e-15,
            "the test needs rounding residue: {image}"
        );
        let b = TriMesh::new(
            vec![q0, q1, q2, [0.5, 1.5, -0.2]],
            vec![[0, 1, 3], [1, 2, 3]],
        )
        .unwrap();
        let q = map_quality(&[0, 1, 2], &a, &b, None).unwrap();
        assert_eq!(q.collapsed_faces, 0.0);
        assert_eq!(q.conformal_distortion, 0.0, "{q:?}");
        // A genuine image (the fourth vertex instead) still counts.
        let q = map_quality(&[0, 1, 3], &a, &b, None).unwrap();
        assert!(
            q.conformal_distortion > 0.0 && q.conformal_distortion < 10.0,
            "{q:?}"
        );
    }

    #[test]
    fn a_constant_map_collapses_everything() {
        let s = icosphere(1.0, 2);
        let n = s.n_vertices();
        let q = map_quality(&vec![3; n], &s, &s, None).unwrap();
        assert_eq!(q.coverage, 1.0 / n as f64);
        assert_eq!(q.collapsed_faces, 1.0);
        assert!(q.area_coverage > 0.0 && q.area_coverage < 0.01);
        // Round trip through a vertex: the mean distance to vertex 3.
        let back = vec![3; n];
        let q = map_quality(&vec![0; n], &s, &s, Some(&back)).unwrap();
        assert!(q.round_trip.unwrap() > 0.0);
        assert!(map_quality(&vec![0; n - 1], &s, &s, None).is_err());
        assert!(map_quality(&vec![n; n], &s, &s, None).is_err());
    }
}
