//! A training run's hyper-parameters: the loss terms' weights, the layer,
//! the schedule.

use serde::{Deserialize, Serialize};

use crate::Error;
use crate::Result;
use crate::augment::Augment;
use crate::fmap_layer::FmapLayer;

/// Weights of the loss terms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LossWeights {
    /// Bijectivity (ULRSSM: 1).
    pub bijectivity: f64,
    /// Orthogonality (1).
    pub orthogonality: f64,
    /// Laplacian commutativity (0: off for near-isometric training).
    pub laplacian: f64,
    /// Coupling of the functional and soft point maps (1).
    pub coupling: f64,
    /// The Dirichlet energy of the soft point maps ([`crate::dirichlet`];
    /// 0: off, as for near-isometric training; the shapes then need
    /// their geometry, [`TrainShape::with_geometry`](super::TrainShape::with_geometry)).
    #[serde(default)]
    pub dirichlet: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        LossWeights {
            bijectivity: 1.0,
            orthogonality: 1.0,
            laplacian: 0.0,
            coupling: 1.0,
            dirichlet: 0.0,
        }
    }
}

/// A training run's hyper-parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub struct Recipe {
    /// Pair steps.
    pub steps: u64,
    /// Initial learning rate (ULRSSM: 1e-3).
    pub lr: f64,
    /// Final learning rate of the cosine schedule (1e-4).
    pub lr_min: f64,
    /// Eigenpairs of the functional maps (ULRSSM: 200).
    pub fmap_eigenpairs: usize,
    /// The functional-map layer (λ = 100, γ = 0.5).
    pub fmap: FmapLayerParams,
    /// Temperature of the soft point maps (0.07).
    pub tau: f64,
    /// The loss terms' weights.
    pub weights: LossWeights,
    /// Vertices of each shape the coupling loss samples per step (`None`:
    /// all).
    pub coupling_samples: Option<usize>,
    /// Bound on the gradients' global norm (`None`: no clipping).
    pub clip: Option<f64>,
    /// Seed of the initial weights and of every random draw.
    pub seed: u64,
    /// Dropout in the blocks' MLPs while training (the reference's
    /// default: on).
    #[serde(default = "on")]
    pub dropout: bool,
    /// Augmentation of coordinate inputs ([`Input::Xyz`](crate::model::Input::Xyz); WKS inputs are
    /// intrinsic and taken as they are).
    #[serde(default)]
    pub augment: Augment,
    /// Centre vertices per shape whose edges estimate the Dirichlet
    /// energy per step (`None`: all), the soft maps going onto the
    /// coupling loss's samples.
    #[serde(default = "dirichlet_centres")]
    pub dirichlet_centres: Option<usize>,
}

fn dirichlet_centres() -> Option<usize> {
    Some(200)
}

fn on() -> bool {
    true
}

/// [`FmapLayer`](crate::fmap_layer::FmapLayer)'s parameters as a recipe stores them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FmapLayerParams {
    /// λ.
    pub lambda: f64,
    /// γ.
    pub gamma: f64,
}

impl Default for Recipe {
    /// ULRSSM's FAUST recipe (learning rates, layer, temperature,
    /// weights) over 1000 steps, the coupling loss on 1000 sampled
    /// vertices per shape.
    fn default() -> Self {
        let l = FmapLayer::default();
        Recipe {
            steps: 1000,
            lr: 1e-3,
            lr_min: 1e-4,
            fmap_eigenpairs: 200,
            fmap: FmapLayerParams {
                lambda: l.lambda,
                gamma: l.gamma,
            },
            tau: 0.07,
            weights: LossWeights::default(),
            coupling_samples: Some(1000),
            clip: None,
            seed: 1,
            dropout: true,
            augment: Augment::default(),
            dirichlet_centres: dirichlet_centres(),
        }
    }
}

impl Recipe {
    /// The learning rate of step `step` (0-based): cosine annealing from
    /// `lr` to `lr_min` over `steps`.
    pub fn lr_at(&self, step: u64) -> f64 {
        let t = if self.steps <= 1 {
            0.0
        } else {
            step.min(self.steps - 1) as f64 / (self.steps - 1) as f64
        };
        self.lr_min + 0.5 * (self.lr - self.lr_min) * (1.0 + (std::f64::consts::PI * t).cos())
    }

    pub(super) fn layer(&self) -> FmapLayer {
        FmapLayer {
            lambda: self.fmap.lambda,
            gamma: self.fmap.gamma,
        }
    }

    pub(super) fn check(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Parameter(m));
        if self.steps == 0 {
            return bad("0 training steps".into());
        }
        if !(self.lr > 0.0 && self.lr.is_finite() && self.lr_min >= 0.0 && self.lr_min <= self.lr) {
            return bad(format!(
                "learning rates {} -> {}: expected 0 <= lr_min <= lr",
                self.lr, self.lr_min
            ));
        }
        if self.fmap_eigenpairs < 2 {
            return bad(format!("{} eigenpairs for the maps", self.fmap_eigenpairs));
        }
        if !(self.tau > 0.0 && self.tau.is_finite()) {
            return bad(format!("temperature {}", self.tau));
        }
        if self.coupling_samples == Some(0) || self.dirichlet_centres == Some(0) {
            return bad("0 coupling samples or Dirichlet centres".into());
        }
        Ok(())
    }
}
