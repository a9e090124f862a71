//! `fmaps train`: unsupervised training of a DiffusionNet feature
//! extractor on a collection of meshes (no ground truth read), resumable.

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::anyhow;
use fmaps::learn::model::{Architecture, Input, Model, Preprocessing};
use fmaps::learn::train::{self, Event, Recipe, Rotation, StepRecord, TrainShape, Trainer};
use fmaps::mesh_io::TriMesh;
use fmaps::viz::plot::{Plot, Series, line_plot};
use rayon::prelude::*;

use crate::{Failure, input, runtime};

#[derive(clap::Args)]
pub(crate) struct TrainArgs {
    /// Training meshes: mesh files, folders (every .off, .obj and .ply in
    /// them) or a .txt list with one mesh name per line, or two per line
    /// for the pairs to train on.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Folder the names of a .txt list are in (default: the list's
    /// folder); a name may leave out its extension.
    #[arg(long)]
    data: Option<PathBuf>,
    /// The model file written at the end (an .npz archive; see the
    /// fmaps-learn docs for its format).
    #[arg(long)]
    out: PathBuf,
    /// The checkpoint: resumed from when it exists, written every
    /// --save-every steps (default: the model's name with .checkpoint.npz).
    #[arg(long)]
    checkpoint: Option<PathBuf>,
    /// Pair steps.
    #[arg(long, default_value_t = 1000)]
    steps: u64,
    /// Initial learning rate (cosine schedule down to --lr-min).
    #[arg(long, default_value_t = 1e-3)]
    lr: f64,
    /// Final learning rate.
    #[arg(long, default_value_t = 1e-4)]
    lr_min: f64,
    /// Seed of the weights and of every random draw.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Vertices per shape the coupling loss samples each step, or `all`.
    #[arg(long, default_value = "1000")]
    coupling_samples: String,
    /// Eigenpairs of the functional maps.
    #[arg(long, default_value_t = 200)]
    fmap_k: usize,
    /// Weight of the Laplacian-commutativity loss.
    #[arg(long, default_value_t = 0.0)]
    w_lap: f64,
    /// No dropout in the blocks' MLPs (the reference trains with it).
    #[arg(long)]
    no_dropout: bool,
    /// Bound on the gradients' global norm.
    #[arg(long)]
    clip: Option<f64>,
    /// Width of the network's blocks.
    #[arg(long, default_value_t = 128)]
    width: usize,
    /// Number of blocks.
    #[arg(long, default_value_t = 4)]
    blocks: usize,
    /// Output features.
    #[arg(long, default_value_t = 256)]
    outputs: usize,
    /// The network's input: the WKS (intrinsic) or the vertex
    /// coordinates (augmented by --rotation and random scales 0.9-1.1).
    #[arg(long, value_enum, default_value_t = InputArg::Wks)]
    input: InputArg,
    /// Input features when --input wks (WKS energies).
    #[arg(long, default_value_t = 128)]
    inputs_wks: usize,
    /// Random rotations of coordinate inputs while training.
    #[arg(long, value_enum, default_value_t = RotationArg::Any)]
    rotation: RotationArg,
    /// Eigenpairs of the network's diffusion and of the WKS.
    #[arg(long, default_value_t = 128)]
    eigenpairs: usize,
    /// Write the checkpoint every this many steps.
    #[arg(long, default_value_t = 25)]
    save_every: u64,
    /// Run at most this many steps now, then save and stop (run again to
    /// continue).
    #[arg(long)]
    stop_after: Option<u64>,
    /// Folder caching each mesh's operators (eigenpairs, gradients).
    #[arg(long)]
    cache: Option<PathBuf>,
    /// Picture of the loss curves (PNG), redrawn at every checkpoint.
    #[arg(long)]
    curve: Option<PathBuf>,
    /// Extra provenance of the model file, KEY=VALUE (repeatable).
    #[arg(long, value_name = "KEY=VALUE")]
    provenance: Vec<String>,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum InputArg {
    Wks,
    Xyz,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum RotationArg {
    Any,
    Y,
    None,
}

pub(crate) fn train_cmd(args: &TrainArgs) -> Result<(), Failure> {
    let started = Instant::now();
    let samples = match args.coupling_samples.as_str() {
        "all" => None,
        s => Some(s.parse::<usize>().ok().filter(|&n| n > 0).ok_or_else(|| {
            input(anyhow!(
                "--coupling-samples {s}: expected a positive count or `all`"
            ))
        })?),
    };
    let mut recipe = Recipe::default();
    recipe.steps = args.steps;
    recipe.lr = args.lr;
    recipe.lr_min = args.lr_min;
    recipe.seed = args.seed;
    recipe.coupling_samples = samples;
    recipe.fmap_eigenpairs = args.fmap_k;
    recipe.weights.laplacian = args.w_lap;
    recipe.clip = args.clip;
    recipe.dropout = !args.no_dropout;
    recipe.augment.rotation = match args.rotation {
        RotationArg::Any => Rotation::Any,
        RotationArg::Y => Rotation::Y,
        RotationArg::None => Rotation::None,
    };
    let (input_kind, inputs) = match args.input {
        InputArg::Wks => (Input::Wks, args.inputs_wks),
        InputArg::Xyz => (Input::Xyz, 3),
    };
    let arch = Architecture {
        inputs,
        width: args.width,
        blocks: args.blocks,
        outputs: args.outputs,
    };
    let pre = Preprocessing {
        input: input_kind,
        eigenpairs: args.eigenpairs,
        ..Preprocessing::default()
    };
    let mut extra = BTreeMap::new();
    for kv in &args.provenance {
        let (k, v) = kv
            .split_once('=')
            .ok_or_else(|| input(anyhow!("--provenance {kv}: expected KEY=VALUE")))?;
        extra.insert(k.to_string(), v.to_string());
    }
    let (files, pairs) = training_files(&args.inputs, args.data.as_deref())?;
    let names = shape_names(&files)?;
    let checkpoint = args
        .checkpoint
        .clone()
        .unwrap_or_else(|| default_checkpoint(&args.out));
    for out in [Some(&args.out), Some(&checkpoint), args.curve.as_ref()]
        .into_iter()
        .flatten()
    {
        fmaps::mesh_io::atomic::output_target(out)
            .map_err(|e| input(anyhow!("{}: cannot write there: {e}", out.display())))?;
    }
    let mut trainer = if checkpoint.exists() {
        let t = Trainer::load(&checkpoint).map_err(input)?;
        if t.recipe != recipe || t.model.architecture() != arch || t.model.preprocessing != pre {
            return Err(input(anyhow!(
                "{}: a checkpoint of another run (recipe {}); pass that run's options, or another --checkpoint",
                checkpoint.display(),
                serde_json::to_string(&t.recipe).unwrap_or_default()
            )));
        }
        if t.shapes != names || t.pairs != pairs {
            return Err(input(anyhow!(
                "{}: a checkpoint of a run on other shapes ({} shapes, {} pairs)",
                checkpoint.display(),
                t.shapes.len(),
                t.pairs.len()
            )));
        }
        eprintln!(
            "resuming {} at step {} of {}",
            checkpoint.display(),
            t.step,
            t.recipe.steps
        );
        t
    } else {
        let model = Model::new(arch, pre, recipe.seed);
        let mut t = Trainer::new(model, recipe.clone(), names.clone()).map_err(input)?;
        t.pairs = pairs;
        t
    };
    let shapes = prepare(&files, &names, &trainer, args.cache.as_deref())?;
    let tty = std::io::stderr().is_terminal();
    let bar = indicatif::ProgressBar::new(trainer.recipe.steps);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{bar:30} {pos}/{len} steps  {elapsed} (ETA {eta})  {msg}",
    ) {
        bar.set_style(style);
    }
    bar.set_position(trainer.step);
    bar.reset_eta();
    let run_start = (Instant::now(), trainer.step);
    let print_every = args.save_every.max(1);
    let total = trainer.recipe.steps;
    let mut history_for_curve: Vec<StepRecord> = trainer.history.clone();
    let curve = args.curve.clone();
    let result = train::run(
        &mut trainer,
        &shapes,
        &checkpoint,
        args.save_every,
        args.stop_after,
        |e| match e {
            Event::Step(r) => {
                history_for_curve.push(*r);
                let msg = loss_line(r);
                bar.set_position(r.step);
                bar.set_message(msg.clone());
                if !tty && (r.step % print_every == 0 || r.step == total) {
                    let (t0, s0) = run_start;
                    let per = t0.elapsed().as_secs_f64() / (r.step - s0).max(1) as f64;
                    eprintln!(
                        "step {}/{total}  {msg}  {per:.2} s/step  ETA {}",
                        r.step,
                        hms(per * (total - r.step) as f64)
                    );
                }
            }
            Event::Saved(_) => {
                if let Some(c) = &curve {
                    // A picture that cannot be written does not stop training.
                    if let Err(e) = save_curve(c, &history_for_curve) {
                        eprintln!("warning: {}: {e}", c.display());
                    }
                }
            }
        },
    );
    bar.finish_and_clear();
    result.map_err(|e| match e {
        fmaps::learn::Error::NonFinite { .. } => runtime(e),
        fmaps::learn::Error::Write { .. } => runtime(e),
        other => input(other),
    })?;
    let (t0, s0) = run_start;
    let steps_now = trainer.step - s0;
    if steps_now > 0 {
        eprintln!(
            "{steps_now} steps in {:.1} s ({:.3} steps/s)",
            t0.elapsed().as_secs_f64(),
            steps_now as f64 / t0.elapsed().as_secs_f64()
        );
    }
    if !trainer.finished() {
        eprintln!(
            "stopped at step {} of {}: run the same command again to continue from {}",
            trainer.step,
            trainer.recipe.steps,
            checkpoint.display()
        );
        return Ok(());
    }
    let mut model = trainer.model.clone();
    model.provenance = trainer.provenance();
    model.provenance.insert(
        "command".into(),
        std::env::args().collect::<Vec<_>>().join(" "),
    );
    model
        .provenance
        .insert("fmaps_version".into(), env!("CARGO_PKG_VERSION").into());
    model.provenance.insert("cpu".into(), cpu_model());
    model
        .provenance
        .insert("threads".into(), rayon::current_num_threads().to_string());
    model.provenance.insert(
        "last_session_seconds".into(),
        format!("{:.0}", started.elapsed().as_secs_f64()),
    );
    model.provenance.extend(extra);
    model.save(&args.out).map_err(runtime)?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

/// `loss 1.23 (bij 0.1, orth 0.2, couple 0.9)`.
fn loss_line(r: &StepRecord) -> String {
    let l = r.losses;
    let mut s = format!(
        "loss {:.4} (bij {:.4}, orth {:.4}, couple {:.4}",
        l.total, l.bijectivity, l.orthogonality, l.coupling
    );
    if l.laplacian != 0.0 {
        s.push_str(&format!(", lap {:.4}", l.laplacian));
    }
    s.push(')');
    s
}

fn hms(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
}

fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string())
}

/// `model.npz` -> `model.checkpoint.npz`.
fn default_checkpoint(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map_or_else(|| "model".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}.checkpoint.npz"))
}

const MESH_EXTENSIONS: [&str; 3] = ["off", "obj", "ply"];

fn is_mesh(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| MESH_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// Pairs of training shapes (indices).
type Pairs = Vec<(usize, usize)>;

/// The mesh files named by the inputs, and the pairs of a pairs list
/// (indices into the files; empty: every pair).
fn training_files(
    inputs: &[PathBuf],
    data: Option<&Path>,
) -> Result<(Vec<PathBuf>, Pairs), Failure> {
    let mut files: Vec<PathBuf> = Vec::new();
    let mut pairs = Vec::new();
    let index_of = |files: &mut Vec<PathBuf>, p: PathBuf| -> usize {
        files.iter().position(|f| *f == p).unwrap_or_else(|| {
            files.push(p);
            files.len() - 1
        })
    };
    for inp in inputs {
        if inp.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(inp)
                .map_err(|e| input(anyhow!("{}: {e}", inp.display())))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && is_mesh(p))
                .collect();
            found.sort();
            if found.is_empty() {
                return Err(input(anyhow!(
                    "{}: no .off, .obj or .ply mesh in this folder",
                    inp.display()
                )));
            }
            for f in found {
                index_of(&mut files, f);
            }
        } else if inp.extension().is_some_and(|e| e == "txt") {
            let text = std::fs::read_to_string(inp)
                .map_err(|e| input(anyhow!("{}: {e}", inp.display())))?;
            let dir = data
                .map(Path::to_path_buf)
                .unwrap_or_else(|| inp.parent().unwrap_or(Path::new(".")).to_path_buf());
            for (l, line) in text.lines().enumerate() {
                let line = line.split('#').next().unwrap_or("").trim();
                if line.is_empty() {
                    continue;
                }
                let words: Vec<&str> = line.split_whitespace().collect();
                if words.len() > 2 {
                    return Err(input(anyhow!(
                        "{}:{}: expected one mesh name, or two for a pair",
                        inp.display(),
                        l + 1
                    )));
                }
                let mut idx = Vec::new();
                for w in &words {
                    let f = resolve(&dir, w).ok_or_else(|| {
                        input(anyhow!(
                            "{}:{}: no mesh `{w}` in {}",
                            inp.display(),
                            l + 1,
                            dir.display()
                        ))
                    })?;
                    idx.push(index_of(&mut files, f));
                }
                if let [a, b] = idx[..] {
                    if a == b {
                        return Err(input(anyhow!(
                            "{}:{}: a pair of a shape with itself",
                            inp.display(),
                            l + 1
                        )));
                    }
                    pairs.push((a, b));
                }
            }
        } else if inp.is_file() {
            index_of(&mut files, inp.clone());
        } else {
            return Err(input(anyhow!("{}: no such file or folder", inp.display())));
        }
    }
    if files.len() < 2 {
        return Err(input(anyhow!(
            "{} training mesh(es): training needs at least two",
            files.len()
        )));
    }
    Ok((files, pairs))
}

/// `dir/name`, or with a mesh extension added.
fn resolve(dir: &Path, name: &str) -> Option<PathBuf> {
    let p = dir.join(name);
    if p.is_file() {
        return Some(p);
    }
    MESH_EXTENSIONS
        .iter()
        .map(|e| dir.join(format!("{name}.{e}")))
        .find(|p| p.is_file())
}

/// The file stems, which must differ (a checkpoint records them).
fn shape_names(files: &[PathBuf]) -> Result<Vec<String>, Failure> {
    let names: Vec<String> = files
        .iter()
        .map(|f| {
            f.file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
        })
        .collect();
    for (i, n) in names.iter().enumerate() {
        if let Some(j) = names[..i].iter().position(|m| m == n) {
            return Err(input(anyhow!(
                "{} and {}: two training meshes named `{n}`",
                files[j].display(),
                files[i].display()
            )));
        }
    }
    Ok(names)
}

/// Reads every mesh and computes its operators and input (in parallel,
/// through the cache when given).
fn prepare(
    files: &[PathBuf],
    names: &[String],
    trainer: &Trainer,
    cache: Option<&Path>,
) -> Result<Vec<TrainShape>, Failure> {
    let spinner = crate::Spinner::new(format!("preparing {} meshes", files.len()));
    let model = &trainer.model;
    let recipe = &trainer.recipe;
    let out: Result<Vec<TrainShape>, Failure> = files
        .par_iter()
        .zip(names)
        .map(|(f, name)| {
            let mesh: TriMesh = crate::load(f)?;
            let on = crate::input_on(f);
            let p = match cache {
                Some(dir) => model
                    .prepare_cached(&mesh, recipe.fmap_eigenpairs, dir)
                    .map_err(on)?,
                None => model.prepare(&mesh, recipe.fmap_eigenpairs).map_err(on)?,
            };
            Ok(TrainShape::from_operators(
                name,
                p.operators,
                p.input,
                recipe,
            ))
        })
        .collect();
    drop(spinner);
    out
}

/// The loss curves (each term and the total, averaged over windows of
/// steps) as a PNG.
fn save_curve(path: &Path, history: &[StepRecord]) -> anyhow::Result<()> {
    if history.is_empty() {
        return Ok(());
    }
    let window = (history.len() / 100).max(1);
    let mut series: Vec<Series> = Vec::new();
    type Pick = fn(&StepRecord) -> f64;
    let terms: [(&str, Pick); 4] = [
        ("total", |r| r.losses.total),
        ("bijectivity", |r| r.losses.bijectivity),
        ("orthogonality", |r| r.losses.orthogonality),
        ("coupling", |r| r.losses.coupling),
    ];
    let mut ymax: f64 = 0.0;
    for (label, pick) in terms {
        let (mut x, mut y) = (Vec::new(), Vec::new());
        for chunk in history.chunks(window) {
            let mean = chunk.iter().map(pick).sum::<f64>() / chunk.len() as f64;
            x.push(chunk.last().map_or(0.0, |r| r.step as f64));
            y.push(mean);
            ymax = ymax.max(mean);
        }
        series.push(Series {
            label: label.into(),
            x,
            y,
        });
    }
    let last = history.last().map_or(1.0, |r| r.step as f64).max(1.0);
    // Ticks at multiples of 1, 2 or 5 times a power of ten, the axis
    // ending on one.
    let nice = |max: f64| {
        let raw = max.max(1e-12) / 5.0;
        let p = 10f64.powf(raw.log10().floor());
        let step = [1.0, 2.0, 5.0, 10.0]
            .into_iter()
            .map(|m| m * p)
            .find(|&s| s >= raw)
            .unwrap_or(10.0 * p);
        let top = (max / step).ceil().max(1.0) * step;
        (top, step)
    };
    let (ymax, ystep) = nice(ymax);
    let (xmax, xstep) = nice(last);
    let ticks = |max: f64, step: f64| {
        (0..)
            .map(|i| i as f64 * step)
            .take_while(|&t| t <= max + step * 1e-9)
            .collect::<Vec<_>>()
    };
    let plot = Plot {
        title: "training losses (window means)",
        x_label: "step",
        y_label: "loss",
        x_range: (0.0, xmax),
        y_range: (0.0, ymax),
        x_ticks: ticks(xmax, xstep),
        y_ticks: ticks(ymax, ystep),
    };
    let png = line_plot(&plot, &series).to_png()?;
    fmaps::mesh_io::atomic::write_atomically(path, |w| w.write_all(&png))?;
    Ok(())
}

/// The learned features `fmaps match --features`, `--adapt` and
/// `--point-map` ask
/// for (`None`: descriptors).
pub(crate) fn learned_features(
    features: &str,
    adapt: Option<usize>,
    point_map: Option<fmaps::pipeline::LearnedPointMap>,
) -> Result<Option<fmaps::pipeline::LearnedFeatures>, Failure> {
    use fmaps::pipeline::LearnedFeatures;
    let mut learned = match features.split_once('=') {
        None if features == "descriptors" => None,
        None if features == "learned" => Some(LearnedFeatures::shipped().map_err(runtime)?),
        Some(("learned", file)) if !file.is_empty() => {
            let model = fmaps::learn::model::Model::load(file).map_err(input)?;
            Some(LearnedFeatures::new(std::sync::Arc::new(model)))
        }
        _ => {
            return Err(input(anyhow::anyhow!(
                "--features '{}': expected descriptors, learned or learned=MODEL",
                features
            )));
        }
    };
    match &mut learned {
        Some(l) => {
            if let Some(n) = adapt {
                l.adaptation.steps = n;
            }
            if let Some(m) = point_map {
                l.point_map = m;
            }
        }
        None => {
            if adapt.is_some() || point_map.is_some() {
                return Err(input(anyhow::anyhow!(
                    "--adapt and --point-map apply to learned features (--features learned)"
                )));
            }
        }
    }
    Ok(learned)
}
