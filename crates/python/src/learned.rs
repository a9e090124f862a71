//! Learned features from Python: the `features=`, `model=`, `adapt=` and
//! `point_map=` options of `match_shapes` and `match_prepared`, and
//! `train`.

use std::path::PathBuf;
use std::sync::Arc;

use fmaps::learn::model::{Architecture, Model, Preprocessing};
use fmaps::learn::train::{Event, Recipe, TrainShape, Trainer, run as run_training};
use fmaps::pipeline::{Features, LearnedFeatures, MatchParams};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::{Mesh, err, run};

/// The learned features `features`, `model`, `adapt` and `point_map`
/// ask for (`None`: descriptors).
pub(crate) fn learned_of(
    features: &str,
    model: Option<PathBuf>,
    adapt: usize,
    point_map: Option<&str>,
) -> PyResult<Option<LearnedFeatures>> {
    let mut learned = match features {
        "descriptors" => {
            if model.is_some() || adapt > 0 || point_map.is_some() {
                return Err(err(
                    "model, adapt and point_map apply to learned features (features = \"learned\")",
                ));
            }
            return Ok(None);
        }
        "learned" => match model {
            None => LearnedFeatures::shipped().map_err(err)?,
            Some(p) => LearnedFeatures::new(Arc::new(Model::load(&p).map_err(err)?)),
        },
        other => {
            return Err(err(format!(
                "features = {other:?}: expected \"descriptors\" or \"learned\""
            )));
        }
    };
    learned.adaptation.steps = adapt;
    if let Some(m) = point_map {
        learned.point_map = m
            .parse()
            .map_err(|e| err(format!("point_map = {m:?}: {e}")))?;
    }
    Ok(Some(learned))
}

/// The refinement, map size and schedule for learned features: "default"
/// is what `fmaps match --features learned` runs (ZoomOut
/// `K:200:20` from size 100 unless `k` is given otherwise).
pub(crate) fn refine_for(
    refine: &str,
    learned: bool,
    smallest: usize,
    k: usize,
    schedule: Option<String>,
) -> (&str, usize, Option<String>) {
    use fmaps::pipeline::RefinerKind;
    if learned && refine == "default" && RefinerKind::default_for(smallest) != RefinerKind::None {
        let k = if k == MatchParams::default().k {
            LearnedFeatures::DEFAULT_K
        } else {
            k
        };
        let schedule = schedule.or_else(|| Some(LearnedFeatures::default_schedule(k)));
        ("zoomout", k, schedule)
    } else {
        (refine, k, schedule)
    }
}

/// Puts `learned` into `params` (one start: the starts vary the
/// descriptor solve).
pub(crate) fn apply(params: &mut MatchParams, learned: Option<LearnedFeatures>) {
    if let Some(l) = learned {
        params.starts.sizes.clear();
        params.features = Features::Learned(l);
    }
}

/// Trains a feature extractor on `meshes` (DiffusionNet, unsupervised,
/// the recipe of `fmaps train`) and writes the model file `out`; a
/// checkpoint (`out` with `.checkpoint.npz`) is written every
/// `save_every` steps and a run started again on it continues exactly.
/// Returns the losses of each step run (dicts: step, total, bijectivity,
/// orthogonality, laplacian, coupling).
#[pyfunction]
#[pyo3(signature = (meshes, out, *, steps = 1000, lr = 1e-3, seed = 1, width = 128, blocks = 4, outputs = 256, inputs = 128, eigenpairs = 128, fmap_k = 200, coupling_samples = Some(1000), dropout = true, save_every = 25, threads = None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn train<'py>(
    py: Python<'py>,
    meshes: Vec<PyRef<'py, Mesh>>,
    out: PathBuf,
    steps: u64,
    lr: f64,
    seed: u64,
    width: usize,
    blocks: usize,
    outputs: usize,
    inputs: usize,
    eigenpairs: usize,
    fmap_k: usize,
    coupling_samples: Option<usize>,
    dropout: bool,
    save_every: u64,
    threads: Option<usize>,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    if meshes.len() < 2 {
        return Err(err("train needs at least two meshes"));
    }
    let meshes: Vec<Arc<fmaps::mesh_io::TriMesh>> =
        meshes.iter().map(|m| Arc::clone(&m.inner)).collect();
    let mut recipe = Recipe::default();
    recipe.steps = steps;
    recipe.lr = lr;
    recipe.lr_min = lr / 10.0;
    recipe.seed = seed;
    recipe.fmap_eigenpairs = fmap_k;
    recipe.coupling_samples = coupling_samples;
    recipe.dropout = dropout;
    let arch = Architecture {
        inputs,
        width,
        blocks,
        outputs,
    };
    let pre = Preprocessing {
        eigenpairs,
        ..Preprocessing::default()
    };
    let checkpoint = out.with_extension("checkpoint.npz");
    let records = run(py, threads, move || {
        let model = Model::new(arch, pre, seed);
        let names: Vec<String> = (0..meshes.len()).map(|i| format!("mesh {i}")).collect();
        let mut trainer = if checkpoint.is_file() {
            let t = Trainer::load(&checkpoint).map_err(|e| e.to_string())?;
            if t.recipe != recipe || t.shapes != names || t.model.architecture() != arch {
                return Err(format!(
                    "{}: a checkpoint of another run (remove it to start again)",
                    checkpoint.display()
                ));
            }
            t
        } else {
            Trainer::new(model, recipe.clone(), names.clone()).map_err(|e| e.to_string())?
        };
        let k = eigenpairs.max(fmap_k);
        let shapes = meshes
            .iter()
            .zip(&names)
            .map(|(m, n)| {
                let prepared = trainer
                    .model
                    .prepare(m, k)
                    .map_err(|e| format!("{n}: {e}"))?;
                Ok(TrainShape::from_operators(
                    n,
                    prepared.operators,
                    prepared.input,
                    &recipe,
                ))
            })
            .collect::<Result<Vec<_>, String>>()?;
        let mut records = Vec::new();
        run_training(&mut trainer, &shapes, &checkpoint, save_every, None, |e| {
            if let Event::Step(r) = e {
                records.push(*r);
            }
        })
        .map_err(|e| e.to_string())?;
        trainer.model.save(&out).map_err(|e| e.to_string())?;
        Ok(records)
    })?
    .map_err(err)?;
    records
        .iter()
        .map(|r| {
            let d = PyDict::new(py);
            d.set_item("step", r.step)?;
            d.set_item("total", r.losses.total)?;
            d.set_item("bijectivity", r.losses.bijectivity)?;
            d.set_item("orthogonality", r.losses.orthogonality)?;
            d.set_item("laplacian", r.losses.laplacian)?;
            d.set_item("coupling", r.losses.coupling)?;
            Ok(d)
        })
        .collect()
}
