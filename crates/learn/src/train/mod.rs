//! Unsupervised training of a [`Model`] on pairs of shapes, as ULRSSM
//! (Cao, Roetzer, Bernard, SIGGRAPH 2023) trains: each step takes a
//! random ordered pair (x, y), computes both shapes' features (with
//! dropout), the functional maps `C_xy` and `C_yx` of the regularised
//! layer ([`FmapLayer`](crate::fmap_layer::FmapLayer)) on the first [`Recipe::fmap_eigenpairs`]
//! eigenpairs, and the loss
//!
//! `w_bij · bijectivity + w_orth · orthogonality + w_lap · Laplacian
//! commutativity + w_couple · coupling`
//!
//! ([`losses`], [`coupling`]); Adam with a cosine learning-rate schedule
//! from [`Recipe::lr`] to [`Recipe::lr_min`] over [`Recipe::steps`]
//! steps, optional gradient clipping. No ground truth is read.
//!
//! Everything random (the pairs, the dropout masks, the coupling loss's
//! vertex samples) comes from one generator seeded by [`Recipe::seed`]:
//! a run is a function of its recipe and its shapes, whatever the thread
//! count. A [`Trainer`] saves and resumes checkpoints exactly (the
//! parameters, Adam's moments, the generator's state, the loss history),
//! so a run killed and resumed gives the same model as a run that was
//! never stopped.

use std::collections::BTreeMap;
use std::path::Path;

use fmaps_mesh_io::{TriMesh, npy, npz};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

pub use crate::augment::{Augment, Rotation};
pub use recipe::{FmapLayerParams, LossWeights, Recipe};

mod recipe;
use crate::coupling::{CouplingShape, coupling};
use crate::dirichlet::{DirichletShape, dirichlet};
use crate::layers::Spectrum;
use crate::losses;
use crate::model::{Input, Model, NetBasis, entry, tensor_npy, write_entries};
use crate::network::{DiffusionNetGrad, FeatureNet, SplitMix};
use crate::optim::{Adam, clip_grad_norm};
use crate::{Error, Result, ShapeOperators};

/// The checkpoint file's format name.
pub const CHECKPOINT_FORMAT: &str = "fmaps-checkpoint";
/// The checkpoint file's version.
pub const CHECKPOINT_VERSION: u32 = 1;

/// A training shape: its operators, input features and bases.
#[derive(Debug, Clone)]
pub struct TrainShape {
    /// Its name (file stem), for messages and checkpoints.
    pub name: String,
    ops: ShapeOperators,
    input: DMatrix<f64>,
    fmap_evals: DVector<f64>,
    /// The maps' eigenvectors when fewer than the operators' (else those).
    fmap_evecs: Option<DMatrix<f64>>,
    /// The unit-area positions and cotangent stiffness, for the Dirichlet
    /// loss.
    geometry: Option<(DMatrix<f64>, sprs::CsMat<f64>)>,
}

impl TrainShape {
    /// Prepares `mesh` for `model` and `recipe` (unit area, operators
    /// with the larger of the two eigenpair counts, the input features).
    pub fn new(name: &str, mesh: &TriMesh, model: &Model, recipe: &Recipe) -> Result<TrainShape> {
        let p = model.prepare(mesh, recipe.fmap_eigenpairs)?;
        Ok(TrainShape::from_operators(
            name,
            p.operators,
            p.input,
            recipe,
        ))
    }

    /// From operators computed elsewhere (a cache) and the input.
    pub fn from_operators(
        name: &str,
        ops: ShapeOperators,
        input: DMatrix<f64>,
        recipe: &Recipe,
    ) -> TrainShape {
        let k = recipe.fmap_eigenpairs.min(ops.eigenvalues.len());
        TrainShape {
            name: name.to_string(),
            fmap_evals: ops.eigenvalues.rows(0, k).into_owned(),
            fmap_evecs: (k < ops.eigenvectors.ncols())
                .then(|| ops.eigenvectors.columns(0, k).into_owned()),
            ops,
            input,
            geometry: None,
        }
    }

    /// With the geometry the Dirichlet loss needs: `mesh`'s positions and
    /// cotangent stiffness, scaled to unit area as the operators are
    /// (`mesh` is the shape the operators were computed on, at any
    /// scale).
    pub fn with_geometry(mut self, mesh: &TriMesh) -> Result<TrainShape> {
        if mesh.n_vertices() != self.input.nrows() {
            return Err(Error::Parameter(format!(
                "{}: a mesh of {} vertices for operators of {}",
                self.name,
                mesh.n_vertices(),
                self.input.nrows()
            )));
        }
        let (unit, _) = mesh.to_unit_area()?;
        self.geometry = Some((
            crate::dirichlet::positions(&unit),
            fmaps_laplacian::cotan_stiffness(&unit),
        ));
        Ok(self)
    }

    /// The shape's operators.
    pub fn operators(&self) -> &ShapeOperators {
        &self.ops
    }

    /// The network's input features.
    pub fn input(&self) -> &DMatrix<f64> {
        &self.input
    }

    /// The functional maps' eigenvalues and eigenvectors.
    pub fn fmap_basis(&self) -> (&DVector<f64>, &DMatrix<f64>) {
        (&self.fmap_evals, self.fmap_evecs())
    }

    fn fmap_evecs(&self) -> &DMatrix<f64> {
        self.fmap_evecs.as_ref().unwrap_or(&self.ops.eigenvectors)
    }

    fn fmap_spectrum(&self) -> Spectrum<'_> {
        Spectrum {
            eigenvalues: &self.fmap_evals,
            eigenvectors: self.fmap_evecs(),
            mass: &self.ops.mass,
        }
    }
}

/// The loss terms of one step (weighted as in the total).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct LossValues {
    /// Weighted bijectivity.
    pub bijectivity: f64,
    /// Weighted orthogonality.
    pub orthogonality: f64,
    /// Weighted Laplacian commutativity.
    pub laplacian: f64,
    /// Weighted coupling.
    pub coupling: f64,
    /// Weighted Dirichlet energy of the soft maps.
    #[serde(default)]
    pub dirichlet: f64,
    /// Their sum.
    pub total: f64,
}

/// What one step did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StepRecord {
    /// The step (1-based).
    pub step: u64,
    /// The pair (indices into the shapes).
    pub pair: (usize, usize),
    /// The learning rate used.
    pub lr: f64,
    /// The losses before the update.
    pub losses: LossValues,
    /// The gradients' global norm before clipping.
    pub grad_norm: f64,
}

/// The losses of the pair (x, y) and the gradients of the network's
/// parameters, drawing the dropout masks (when `dropout`) and the
/// coupling samples from `rng` (x's then y's).
pub fn pair_loss(
    model: &Model,
    recipe: &Recipe,
    x: &TrainShape,
    y: &TrainShape,
    rng: &mut SplitMix,
    dropout: bool,
) -> Result<(LossValues, DiffusionNetGrad)> {
    pair_loss_full(model, recipe, x, y, rng, dropout).map(|p| (p.losses, p.grad))
}

/// Everything one pair step computes.
#[derive(Debug, Clone)]
pub struct PairOutput<G = DiffusionNetGrad> {
    /// The losses.
    pub losses: LossValues,
    /// The parameters' gradients.
    pub grad: G,
    /// The features of x and y.
    pub features: (DMatrix<f64>, DMatrix<f64>),
    /// `C_xy` and `C_yx`.
    pub maps: (DMatrix<f64>, DMatrix<f64>),
}

/// [`pair_loss`] with the features and maps it computed.
pub fn pair_loss_full(
    model: &Model,
    recipe: &Recipe,
    x: &TrainShape,
    y: &TrainShape,
    rng: &mut SplitMix,
    dropout: bool,
) -> Result<PairOutput> {
    let k_net = model.preprocessing.eigenpairs;
    let augment = (dropout && model.preprocessing.input == Input::Xyz).then_some(&recipe.augment);
    pair_loss_of(&model.net, k_net, recipe, x, y, rng, dropout, augment)
}

/// [`pair_loss_full`] for any [`FeatureNet`] whose diffusion uses the
/// first `k_net` eigenpairs, the inputs augmented by `augment` when given.
#[allow(clippy::too_many_arguments)]
pub fn pair_loss_of<N: FeatureNet>(
    net: &N,
    k_net: usize,
    recipe: &Recipe,
    x: &TrainShape,
    y: &TrainShape,
    rng: &mut SplitMix,
    dropout: bool,
    augment: Option<&Augment>,
) -> Result<PairOutput<N::Grad>> {
    let (bx, by) = (NetBasis::new(&x.ops, k_net), NetBasis::new(&y.ops, k_net));
    let (input_x, input_y) = match augment {
        Some(a) => (
            std::borrow::Cow::Owned(a.apply(&x.input, rng)),
            std::borrow::Cow::Owned(a.apply(&y.input, rng)),
        ),
        None => (
            std::borrow::Cow::Borrowed(&x.input),
            std::borrow::Cow::Borrowed(&y.input),
        ),
    };
    let noise_x = dropout.then(|| net.draw(x.input.nrows(), rng));
    let noise_y = dropout.then(|| net.draw(y.input.nrows(), rng));
    let samples_x = draw_samples(x.input.nrows(), recipe.coupling_samples, rng);
    let samples_y = draw_samples(y.input.nrows(), recipe.coupling_samples, rng);
    let ((fx, tape_x), (fy, tape_y)) = rayon::join(
        || net.forward_train(bx.input(&x.ops), &input_x, noise_x.as_ref()),
        || net.forward_train(by.input(&y.ops), &input_y, noise_y.as_ref()),
    );
    for (f, s) in [(&fx, x), (&fy, y)] {
        if let Some(i) = f.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                step: 0,
                what: format!(
                    "feature {} of vertex {} of {}",
                    i / f.nrows(),
                    i % f.nrows(),
                    s.name
                ),
            });
        }
    }
    let layer = recipe.layer();
    let (sx, sy) = (x.fmap_spectrum(), y.fmap_spectrum());
    let (a, b) = (sx.project(&fx), sy.project(&fy));
    let (c_xy, tape_xy) = layer.forward_tape(&a, &b, &x.fmap_evals, &y.fmap_evals)?;
    let (c_yx, tape_yx) = layer.forward_tape(&b, &a, &y.fmap_evals, &x.fmap_evals)?;
    let w = recipe.weights;
    let mut values = LossValues::default();
    let (bij, mut d_xy, mut d_yx) = losses::bijectivity(&c_xy, &c_yx);
    values.bijectivity = w.bijectivity * bij;
    d_xy *= w.bijectivity;
    d_yx *= w.bijectivity;
    for (c, d) in [(&c_xy, &mut d_xy), (&c_yx, &mut d_yx)] {
        let (o, g) = losses::orthogonality(c);
        values.orthogonality += w.orthogonality * o;
        *d += g * w.orthogonality;
    }
    if w.laplacian != 0.0 {
        for (c, d, from, to) in [
            (&c_xy, &mut d_xy, &x.fmap_evals, &y.fmap_evals),
            (&c_yx, &mut d_yx, &y.fmap_evals, &x.fmap_evals),
        ] {
            let (l, g) = losses::laplacian_commutativity(c, from, to, recipe.fmap.gamma);
            values.laplacian += w.laplacian * l;
            *d += g * w.laplacian;
        }
    }
    let mut dfx = DMatrix::zeros(fx.nrows(), fx.ncols());
    let mut dfy = DMatrix::zeros(fy.nrows(), fy.ncols());
    if w.coupling != 0.0 {
        fn side<'a>(
            f: &'a DMatrix<f64>,
            s: &'a TrainShape,
            v: Option<&'a [usize]>,
        ) -> CouplingShape<'a> {
            CouplingShape {
                features: f,
                eigenvectors: s.fmap_evecs(),
                mass: &s.ops.mass,
                vertices: v,
            }
        }
        let g = coupling(
            &side(&fx, x, samples_x.as_deref()),
            &side(&fy, y, samples_y.as_deref()),
            &c_xy,
            &c_yx,
            recipe.tau,
        );
        values.coupling = w.coupling * g.loss;
        d_xy += g.c_xy * w.coupling;
        d_yx += g.c_yx * w.coupling;
        dfx += g.features_x * w.coupling;
        dfy += g.features_y * w.coupling;
    }
    if w.dirichlet != 0.0 {
        let (Some((px, lx)), Some((py, ly))) = (&x.geometry, &y.geometry) else {
            return Err(Error::Parameter(format!(
                "the Dirichlet loss needs the geometry of {} and {} (TrainShape::with_geometry)",
                x.name, y.name
            )));
        };
        let centres_x = draw_samples(fx.nrows(), recipe.dirichlet_centres, rng);
        let centres_y = draw_samples(fy.nrows(), recipe.dirichlet_centres, rng);
        let g = dirichlet(
            &DirichletShape {
                features: &fx,
                positions: px,
                stiffness: lx,
                centres: centres_x.as_deref(),
                targets: samples_x.as_deref(),
            },
            &DirichletShape {
                features: &fy,
                positions: py,
                stiffness: ly,
                centres: centres_y.as_deref(),
                targets: samples_y.as_deref(),
            },
            recipe.tau,
        );
        values.dirichlet = w.dirichlet * g.loss;
        dfx += g.features_x * w.dirichlet;
        dfy += g.features_y * w.dirichlet;
    }
    values.total = values.bijectivity
        + values.orthogonality
        + values.laplacian
        + values.coupling
        + values.dirichlet;
    let (da1, db1) = layer.backward_tape(&a, &b, &tape_xy, &d_xy);
    let (db2, da2) = layer.backward_tape(&b, &a, &tape_yx, &d_yx);
    dfx += sx.project_backward(&(da1 + da2));
    dfy += sy.project_backward(&(db1 + db2));
    let (mut grad, grad_y) = rayon::join(
        || net.backward_train(bx.input(&x.ops), &input_x, &tape_x, &dfx),
        || net.backward_train(by.input(&y.ops), &input_y, &tape_y, &dfy),
    );
    N::add_grad(&mut grad, &grad_y);
    Ok(PairOutput {
        losses: values,
        grad,
        features: (fx, fy),
        maps: (c_xy, c_yx),
    })
}

/// `count` distinct vertices of `n` (all when `None` or at least `n`),
/// sorted.
fn draw_samples(n: usize, count: Option<usize>, rng: &mut SplitMix) -> Option<Vec<usize>> {
    let count = count?;
    if count >= n {
        return None;
    }
    // Partial Fisher–Yates.
    let mut idx: Vec<usize> = (0..n).collect();
    for i in 0..count {
        let j = i + (rng.next_u64() % (n - i) as u64) as usize;
        idx.swap(i, j);
    }
    let mut s = idx[..count].to_vec();
    s.sort_unstable();
    Some(s)
}

/// A training run in progress (see the module docs).
#[derive(Debug, Clone)]
pub struct Trainer {
    /// The model being trained.
    pub model: Model,
    /// The recipe.
    pub recipe: Recipe,
    /// The training shapes' names, in the order the pairs index them.
    pub shapes: Vec<String>,
    /// The pairs a step draws from (indices into `shapes`); empty: every
    /// ordered pair of two different shapes.
    pub pairs: Vec<(usize, usize)>,
    /// Steps done.
    pub step: u64,
    /// One record per step done.
    pub history: Vec<StepRecord>,
    adam: Adam,
    rng: SplitMix,
}

/// A checkpoint's training state (its `training` entry).
#[derive(Debug, Clone, Serialize, Deserialize)]
struct TrainingMeta {
    format: String,
    version: u32,
    recipe: Recipe,
    shapes: Vec<String>,
    pairs: Vec<(usize, usize)>,
    step: u64,
    adam_steps: u64,
    rng: u64,
    history: Vec<StepRecord>,
}

impl Trainer {
    /// A new run of `recipe` on the shapes named `shapes`, from `model`
    /// (fresh: [`Model::new`] with the recipe's seed).
    pub fn new(model: Model, recipe: Recipe, shapes: Vec<String>) -> Result<Trainer> {
        recipe.check()?;
        if shapes.len() < 2 {
            return Err(Error::Parameter(format!(
                "{} training shape(s): pairs need at least two",
                shapes.len()
            )));
        }
        Ok(Trainer {
            adam: Adam::new(recipe.lr),
            // The weights took the seed itself; the draws a derived one.
            rng: SplitMix(recipe.seed ^ 0x5EED_DA7A),
            model,
            recipe,
            shapes,
            pairs: Vec::new(),
            step: 0,
            history: Vec::new(),
        })
    }

    /// Whether every step is done.
    pub fn finished(&self) -> bool {
        self.step >= self.recipe.steps
    }

    /// One step on `shapes` (the shapes named by [`shapes`](Self::shapes),
    /// in that order). A non-finite loss or gradient is an error and
    /// leaves the model as it was.
    pub fn step(&mut self, shapes: &[TrainShape]) -> Result<StepRecord> {
        if shapes.len() != self.shapes.len() {
            return Err(Error::Parameter(format!(
                "{} shapes for a run on {}",
                shapes.len(),
                self.shapes.len()
            )));
        }
        let mut rng = self.rng.clone();
        let (i, j) = if self.pairs.is_empty() {
            let n = shapes.len() as u64;
            let i = (rng.next_u64() % n) as usize;
            (
                i,
                (i + 1 + (rng.next_u64() % (n - 1)) as usize) % shapes.len(),
            )
        } else {
            self.pairs[(rng.next_u64() % self.pairs.len() as u64) as usize]
        };
        let step = self.step + 1;
        let pair = format!("pair {} -> {}", shapes[i].name, shapes[j].name);
        let (values, mut grad) = pair_loss(
            &self.model,
            &self.recipe,
            &shapes[i],
            &shapes[j],
            &mut rng,
            self.recipe.dropout,
        )
        .map_err(|e| match e {
            Error::NonFinite { what, .. } => Error::NonFinite {
                step,
                what: format!("{what}, {pair}"),
            },
            other => other,
        })?;
        if !values.total.is_finite() {
            return Err(Error::NonFinite {
                step,
                what: format!("loss {} on {pair}", values.total),
            });
        }
        let mut groups = grad.groups_mut();
        let grad_norm = match self.recipe.clip {
            Some(max) => clip_grad_norm(&mut groups, max),
            None => clip_grad_norm(&mut groups, f64::INFINITY),
        };
        if !grad_norm.is_finite() {
            return Err(Error::NonFinite {
                step,
                what: format!("gradient norm {grad_norm} on {pair}"),
            });
        }
        let lr = self.recipe.lr_at(self.step);
        self.adam.lr = lr;
        self.adam.begin_step();
        for (g, (p, d)) in self
            .model
            .net
            .params_mut()
            .into_iter()
            .zip(groups)
            .enumerate()
        {
            self.adam.update(g, p, d);
        }
        // The reference keeps the diffusion times at least 1e-8.
        for b in &mut self.model.net.blocks {
            b.diffusion.times.apply(|t| *t = t.max(1e-8));
        }
        self.rng = rng;
        self.step = step;
        let record = StepRecord {
            step,
            pair: (i, j),
            lr,
            losses: values,
            grad_norm,
        };
        self.history.push(record);
        Ok(record)
    }

    /// Writes the checkpoint `path` atomically: the model (a model file
    /// with the training state added, so a checkpoint loads as a model),
    /// Adam's moments, the generator, the history.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let meta = TrainingMeta {
            format: CHECKPOINT_FORMAT.into(),
            version: CHECKPOINT_VERSION,
            recipe: self.recipe.clone(),
            shapes: self.shapes.clone(),
            pairs: self.pairs.clone(),
            step: self.step,
            adam_steps: self.adam.steps,
            rng: self.rng.0,
            history: self.history.clone(),
        };
        let text = serde_json::to_string(&meta)
            .map_err(|e| Error::Parameter(format!("checkpoint metadata: {e}")))?;
        let mut buf = Vec::new();
        npy::write_u8(&mut buf, text.as_bytes()).map_err(|e| Error::Write {
            path: path.as_ref().to_path_buf(),
            source: e,
        })?;
        let mut extra = vec![("training.npy".to_string(), buf)];
        let params = self.model.net.params();
        for (g, p) in params.iter().enumerate() {
            if let Some((m, v)) = self.adam.moments().get(g)
                && !m.is_empty()
            {
                {
                    extra.push((format!("adam.m.{}.npy", p.name), tensor_npy(&p.shape, m)?));
                    extra.push((format!("adam.v.{}.npy", p.name), tensor_npy(&p.shape, v)?));
                }
            }
        }
        write_entries(path.as_ref(), &self.model.entries(extra)?)
    }

    /// Reads a checkpoint written by [`save`](Self::save).
    pub fn load(path: impl AsRef<Path>) -> Result<Trainer> {
        let path = path.as_ref();
        let data = fmaps_mesh_io::read_bounded(path, 1 << 31)?;
        Trainer::parse(&data).map_err(|problem| Error::ModelFile {
            path: path.to_path_buf(),
            problem,
        })
    }

    fn parse(data: &[u8]) -> std::result::Result<Trainer, String> {
        let model = Model::parse(data)?;
        let entries = npz::read_archive(data).map_err(|(at, m)| format!("byte {at}: {m}"))?;
        let text =
            npy::parse_u8(entry(&entries, "training").map_err(|_| {
                "a model file without training state, not a checkpoint".to_string()
            })?)
            .map_err(|(_, m)| format!("`training`: {m}"))?;
        let meta: TrainingMeta = serde_json::from_slice(&text)
            .map_err(|e| format!("`training` is not a checkpoint's state: {e}"))?;
        if meta.format != CHECKPOINT_FORMAT || meta.version != CHECKPOINT_VERSION {
            return Err(format!(
                "checkpoint format `{}` version {}; this fmaps reads `{CHECKPOINT_FORMAT}` version {CHECKPOINT_VERSION}",
                meta.format, meta.version
            ));
        }
        let mut moments = Vec::new();
        if meta.adam_steps > 0 {
            for p in model.net.params() {
                let mut pair = (vec![0.0; p.values.len()], vec![0.0; p.values.len()]);
                for (which, out) in [("m", &mut pair.0), ("v", &mut pair.1)] {
                    let name = format!("adam.{which}.{}", p.name);
                    let arr = npy::parse_f64(entry(&entries, &name)?)
                        .map_err(|(_, m)| format!("`{name}`: {m}"))?;
                    if arr.shape != p.shape {
                        return Err(format!(
                            "`{name}` has shape {:?}, expected {:?}",
                            arr.shape, p.shape
                        ));
                    }
                    out.copy_from_slice(&arr.data);
                }
                moments.push(pair);
            }
        }
        let mut t = Trainer::new(model, meta.recipe, meta.shapes).map_err(|e| e.to_string())?;
        if let Some(&(i, j)) = meta
            .pairs
            .iter()
            .find(|&&(i, j)| i.max(j) >= t.shapes.len())
        {
            return Err(format!("pair ({i}, {j}) of {} shapes", t.shapes.len()));
        }
        t.pairs = meta.pairs;
        t.adam.steps = meta.adam_steps;
        t.adam.set_moments(moments);
        t.rng = SplitMix(meta.rng);
        t.step = meta.step;
        t.history = meta.history;
        Ok(t)
    }

    /// The provenance entries of a run: recipe, steps, final losses.
    pub fn provenance(&self) -> BTreeMap<String, String> {
        let mut p = BTreeMap::new();
        p.insert(
            "recipe".into(),
            serde_json::to_string(&self.recipe).unwrap_or_default(),
        );
        p.insert("steps".into(), self.step.to_string());
        p.insert("shapes".into(), self.shapes.join(" "));
        if let Some(last) = self.history.last() {
            p.insert(
                "final_losses".into(),
                serde_json::to_string(&last.losses).unwrap_or_default(),
            );
        }
        p
    }
}

/// What [`run`] reports as it goes.
#[derive(Debug, Clone, Copy)]
pub enum Event<'a> {
    /// A step is done.
    Step(&'a StepRecord),
    /// The checkpoint was written after this step.
    Saved(u64),
}

/// Runs `trainer` on `shapes` until its last step (or `stop_after` more
/// steps), writing the checkpoint `checkpoint` every `save_every` steps and
/// at the end. On an error (a non-finite loss) the checkpoint keeps the
/// last good state.
pub fn run(
    trainer: &mut Trainer,
    shapes: &[TrainShape],
    checkpoint: &Path,
    save_every: u64,
    stop_after: Option<u64>,
    mut on_event: impl FnMut(Event<'_>),
) -> Result<()> {
    let last = match stop_after {
        Some(n) => (trainer.step + n).min(trainer.recipe.steps),
        None => trainer.recipe.steps,
    };
    let mut saved = trainer.step;
    while trainer.step < last {
        let record = trainer.step(shapes)?;
        on_event(Event::Step(&record));
        if save_every > 0 && trainer.step.is_multiple_of(save_every) {
            trainer.save(checkpoint)?;
            saved = trainer.step;
            on_event(Event::Saved(trainer.step));
        }
    }
    if saved != trainer.step {
        trainer.save(checkpoint)?;
        on_event(Event::Saved(trainer.step));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
