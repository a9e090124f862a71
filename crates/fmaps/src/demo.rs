//! The built-in pairs of `fmaps demo` (and of the Python package's
//! `demo_pairs`): generated in code with exact ground truth, so that a
//! fresh checkout can run and check the whole pipeline without data.

use crate::eval::GroundTruth;
use crate::mesh_io::TriMesh;
use crate::shapes::body::{Body, mirrored, nearest_vertices};
use crate::shapes::creature_pair;

/// One built-in pair: source `a`, target `b` and their ground truth
/// (`gt_a[i]` of A corresponds to `gt_b[i]` of B, and to `gt_b_sym[i]`
/// under the left/right symmetry, when the pair has one).
#[derive(Debug, Clone)]
pub struct DemoPair {
    /// A one-line description.
    pub title: String,
    /// Short name ("creature", "bodies").
    pub name: &'static str,
    /// Source shape A.
    pub a: TriMesh,
    /// Target shape B.
    pub b: TriMesh,
    /// Ground-truth vertices of A (0-based).
    pub gt_a: Vec<usize>,
    /// Their true images on B.
    pub gt_b: Vec<usize>,
    /// Their mirrored images on B (a symmetric shape), if any.
    pub gt_b_sym: Option<Vec<usize>>,
}

impl DemoPair {
    /// The ground truth as the evaluation takes it.
    pub fn truth(&self) -> Result<GroundTruth, crate::eval::Error> {
        GroundTruth::new(self.gt_a.clone(), self.gt_b.clone(), self.gt_b_sym.clone())
    }
}

/// The two pairs of `fmaps demo`: the asymmetric creature at rest against
/// a bent, renumbered, rigidly moved copy (near-isometric; the icosphere
/// subdivided `subdivisions` times: 4 = 2,562 vertices), and two
/// individuals of the generated body collection, walking and reaching
/// (`body_0_1 -> body_5_3` of `cargo xtask eval --collection
/// generated-noniso`: limbs, girths and torso of different proportions,
/// independent meshes, ground truth through the template).
pub fn demo_pairs(subdivisions: u32) -> Result<Vec<DemoPair>, String> {
    let pair = creature_pair(subdivisions);
    let n = pair.source.n_vertices();
    let creature = DemoPair {
        title: "creature, rest -> walking (near-isometric)".into(),
        name: "creature",
        gt_a: (0..n).collect(),
        gt_b: pair.truth.clone(),
        gt_b_sym: None,
        a: pair.source,
        b: pair.target,
    };
    let body = Body::template();
    let (sa, sb) = (
        body.collection_shape(0, 1).map_err(|e| e.to_string())?,
        body.collection_shape(5, 3).map_err(|e| e.to_string())?,
    );
    let points = body.truth_points().map_err(|e| e.to_string())?;
    let mirror: Vec<[f64; 3]> = points.iter().map(|&p| mirrored(p)).collect();
    let bodies = DemoPair {
        title: "two different bodies, walking -> reaching (non-isometric)".into(),
        name: "bodies",
        gt_a: nearest_vertices(&points, &sa.rest),
        gt_b: nearest_vertices(&points, &sb.rest),
        gt_b_sym: Some(nearest_vertices(&mirror, &sb.rest)),
        a: sa.mesh,
        b: sb.mesh,
    };
    Ok(vec![creature, bodies])
}
