//! Test-time adaptation: a few steps of the unsupervised training losses
//! on the very pair to be matched, from a trained model (Cao, Roetzer,
//! Bernard, "Unsupervised Learning of Robust Spectral Shape Matching",
//! SIGGRAPH 2023, section 4.4). The losses need no ground truth, so the
//! network can fit the pair it is asked about: shapes unlike the training
//! data (other people, other species, other meshings) gain the most. The
//! steps run on a copy; the model given is unchanged.

use crate::model::Model;
use crate::network::SplitMix;
use crate::optim::Adam;
use crate::train::{LossValues, Recipe, TrainShape, pair_loss};
use crate::{Error, Result};

/// How a model is adapted to a pair.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct Adaptation {
    /// Adam steps on the pair (0: none).
    pub steps: usize,
    /// Learning rate, constant (1e-3: the training recipe's initial rate).
    pub lr: f64,
    /// The losses (their weights, the layer, the temperature, the coupling
    /// samples, the seed of the samples). Dropout is off whatever the
    /// recipe says: the map is read from the same network that was
    /// adapted.
    pub recipe: Recipe,
}

impl Default for Adaptation {
    fn default() -> Self {
        Adaptation {
            steps: 0,
            lr: 1e-3,
            recipe: Recipe::default(),
        }
    }
}

/// A model adapted to a pair, and the losses before each step.
#[derive(Debug, Clone)]
pub struct Adapted {
    /// The adapted copy of the model.
    pub model: Model,
    /// The pair's losses before each step (`steps` entries).
    pub losses: Vec<LossValues>,
}

/// Adapts a copy of `model` to the pair (`x`, `y`): `adaptation.steps`
/// Adam steps on the pair's unsupervised losses (both directions, as in
/// training). The shapes must be prepared for `model` and
/// `adaptation.recipe` ([`TrainShape::new`] or
/// [`TrainShape::from_operators`]).
///
/// Errors: a non-finite loss or gradient (naming the step), the layer's
/// errors.
///
/// ```
/// use fmaps_learn::adapt::{Adaptation, adapt};
/// use fmaps_learn::model::{Architecture, Model, Preprocessing};
/// use fmaps_learn::train::{Recipe, TrainShape};
///
/// let arch = Architecture { inputs: 8, width: 8, blocks: 1, outputs: 8 };
/// let pre = Preprocessing { eigenpairs: 12, ..Preprocessing::default() };
/// let model = Model::new(arch, pre, 1);
/// let mut adaptation = Adaptation::default();
/// adaptation.steps = 3;
/// adaptation.recipe.fmap_eigenpairs = 10;
/// adaptation.recipe.coupling_samples = None;
/// let pair = fmaps_shapes::creature_pair(2);
/// let x = TrainShape::new("a", &pair.source, &model, &adaptation.recipe)?;
/// let y = TrainShape::new("b", &pair.target, &model, &adaptation.recipe)?;
/// let adapted = adapt(&model, &x, &y, &adaptation)?;
/// assert_eq!(adapted.losses.len(), 3);
/// # Ok::<(), fmaps_learn::Error>(())
/// ```
pub fn adapt(
    model: &Model,
    x: &TrainShape,
    y: &TrainShape,
    adaptation: &Adaptation,
) -> Result<Adapted> {
    if !(adaptation.lr.is_finite() && adaptation.lr > 0.0) {
        return Err(Error::Parameter(format!(
            "adaptation learning rate {}: expected a positive number",
            adaptation.lr
        )));
    }
    let mut model = model.clone();
    let mut adam = Adam::new(adaptation.lr);
    let mut rng = SplitMix(adaptation.recipe.seed);
    let mut losses = Vec::with_capacity(adaptation.steps);
    for step in 1..=adaptation.steps {
        let (values, mut grad) = pair_loss(&model, &adaptation.recipe, x, y, &mut rng, false)
            .map_err(|e| match e {
                Error::NonFinite { what, .. } => Error::NonFinite {
                    step: step as u64,
                    what,
                },
                other => other,
            })?;
        let groups = grad.groups_mut();
        if !values.total.is_finite() || groups.iter().any(|g| g.iter().any(|v| !v.is_finite())) {
            return Err(Error::NonFinite {
                step: step as u64,
                what: format!("adaptation loss {} or its gradient", values.total),
            });
        }
        adam.begin_step();
        for (g, (p, d)) in model.net.params_mut().into_iter().zip(groups).enumerate() {
            adam.update(g, p, d);
        }
        for b in &mut model.net.blocks {
            b.diffusion.times.apply(|t| *t = t.max(1e-8));
        }
        losses.push(values);
    }
    Ok(Adapted { model, losses })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Architecture, Preprocessing};

    /// With the Dirichlet term the adaptation records it and moves the
    /// network elsewhere; the model given is unchanged either way.
    #[test]
    fn the_dirichlet_term_adapts_the_model_differently() {
        let arch = Architecture {
            inputs: 8,
            width: 8,
            blocks: 1,
            outputs: 8,
        };
        let pre = Preprocessing {
            eigenpairs: 12,
            ..Preprocessing::default()
        };
        let model = Model::new(arch, pre, 1);
        let mut plain = Adaptation {
            steps: 3,
            ..Adaptation::default()
        };
        plain.recipe.fmap_eigenpairs = 10;
        plain.recipe.coupling_samples = Some(100);
        let mut smooth = plain.clone();
        smooth.recipe.weights.dirichlet = 10.0;
        let pair = fmaps_shapes::creature_pair(2);
        let x = TrainShape::new("a", &pair.source, &model, &plain.recipe)
            .unwrap()
            .with_geometry(&pair.source)
            .unwrap();
        let y = TrainShape::new("b", &pair.target, &model, &plain.recipe)
            .unwrap()
            .with_geometry(&pair.target)
            .unwrap();
        let a = adapt(&model, &x, &y, &plain).unwrap();
        let b = adapt(&model, &x, &y, &smooth).unwrap();
        assert!(a.losses.iter().all(|l| l.dirichlet == 0.0));
        assert!(b.losses.iter().all(|l| l.dirichlet > 0.0));
        // The first step's other terms are the same network's.
        assert_eq!(a.losses[0].coupling, b.losses[0].coupling);
        assert_ne!(a.model, b.model);
        assert_ne!(a.model, model);
    }
}
