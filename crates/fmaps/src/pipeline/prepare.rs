//! The per-shape stages: unit-area scaling ([`TriMesh::to_unit_area`]),
//! the eigenbasis ([`crate::spectrum`]) and the descriptors
//! ([`descriptors::descriptor_matrix`]).

use std::time::Instant;

use fmaps_eigensolve::SpectralBasis;
use fmaps_mesh_io::TriMesh;
use fmaps_solve::ShapeData;
use nalgebra::DMatrix;

use std::sync::Arc;

use super::error::MatchError;
use super::features::{LearnedShape, learned_shape};
use super::params::{Features, MatchParams};
use crate::{descriptors, refine, spectrum};

/// One shape after the per-shape stages: reusable across pairs.
#[derive(Debug, Clone)]
pub struct PreparedShape {
    /// Vertex positions (for sub-sampled refinement and the orientation
    /// score), after the area normalization when it is on.
    pub vertices: Vec<[f64; 3]>,
    /// Oriented triangles (for the orientation operators).
    pub faces: Vec<[usize; 3]>,
    /// The eigenbasis (`k_process` pairs) of the (normalized) shape.
    pub basis: SpectralBasis,
    /// Total area of the (normalized) shape: the sum of the lumped mass,
    /// 1 to rounding with [`MatchParams::area_normalize`].
    pub area: f64,
    /// The input mesh's area, in its own units squared.
    pub input_area: f64,
    /// The factor every coordinate was multiplied by (`1/√input_area`
    /// with the area normalization, else 1).
    pub scale: f64,
    /// Seconds for the Laplacian and the eigenbasis (and the learned
    /// features, when asked).
    pub seconds: f64,
    /// The learned features' state, when prepared for
    /// [`Features::Learned`] (else computed by the pipeline when a learned
    /// match needs it).
    pub learned: Option<Arc<LearnedShape>>,
}

/// Laplacian and eigenbasis of one shape, after scaling it to unit area
/// when [`MatchParams::area_normalize`] is on (the default), so that
/// nothing downstream depends on the mesh's units.
pub fn prepare(mesh: &TriMesh, params: &MatchParams) -> Result<PreparedShape, MatchError> {
    prepare_with_basis(mesh, params, None)
}

/// [`prepare`], with the eigenbasis taken from `cached` when given (a
/// basis [`prepare`] computed earlier for the same mesh and parameters,
/// e.g. from `fmaps batch`'s cache): the same normalization, no
/// eigensolve. A cached basis with another vertex count or fewer than
/// `k_process` pairs is an error.
pub fn prepare_with_basis(
    mesh: &TriMesh,
    params: &MatchParams,
    cached: Option<SpectralBasis>,
) -> Result<PreparedShape, MatchError> {
    params.check()?;
    let t = Instant::now();
    let input_area = mesh.area();
    let (normalized, scale) = if params.area_normalize {
        let (m, scale) = mesh.to_unit_area().map_err(|e| MatchError::InvalidShape {
            shape: "input",
            message: match e {
                fmaps_mesh_io::Error::InvalidMesh { problem, .. } => problem.to_string(),
                e => e.to_string(),
            },
        })?;
        (Some(m), scale)
    } else {
        (None, 1.0)
    };
    let mesh = normalized.as_ref().unwrap_or(mesh);
    let basis = match cached {
        Some(b) => {
            if b.eigenvectors.nrows() != mesh.n_vertices() || b.eigenvalues.len() < params.k_process
            {
                return Err(MatchError::InvalidShape {
                    shape: "input",
                    message: format!(
                        "the cached eigenbasis has {} rows and {} pairs, the mesh {} vertices and k_process = {}",
                        b.eigenvectors.nrows(),
                        b.eigenvalues.len(),
                        mesh.n_vertices(),
                        params.k_process
                    ),
                });
            }
            b
        }
        None => {
            spectrum(mesh, params.k_process, &params.spectrum)
                .map_err(|source| MatchError::Spectrum {
                    shape: "input",
                    source,
                })?
                .basis
        }
    };
    let area = basis.mass.iter().sum();
    let learned = match &params.features {
        Features::Learned(l) => Some(Arc::new(learned_shape(
            mesh,
            &basis,
            params.spectrum.mass,
            l,
        )?)),
        Features::Descriptors => None,
    };
    Ok(PreparedShape {
        vertices: mesh.vertices().to_vec(),
        faces: mesh.faces().to_vec(),
        basis,
        area,
        input_area,
        scale,
        seconds: t.elapsed().as_secs_f64(),
        learned,
    })
}

/// The descriptors (n x p, unit L² columns) of a prepared shape
/// ([`descriptors::descriptor_matrix`] on its first
/// [`eigenpairs`](super::DescriptorOptions::eigenpairs)).
pub fn shape_descriptors(
    shape: &PreparedShape,
    landmarks: &[usize],
    params: &MatchParams,
) -> Result<DMatrix<f64>, MatchError> {
    let basis = shape.basis.truncate(params.descriptors.eigenpairs);
    Ok(descriptors::descriptor_matrix(
        &basis.eigenvalues,
        &basis.eigenvectors,
        &basis.mass,
        landmarks,
        &params.descriptors.params(),
    )?)
}

impl PreparedShape {
    /// Its vertices and triangles, for refiners that work on the meshes.
    pub fn geometry(&self) -> refine::ShapeGeometry<'_> {
        refine::ShapeGeometry {
            vertices: &self.vertices,
            faces: &self.faces,
        }
    }
}

/// The arrays of a prepared shape the energy needs (its basis truncated
/// to the map's size).
pub(super) fn shape_data<'a>(
    shape: &'a PreparedShape,
    truncated: &'a SpectralBasis,
) -> ShapeData<'a> {
    ShapeData {
        faces: &shape.faces,
        phi: &truncated.eigenvectors,
        evals: &truncated.eigenvalues,
        mass: &truncated.mass,
        area: shape.area,
    }
}
