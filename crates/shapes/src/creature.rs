//! A built-in articulated test shape with known correspondence: an
//! asymmetric "creature" (a body with a head, two arms and two legs of
//! different lengths, and a tail) and its poses, bent at the joints.
//!
//! Every pose has the same vertices and triangles, so the ground truth
//! between two poses is known exactly; [`creature_pair`] renumbers the
//! target's vertices and moves it rigidly so that the truth is not the
//! identity and extrinsic coordinates do not give it away.

use crate::primitives::icosphere;
use crate::smoothstep;
use fmaps_mesh_io::TriMesh;
use fmaps_mesh_io::vec3::{dot, normalized, rotate};

/// One limb: a smooth protrusion of the unit sphere along `direction`.
#[derive(Debug, Clone, Copy)]
struct Limb {
    direction: [f64; 3],
    length: f64,
    /// Angular width (the protrusion is `exp(-(1 - cos θ) / width)`).
    width: f64,
    /// The axis a pose bends the limb about (at its joint).
    axis: [f64; 3],
}

/// Head, right arm, left arm, right leg, left leg, tail: deliberately of
/// different lengths and not mirror images, so the shape has no symmetry.
fn limbs() -> [Limb; 6] {
    let l = |d: [f64; 3], length: f64, width: f64, axis: [f64; 3]| Limb {
        direction: normalized(d),
        length,
        width,
        axis: normalized(axis),
    };
    [
        l([0.0, 1.0, 0.0], 0.7, 0.08, [1.0, 0.0, 0.0]),
        l([1.0, 0.25, 0.0], 1.4, 0.05, [0.0, 0.0, 1.0]),
        l([-1.0, 0.35, 0.1], 1.1, 0.06, [0.0, 0.0, 1.0]),
        l([0.35, -1.0, 0.0], 1.5, 0.06, [1.0, 0.0, 0.0]),
        l([-0.4, -1.0, 0.05], 1.25, 0.07, [1.0, 0.0, 0.0]),
        l([0.0, -0.2, -1.0], 0.9, 0.04, [1.0, 0.0, 0.0]),
    ]
}

/// A pose: the bend of each limb at its joint, in radians, in the order
/// head, right arm, left arm, right leg, left leg, tail.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose(pub [f64; 6]);

impl Pose {
    /// All limbs straight.
    pub fn rest() -> Pose {
        Pose([0.0; 6])
    }

    /// A walking pose: head nodding, arms and legs bent at different
    /// angles, tail curled.
    pub fn walking() -> Pose {
        Pose([0.35, -0.8, 0.6, 0.55, -0.4, 0.9])
    }
}

/// The creature in a pose, on an icosphere subdivided `subdivisions` times
/// (`10 * 4^s + 2` vertices; 4 gives 2562, 5 gives 10242). Closed,
/// genus 0, outward-oriented; vertex `i` is the same body point in every
/// pose. Bending rotates each limb beyond its joint rigidly and blends the
/// rotation over a short zone, so two poses are near-isometric (the
/// stretch is confined to the joints).
pub fn creature(subdivisions: u32, pose: &Pose) -> TriMesh {
    let (v, f) = icosphere(1.0, subdivisions).into_parts();
    let limbs = limbs();
    let v = v
        .into_iter()
        .map(|u| {
            // The rest shape: radial protrusions on a squashed body.
            let r = 1.0
                + limbs
                    .iter()
                    .map(|l| l.length * (-(1.0 - dot(u, l.direction)) / l.width).exp())
                    .sum::<f64>();
            let mut p = [0.9 * r * u[0], 1.1 * r * u[1], 0.7 * r * u[2]];
            for (l, &angle) in limbs.iter().zip(&pose.0) {
                if angle != 0.0 {
                    p = bend(p, u, l, angle);
                }
            }
            p
        })
        .collect();
    TriMesh::new(v, f).expect("the icosphere's triangles are valid")
}

/// Rotates the part of limb `l` beyond its joint by `angle`, blended over
/// a zone around the joint; `u` is the point's direction on the sphere
/// (which limb it belongs to).
fn bend(p: [f64; 3], u: [f64; 3], l: &Limb, angle: f64) -> [f64; 3] {
    // Only points in this limb's cone move.
    let gate = smoothstep((dot(u, l.direction) - 0.5) / 0.3);
    if gate == 0.0 {
        return p;
    }
    let d = l.direction;
    let joint = 0.9 + 0.35 * l.length;
    let t = dot(p, d);
    let half = 0.12;
    let s = gate * smoothstep((t - (joint - half)) / (2.0 * half));
    if s == 0.0 {
        return p;
    }
    let c = [joint * d[0], joint * d[1], joint * d[2]];
    let q = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
    let r = rotate(q, l.axis, s * angle);
    [r[0] + c[0], r[1] + c[1], r[2] + c[2]]
}

/// Two poses of the creature with the exact correspondence.
#[derive(Debug, Clone)]
pub struct MeshPair {
    /// The source shape.
    pub source: TriMesh,
    /// The target shape.
    pub target: TriMesh,
    /// The true map: `truth[i]` is the target vertex of source vertex `i`
    /// (0-based).
    pub truth: Vec<usize>,
}

/// The built-in test pair: the creature at rest (source) and walking
/// (target), the target's vertices renumbered by a fixed permutation and
/// the target rotated and translated.
pub fn creature_pair(subdivisions: u32) -> MeshPair {
    let source = creature(subdivisions, &Pose::rest());
    let (v, f) = creature(subdivisions, &Pose::walking()).into_parts();
    let n = v.len();
    // A fixed pseudo-random permutation (xorshift Fisher-Yates):
    // new index of old vertex i is truth[i].
    let mut order: Vec<usize> = (0..n).collect();
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    for i in (1..n).rev() {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        order.swap(i, (state % (i as u64 + 1)) as usize);
    }
    // order[new] = old.
    let mut truth = vec![0; n];
    for (new, &old) in order.iter().enumerate() {
        truth[old] = new;
    }
    let axis = normalized([0.3, 1.0, 0.2]);
    let vt: Vec<[f64; 3]> = order
        .iter()
        .map(|&old| {
            let r = rotate(v[old], axis, 0.7);
            [r[0] + 4.0, r[1] - 1.0, r[2] + 0.5]
        })
        .collect();
    let ft: Vec<[usize; 3]> = f.iter().map(|t| t.map(|x| truth[x])).collect();
    let target = TriMesh::new(vt, ft).expect("a renumbering of valid triangles");
    MeshPair {
        source,
        target,
        truth,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edge_lengths(m: &TriMesh) -> Vec<f64> {
        let v = m.vertices();
        m.faces()
            .iter()
            .flat_map(|f| [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])])
            .map(|(a, b)| {
                (0..3)
                    .map(|i| (v[a][i] - v[b][i]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .collect()
    }

    #[test]
    fn poses_are_closed_meshes_and_near_isometric() {
        let rest = creature(3, &Pose::rest());
        let walk = creature(3, &Pose::walking());
        assert_eq!(rest.n_vertices(), 642);
        let report = walk.validate();
        assert!(report.is_closed_manifold() && report.is_clean());
        // Same triangles, edge lengths change little: near-isometric.
        assert_eq!(rest.faces(), walk.faces());
        let (a, b) = (edge_lengths(&rest), edge_lengths(&walk));
        let rel: Vec<f64> = a.iter().zip(&b).map(|(x, y)| (y / x - 1.0).abs()).collect();
        let mean = rel.iter().sum::<f64>() / rel.len() as f64;
        assert!(mean < 0.05, "mean relative edge change {mean}");
        // ... but the pose really differs.
        let moved = rest
            .vertices()
            .iter()
            .zip(walk.vertices())
            .filter(|(p, q)| (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>() > 0.01)
            .count();
        assert!(moved > rest.n_vertices() / 10, "{moved} vertices moved");
        // Outward orientation: positive volume.
        let vol: f64 = walk
            .faces()
            .iter()
            .map(|f| {
                let [p, q, r] = f.map(|i| walk.vertices()[i]);
                dot(
                    p,
                    [
                        q[1] * r[2] - q[2] * r[1],
                        q[2] * r[0] - q[0] * r[2],
                        q[0] * r[1] - q[1] * r[0],
                    ],
                )
            })
            .sum::<f64>()
            / 6.0;
        assert!(vol > 1.0, "volume {vol}");
    }

    #[test]
    fn the_pair_truth_maps_source_vertices_to_their_renumbered_copies() {
        let pair = creature_pair(2);
        let n = pair.source.n_vertices();
        assert_eq!(pair.target.n_vertices(), n);
        let mut seen = vec![false; n];
        for &t in &pair.truth {
            assert!(!seen[t]);
            seen[t] = true;
        }
        assert!(
            pair.truth
                .iter()
                .enumerate()
                .filter(|(i, t)| i == *t)
                .count()
                < n / 10
        );
        // Through the truth, the target's triangles are the source's.
        let walk = creature(2, &Pose::walking());
        let mut mapped: Vec<[usize; 3]> = walk
            .faces()
            .iter()
            .map(|f| f.map(|x| pair.truth[x]))
            .collect();
        let mut target = pair.target.faces().to_vec();
        mapped.sort();
        target.sort();
        assert_eq!(mapped, target);
        // And the target is a rigid motion of the walking pose: distances kept.
        let (v, w) = (walk.vertices(), pair.target.vertices());
        let d =
            |p: [f64; 3], q: [f64; 3]| (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt();
        for (i, j) in [(0, 5), (10, 100), (3, 150)] {
            let (a, b) = (d(v[i], v[j]), d(w[pair.truth[i]], w[pair.truth[j]]));
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }
}
