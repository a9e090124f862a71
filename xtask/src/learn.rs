//! `cargo xtask train`: `fmaps train` on the FAUST training shapes of the
//! datasets layout (`tr_reg_000`–`tr_reg_079` of the remeshed FAUST; never
//! a test shape), and `cargo xtask learn-eval`: the accuracy of learned
//! features on a collection's test pairs (exact geodesics, the protocol of
//! `cargo xtask eval`), each vertex of A sent to the vertex of B with the
//! most similar features (cosine).

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use anyhow::Context;
use fmaps::eval::{Collection, EvalParams, evaluate};
use fmaps::geodesic::ExactSolver;
use fmaps_learn::model::Model;
use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::util::{data_dir, fmaps_binary, machine_header};

/// Options of `cargo xtask train`.
#[derive(clap::Args)]
pub struct TrainArgs {
    /// The model file written.
    #[arg(long, default_value = "target/train/faust.npz")]
    out: PathBuf,
    /// Datasets folder (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Options passed on to `fmaps train` (after `--`): --steps, --lr, ...
    #[arg(last = true)]
    rest: Vec<String>,
}

/// The FAUST training shapes' names.
pub fn faust_training_shapes() -> Vec<String> {
    (0..80).map(|i| format!("tr_reg_{i:03}")).collect()
}

pub fn train(args: &TrainArgs) -> anyhow::Result<()> {
    let dir = data_dir(args.data.as_deref()).join("bcicp/FAUST/vtx_5k");
    let files: Vec<PathBuf> = faust_training_shapes()
        .iter()
        .map(|s| dir.join(format!("{s}.off")))
        .collect();
    if let Some(f) = files.iter().find(|f| !f.is_file()) {
        anyhow::bail!(
            "{}: missing (see ../shared/datasets/README.md)",
            f.display()
        );
    }
    let out_dir = args.out.parent().unwrap_or(std::path::Path::new("."));
    std::fs::create_dir_all(out_dir)?;
    let commit = Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .output()
        .ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default();
    let mut cmd = Command::new(fmaps_binary()?);
    cmd.arg("--threads")
        .arg(args.threads.to_string())
        .arg("train")
        .args(&files)
        .arg("--out")
        .arg(&args.out)
        .arg("--cache")
        .arg(out_dir.join("operators"))
        .arg("--curve")
        .arg(args.out.with_extension("png"))
        .arg("--provenance")
        .arg(format!("commit={commit}"))
        .arg("--provenance")
        .arg("data=FAUST_r (remeshed FAUST, 5k vertices) tr_reg_000-tr_reg_079, no ground truth read")
        .args(&args.rest);
    println!("{}", machine_header(args.threads));
    let status = cmd.status().context("running fmaps train")?;
    if !status.success() {
        anyhow::bail!("fmaps train failed ({status})");
    }
    Ok(())
}

/// Options of `cargo xtask learn-eval`.
#[derive(clap::Args)]
pub struct EvalArgs {
    /// Model files (`untrained` for a fresh network of the default
    /// architecture, seed 1).
    #[arg(long, required = true)]
    model: Vec<String>,
    /// Collection (`FAUST_r`: the test shapes tr_reg_080-099, all 190
    /// pairs; or any collection of `cargo xtask eval`). Pairs with a FAUST
    /// training shape are refused.
    #[arg(long, default_value = "FAUST_r")]
    collection: String,
    /// Evaluate N pairs spread evenly over the list.
    #[arg(long)]
    pairs: Option<usize>,
    /// Datasets folder (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    data: Option<PathBuf>,
}

/// Rows of `f` scaled to unit length.
fn normalized(f: &DMatrix<f64>) -> DMatrix<f64> {
    let mut g = f.clone();
    for mut r in g.row_iter_mut() {
        let n = r.norm().max(1e-12);
        r /= n;
    }
    g
}

/// For each row of `a`, the row of `b` with the largest dot product.
fn nearest_by_cosine(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Vec<usize> {
    let sim = a * b.transpose();
    (0..sim.nrows())
        .map(|i| sim.row(i).transpose().argmax().0)
        .collect()
}

pub fn learn_eval(args: &EvalArgs) -> anyhow::Result<()> {
    let root = data_dir(args.data.as_deref()).join("bcicp");
    let (c, mut pairs) = crate::eval::collection_pairs(&root, &args.collection)?;
    let training = faust_training_shapes();
    if c.name() == "FAUST"
        && let Some((a, b)) = pairs
            .iter()
            .find(|(a, b)| training.contains(a) || training.contains(b))
    {
        anyhow::bail!(
            "{}: the pair {a} {b} has a FAUST training shape; evaluate on FAUST_r",
            args.collection
        );
    }
    if let Some(n) = args.pairs.filter(|&n| n < pairs.len()) {
        let len = pairs.len();
        pairs = (0..n).map(|i| pairs[i * len / n].clone()).collect();
    }
    let mut shapes: Vec<String> = pairs
        .iter()
        .flat_map(|(a, b)| [a.clone(), b.clone()])
        .collect();
    shapes.sort();
    shapes.dedup();
    println!("{}", machine_header(rayon::current_num_threads()));
    println!(
        "{}: {} test pairs, {} shapes; map: nearest features (cosine); error x100, exact geodesics",
        args.collection,
        pairs.len(),
        shapes.len()
    );
    for m in &args.model {
        let model = if m == "untrained" {
            Model::new(Default::default(), Default::default(), 1)
        } else {
            Model::load(m)?
        };
        let t = Instant::now();
        let feats: Vec<(String, DMatrix<f64>)> = shapes
            .par_iter()
            .map(|s| -> anyhow::Result<_> {
                let mesh = c.read_mesh(s)?;
                Ok((s.clone(), normalized(&model.features(&mesh)?)))
            })
            .collect::<anyhow::Result<_>>()?;
        let features_s = t.elapsed().as_secs_f64();
        let get = |s: &str| &feats.iter().find(|(n, _)| n == s).expect("computed").1;
        let errors: Vec<f64> = pairs
            .par_iter()
            .map(|(a, b)| -> anyhow::Result<f64> {
                let (ma, mb) = (c.read_mesh(a)?, c.read_mesh(b)?);
                let gt = c.ground_truth(a, b, ma.n_vertices(), mb.n_vertices())?;
                let t_ab = nearest_by_cosine(get(a), get(b));
                let solver = ExactSolver::new(&mb)?;
                let r = evaluate(&mb, &solver, &t_ab, &gt, None, &EvalParams::default())?;
                Ok(r.mean_error * 100.0)
            })
            .collect::<anyhow::Result<_>>()?;
        let mean = errors.iter().sum::<f64>() / errors.len().max(1) as f64;
        let worst = errors.iter().cloned().fold(0.0, f64::max);
        println!(
            "{m}: mean {mean:.2}, worst pair {worst:.2} ({} pairs; features {features_s:.1} s)",
            errors.len()
        );
    }
    Ok(())
}

/// Options of `cargo xtask learn-parity`.
#[derive(clap::Args)]
pub struct ParityArgs {
    /// Folder the arrays are written to (then run
    /// `crates/learn/peers/parity.py FOLDER` in a venv with torch and geomfum).
    #[arg(long, default_value = "target/learn-parity")]
    out: PathBuf,
    /// The model (default: a fresh network of the default architecture,
    /// seed 1, its diffusion times set to a spread of values).
    #[arg(long)]
    model: Option<PathBuf>,
    /// The two FAUST shapes of the pair.
    #[arg(long, default_values_t = ["tr_reg_080".to_string(), "tr_reg_081".to_string()])]
    shapes: Vec<String>,
    /// Datasets folder (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    data: Option<PathBuf>,
}

fn save_matrix(path: &std::path::Path, m: &DMatrix<f64>) -> anyhow::Result<()> {
    fmaps::mesh_io::npy::save_f64(path, &[m.nrows(), m.ncols()], m.as_slice())?;
    Ok(())
}

fn save_vector(path: &std::path::Path, v: &[f64]) -> anyhow::Result<()> {
    fmaps::mesh_io::npy::save_f64(path, &[v.len()], v)?;
    Ok(())
}

/// Writes what the PyTorch parity check needs: per shape the operators,
/// the input and our features (no dropout); for the pair our maps, losses
/// (every vertex in the coupling loss) and every parameter's gradient.
pub fn learn_parity(args: &ParityArgs) -> anyhow::Result<()> {
    use fmaps_learn::train::{Recipe, TrainShape, pair_loss_full};
    let root = data_dir(args.data.as_deref()).join("bcicp");
    let c = Collection::open(&root, "FAUST")?;
    let model = match &args.model {
        Some(p) => Model::load(p)?,
        None => {
            let mut m = Model::new(Default::default(), Default::default(), 1);
            // Times spread over the spectrum's scales, so the diffusion
            // matters in the comparison.
            for (b, block) in m.net.blocks.iter_mut().enumerate() {
                let n = block.diffusion.times.len();
                for (i, t) in block.diffusion.times.iter_mut().enumerate() {
                    *t = 1e-4 * 10f64.powf(3.0 * (i + b) as f64 / n as f64);
                }
            }
            m
        }
    };
    let mut recipe = Recipe::default();
    recipe.coupling_samples = None;
    recipe.weights.laplacian = 0.001;
    std::fs::create_dir_all(&args.out)?;
    model.save(args.out.join("model.npz"))?;
    let mut shapes = Vec::new();
    for (tag, name) in ["x", "y"].iter().zip(&args.shapes) {
        let mesh = c.read_mesh(name)?;
        let s = TrainShape::new(name, &mesh, &model, &recipe)?;
        let ops = s.operators();
        let o = |f: &str| args.out.join(format!("{tag}_{f}.npy"));
        save_vector(&o("mass"), ops.mass.as_slice())?;
        save_vector(&o("evals"), ops.eigenvalues.as_slice())?;
        save_matrix(&o("evecs"), &ops.eigenvectors)?;
        for (g, m) in [("gradX", &ops.grad_x), ("gradY", &ops.grad_y)] {
            let (mut r, mut cidx, mut v) = (Vec::new(), Vec::new(), Vec::new());
            for (i, row) in m.outer_iterator().enumerate() {
                for (j, val) in row.iter() {
                    r.push(i as f64);
                    cidx.push(j as f64);
                    v.push(*val);
                }
            }
            save_vector(&o(&format!("{g}_rows")), &r)?;
            save_vector(&o(&format!("{g}_cols")), &cidx)?;
            save_vector(&o(&format!("{g}_vals")), &v)?;
        }
        save_matrix(&o("input"), s.input())?;
        shapes.push(s);
    }
    let p = pair_loss_full(
        &model,
        &recipe,
        &shapes[0],
        &shapes[1],
        &mut fmaps_learn::network::SplitMix(1),
        false,
    )?;
    save_matrix(&args.out.join("x_features.npy"), &p.features.0)?;
    save_matrix(&args.out.join("y_features.npy"), &p.features.1)?;
    save_matrix(&args.out.join("cxy.npy"), &p.maps.0)?;
    save_matrix(&args.out.join("cyx.npy"), &p.maps.1)?;
    let mut grad = p.grad.clone();
    let names: Vec<(String, Vec<usize>)> = model
        .net
        .params()
        .into_iter()
        .map(|q| (q.name, q.shape))
        .collect();
    for ((name, shape), g) in names.iter().zip(grad.groups_mut()) {
        let m = if shape.len() == 2 {
            DMatrix::from_column_slice(shape[0], shape[1], g)
        } else {
            DMatrix::from_column_slice(shape[0], 1, g)
        };
        save_matrix(&args.out.join(format!("grad.{name}.npy")), &m)?;
    }
    let meta = serde_json::json!({
        "losses": p.losses,
        "recipe": recipe,
        "eigenpairs_net": model.preprocessing.eigenpairs,
        "shapes": args.shapes,
    });
    std::fs::write(
        args.out.join("pair.json"),
        serde_json::to_string_pretty(&meta)?,
    )?;
    println!(
        "wrote {} (losses: {})",
        args.out.display(),
        serde_json::to_string(&p.losses)?
    );
    Ok(())
}

/// `learned[:KEY=VALUE,..]`: the pipeline with learned features (the
/// shipped model unless `model=PATH`), keys `adapt=N` (test-time
/// adaptation steps), `lr=X` (their learning rate), `dirichlet=W` (the
/// weight of the Dirichlet term in them), `map=features|spectral`
/// (the initial point map), `k=K` (the map's size, 50), `refine=REFINER`
/// (a refiner of `REFINER@PUBLISHED`, or `default` for what `fmaps match`
/// runs by default; none without), `second-opinion=true` (the default
/// descriptor pipeline too, the least area-distorting map kept: `fmaps
/// match --features learned --second-opinion`); `None` for other methods.
pub(crate) fn learned_method(method: &str) -> anyhow::Result<Option<fmaps::MatchParams>> {
    use fmaps::pipeline::{Features, LearnedFeatures, Refinement};
    let Some(rest) = method.strip_prefix("learned") else {
        return Ok(None);
    };
    let list = match rest.strip_prefix(':') {
        Some(l) => l,
        None if rest.is_empty() => "",
        None => return Ok(None),
    };
    let mut learned = LearnedFeatures::shipped()?;
    let mut params = fmaps::MatchParams::unrefined();
    let mut second_opinion = false;
    for kv in list.split(',').filter(|s| !s.is_empty()) {
        let (k, v) = kv
            .split_once('=')
            .with_context(|| format!("{method}: expected KEY=VALUE, got '{kv}'"))?;
        match k {
            "model" => {
                learned.model = std::sync::Arc::new(
                    fmaps::learn::model::Model::load(v).with_context(|| method.to_string())?,
                )
            }
            "adapt" => learned.adaptation.steps = v.parse().with_context(|| kv.to_string())?,
            "lr" => learned.adaptation.lr = v.parse().with_context(|| kv.to_string())?,
            "second-opinion" => second_opinion = v.parse().with_context(|| kv.to_string())?,
            "dirichlet" => {
                learned.adaptation.recipe.weights.dirichlet =
                    v.parse().with_context(|| kv.to_string())?
            }
            "map" => learned.point_map = v.parse().map_err(anyhow::Error::msg)?,
            "k" => params.k = v.parse().with_context(|| kv.to_string())?,
            "refine" => {
                params.refinement = match v {
                    "default" => Refinement::recommended(),
                    r => crate::eval::refiner_method(r)?,
                }
            }
            _ => anyhow::bail!(
                "{method}: unknown key '{k}' (model, adapt, lr, dirichlet, map, k, refine, second-opinion)"
            ),
        }
    }
    params.features = Features::Learned(learned);
    params.k_process = params.k_process_needed();
    if second_opinion {
        // The benchmarks' meshes have thousands of vertices: the default
        // refinement applies.
        params = params.with_axiomatic_opinion(5000, 5000)?;
    }
    Ok(Some(params))
}
