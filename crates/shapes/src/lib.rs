//! Shapes generated in code, with known geometry and exact ground truth:
//! for tests, examples and benchmarks that must not depend on data files.
//!
//! - **Primitives** ([`icosphere`], [`torus`], [`grid`], [`subdivide`],
//!   [`disjoint_union`], [`translated`]): closed and open surfaces whose
//!   area, Euler characteristic and Laplace spectrum are known.
//! - **The creature** ([`creature()`], [`creature_pair`]): an asymmetric
//!   body (head, arms and legs of different lengths, a tail) and a bent,
//!   renumbered, rigidly moved copy with its vertex correspondence: the
//!   near-isometric demo pair.
//! - **Bodies** ([`body`]): a skinned body of any proportions and pose,
//!   remeshed independently for every shape, with every vertex's position
//!   on the template, so the ground truth of a pair is exact (the generated
//!   non-isometric benchmark).
//! - **Isosurfaces** ([`isosurface`]): marching tetrahedra on a grid and a
//!   relaxation of the vertices onto the implicit surface.
//!
//! ```
//! use fmaps_shapes::{creature_pair, icosphere};
//!
//! let sphere = icosphere(1.0, 2);
//! assert_eq!(sphere.n_vertices(), 10 * 4usize.pow(2) + 2);
//! assert_eq!(sphere.validate().genus, Some(0));
//!
//! // The target is a renumbered copy: `truth[i]` is the target vertex of
//! // source vertex `i`.
//! let pair = creature_pair(2);
//! assert_eq!(pair.truth.len(), pair.source.n_vertices());
//! assert_eq!(pair.source.n_vertices(), pair.target.n_vertices());
//! ```
//!
//! Meshes are [`fmaps_mesh_io::TriMesh`]; reading and writing them is
//! `fmaps-mesh-io`'s work, not this crate's.
//!
//! # Features
//!
//! None: the crate depends on `fmaps-mesh-io`, `fmaps-simd` (its seeded
//! generator), `kiddo` (3D nearest-vertex queries for the bodies' ground
//! truth) and `thiserror` only.
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod body;
mod creature;
mod error;
pub mod isosurface;
mod primitives;

pub use creature::{MeshPair, Pose, creature, creature_pair};
pub use error::{Error, Result};
pub use primitives::{disjoint_union, grid, icosphere, subdivide, torus, translated};

/// The cubic smoothstep `3x² − 2x³` of `x` clamped to [0, 1]: the blend of
/// the generated bodies' joints and the creature's bends.
pub(crate) fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}
