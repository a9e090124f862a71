//! The options of the learned-features stage ([`super::Features::Learned`])
//! and what a shape prepared for it holds.

use std::sync::Arc;

use fmaps_learn::ShapeOperators;
use fmaps_learn::adapt::Adaptation;
use fmaps_learn::model::Model;
use fmaps_mesh_io::TriMesh;
use nalgebra::DMatrix;

use crate::laplacian::MassKind;

use super::error::MatchError;

/// How the initial point map is read off learned features.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum LearnedPointMap {
    /// For each source vertex, the target vertex of most similar features
    /// (largest cosine similarity, as the networks are trained to
    /// produce): no functional map involved.
    #[default]
    Features,
    /// The functional map of the features through the regularised layer
    /// the network was trained with (λ and γ of the adaptation's recipe)
    /// at size `k`, then nearest neighbours in the spectral embedding.
    Spectral,
}

impl LearnedPointMap {
    /// The names `fmaps match --point-map` takes.
    pub const ALL: [LearnedPointMap; 2] = [LearnedPointMap::Features, LearnedPointMap::Spectral];

    /// `features` or `spectral`.
    pub fn name(self) -> &'static str {
        match self {
            LearnedPointMap::Features => "features",
            LearnedPointMap::Spectral => "spectral",
        }
    }
}

impl std::str::FromStr for LearnedPointMap {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        LearnedPointMap::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("'{s}': expected features or spectral"))
    }
}

/// The learned-features stage of [`MatchParams::features`](super::MatchParams::features).
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct LearnedFeatures {
    /// The feature extractor.
    pub model: Arc<Model>,
    /// Test-time adaptation to each pair (`steps` 0: none): its recipe
    /// also holds the functional-map layer's λ and γ.
    pub adaptation: Adaptation,
    /// How the initial point map is read off the features.
    pub point_map: LearnedPointMap,
}

impl LearnedFeatures {
    /// The map size `fmaps match --features learned` pulls the learned
    /// point map back to when no refinement is named (100).
    pub const DEFAULT_K: usize = 100;

    /// The ZoomOut schedule that refines it then, `K:200:20` from the map
    /// size K: a learned map is accurate at a high spectral resolution,
    /// and a few ZoomOut steps from there smooth it without pulling it
    /// back through the low frequencies (measured in docs/benchmarks.md:
    /// from 50 the standard 50:150:5 schedule loses accuracy).
    pub fn default_schedule(k: usize) -> String {
        format!("{k}:{}:20", k.max(200))
    }

    /// `model`'s features, no adaptation, the point map by nearest
    /// features.
    pub fn new(model: Arc<Model>) -> LearnedFeatures {
        LearnedFeatures {
            model,
            adaptation: Adaptation::default(),
            point_map: LearnedPointMap::default(),
        }
    }

    /// The eigenpairs per shape these features use: the model's, and with
    /// adaptation the training losses' functional maps'.
    pub fn eigenpairs(&self) -> usize {
        let model = self.model.preprocessing.eigenpairs;
        if self.adaptation.steps > 0 {
            model.max(self.adaptation.recipe.fmap_eigenpairs)
        } else {
            model
        }
    }

    /// The weight of the Dirichlet energy of the soft maps in the
    /// adaptation's losses for non-isometric pairs
    /// ([`LearnedFeatures::non_isometric`]).
    pub const NON_ISOMETRIC_DIRICHLET: f64 = 10.0;

    /// For non-isometric pairs: the adaptation's losses also hold the
    /// Dirichlet energy of the soft point maps
    /// ([`fmaps_learn::dirichlet`]), weight
    /// [`Self::NON_ISOMETRIC_DIRICHLET`] (no effect without adaptation).
    pub fn non_isometric(mut self) -> LearnedFeatures {
        self.adaptation.recipe.weights.dirichlet = Self::NON_ISOMETRIC_DIRICHLET;
        self
    }

    /// The model shipped with fmaps ([`Model::shipped`]).
    pub fn shipped() -> Result<LearnedFeatures, MatchError> {
        Ok(LearnedFeatures::new(Arc::new(
            Model::shipped().map_err(MatchError::Learned)?,
        )))
    }
}

pub(super) fn learn_error(e: fmaps_learn::Error) -> MatchError {
    MatchError::Learned(e)
}

/// What a shape holds for a learned pipeline: the network's operators
/// (around the shape's eigenbasis), its input and its features.
#[derive(Debug, Clone)]
pub struct LearnedShape {
    /// DiffusionNet's operators of the unit-area shape.
    pub operators: ShapeOperators,
    /// The network's input (n x inputs).
    pub input: DMatrix<f64>,
    /// The model's features (n x outputs), without adaptation.
    pub features: DMatrix<f64>,
    /// The model they are of.
    pub model: Arc<Model>,
}

impl LearnedShape {
    /// Whether this state serves `learned`: the same model (the same
    /// weights), and operators of as many eigenpairs as it needs.
    pub fn serves(&self, learned: &LearnedFeatures) -> bool {
        (Arc::ptr_eq(&self.model, &learned.model) || *self.model == *learned.model)
            && self.operators.eigenvalues.len() >= learned.eigenpairs()
    }
}

/// The learned state of a prepared shape (`mesh`: its unit-area mesh,
/// `basis`: its eigenbasis) for `learned`: the operators around the basis
/// when it is the lumped-mass cotangent one the networks use, else their
/// own.
pub(super) fn learned_shape(
    mesh: &TriMesh,
    basis: &fmaps_eigensolve::SpectralBasis,
    mass: MassKind,
    learned: &LearnedFeatures,
) -> Result<LearnedShape, MatchError> {
    let model = &learned.model;
    let k = learned.eigenpairs();
    let operators = if mass == MassKind::Lumped && basis.k() >= k {
        ShapeOperators::with_basis(
            mesh,
            basis.mass.clone(),
            basis.eigenvalues.rows(0, k).into_owned(),
            basis.eigenvectors.columns(0, k).into_owned(),
        )
    } else {
        ShapeOperators::compute(mesh, k)
    }
    .map_err(learn_error)?;
    let input = model.input(mesh, &operators).map_err(learn_error)?;
    let features = model.features_of(&operators, &input);
    if let Some(i) = features.iter().position(|v| !v.is_finite()) {
        return Err(MatchError::InvalidShape {
            shape: "input",
            message: format!(
                "the learned features are not finite at vertex {}, feature {}",
                i % features.nrows(),
                i / features.nrows()
            ),
        });
    }
    Ok(LearnedShape {
        operators,
        input,
        features,
        model: Arc::clone(model),
    })
}
