//! `cargo xtask eval`: the benchmark table. For each collection and each
//! method (today: the published maps in `maps/*.zip`), every test pair (or
//! the first N) is evaluated with exact geodesics; a table goes to stdout
//! and per-pair numbers to `target/eval/<collection>-<method>.json`.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use fmaps::eval::{Collection, EvalParams, evaluate};
use fmaps::geodesic::{DijkstraSolver, DistanceSolver, ExactSolver};
use fmaps::mesh_io::TriMesh;

pub(crate) use crate::collections::collection_pairs;
use crate::collections::farthest_points;
pub(crate) use crate::methods::refiner_method;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;

use crate::util::{bcicp_dir, collections_or_default, root};

/// Options of `cargo xtask eval`.
#[derive(clap::Args)]
pub struct Args {
    /// Collections to evaluate (default: FAUST and TOSCA_Isometric); also
    /// the FAUST splits `FAUST_r` (tr_reg_080..099, all 190 pairs) and
    /// `FAUST_inter` (the test pairs of two different people),
    /// `FAUST_r_ordered` (every ordered pair of tr_reg_080..099, the 20
    /// self-pairs included: the learned papers' 400 pairs); and the
    /// generated bodies (`cargo xtask generate`, built on demand):
    /// `generated-iso` (one individual, two poses), `generated-noniso`
    /// (two individuals of different proportions) and `generated-species`
    /// (two species: proportions and postures of other kinds of body).
    #[arg(long = "collection")]
    collections: Vec<String>,
    /// Only the first N test pairs (default: all; after --offset/--stride).
    /// A subset run writes `target/eval/<collection>-<method>@<offset>[s<stride>][n<N>].json`
    /// so that chunks of one collection do not overwrite each other.
    #[arg(long)]
    pairs: Option<usize>,
    /// Start at the pair of this 0-based index (with --stride: a regular
    /// subset, e.g. `--offset 6 --stride 15` for lines 7, 22, 37, ... of
    /// test_pairs.txt).
    #[arg(long, default_value_t = 0)]
    offset: usize,
    /// Take every STRIDE-th pair from --offset.
    #[arg(long, default_value_t = 1)]
    stride: usize,
    /// Methods (default: every published method found in maps/);
    /// `saved:<COLLECTION>-<METHOD>` evaluates the maps an earlier
    /// `--save-maps` run kept.
    /// Modifiers: `METHOD+sinkhorn` (the refiner converts with the Fast
    /// Sinkhorn Filter), `METHOD+no-stop` (a multi-start ZoomOut runs every
    /// start to the end instead of stopping them at the middle of the
    /// schedule: `fmaps match --select-at none`).
    #[arg(long = "method")]
    methods: Vec<String>,
    /// Dataset directory (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Geodesic method: exact or dijkstra.
    #[arg(long, default_value = "exact")]
    geodesic: String,
    /// Where `pyfm:<stage>` methods are read from: `<DIR>/pyfm-<collection>/`
    /// as written by `../shared/peers/pyfm_pipeline.py --out`.
    #[arg(long, default_value = "target/peers")]
    peer_dir: PathBuf,
    /// Threads for the fmaps pipeline (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Also write every map (`target/eval/maps/<collection>-<method>/<A>_<B>.map`,
    /// 1-based as the dataset's), for `cargo xtask confidence`.
    #[arg(long)]
    save_maps: bool,
}

/// Where the maps of a method come from.
enum MapSource {
    /// A method of the dataset's `maps/*.zip`.
    Published(fmaps::eval::PublishedMaps),
    /// `fmaps-init`, `fmaps-icp`, `fmaps-zoomout[:START:FINAL:STEP][@..]`:
    /// the fmaps pipeline, run here.
    Pipeline(Box<PipelineCache>),
    /// `REFINER@PUBLISHED` (`zoomout`, `zoomout:START:FINAL:STEP`, `icp`):
    /// a refiner run here from the dataset's published maps.
    Refined {
        published: fmaps::eval::PublishedMaps,
        cache: Box<PipelineCache>,
    },
    /// pyFM's maps from `pyfm_pipeline.py` with its per-pair timings.
    PyFm {
        dir: PathBuf,
        seconds: HashMap<(String, String), f64>,
    },
}

/// A map A -> B, its seconds when known, and method details (or null).
/// A method's map of a pair: the map, the seconds it took (when known),
/// the pipeline's report (else null) and the pipeline's initial map.
type MethodMap = (
    Vec<usize>,
    Option<f64>,
    serde_json::Value,
    Option<Vec<usize>>,
);

/// Prepared shapes (eigenbases) reused across pairs, like the peer does.
struct PipelineCache {
    params: fmaps::MatchParams,
    shapes: HashMap<String, fmaps::pipeline::PreparedShape>,
    /// Landmark pairs per pair, taken from the ground truth (`+landmarks=N`).
    landmarks: usize,
}

impl MapSource {
    fn open(c: &Collection, method: &str, peer_dir: &std::path::Path) -> anyhow::Result<MapSource> {
        if method.starts_with("saved:") {
            // The saved maps' directory names the method with its modifiers.
            return MapSource::open_nn(c, method, peer_dir);
        }
        // `METHOD+sinkhorn`: the refiner converts with the Fast Sinkhorn
        // Filter.
        let (method, sinkhorn) = match method.split_once("+sinkhorn") {
            Some((head, tail)) => (format!("{head}{tail}"), true),
            None => (method.to_string(), false),
        };
        // `METHOD+no-stop`: a multi-start ZoomOut runs every start to the
        // end (`fmaps match --select-at none`).
        let (method, no_stop) = match method.split_once("+no-stop") {
            Some((head, tail)) => (format!("{head}{tail}"), true),
            None => (method, false),
        };
        // `METHOD+landmarks=N`: N landmark pairs from the ground truth
        // (farthest points of the truth's source points).
        let (method, landmarks) = match method.split_once("+landmarks=") {
            Some((head, n)) => (
                head.to_string(),
                n.parse::<usize>().context("+landmarks=N")?,
            ),
            None => (method, 0),
        };
        let method = method.as_str();
        let mut source = MapSource::open_nn(c, method, peer_dir)?;
        if landmarks > 0 {
            match &mut source {
                MapSource::Pipeline(cache) => cache.landmarks = landmarks,
                _ => bail!("+landmarks applies to fmaps pipeline methods"),
            }
        }
        if sinkhorn {
            match &mut source {
                MapSource::Pipeline(cache) | MapSource::Refined { cache, .. } => {
                    cache.params.refinement = with_sinkhorn(&cache.params.refinement, method)?;
                }
                _ => bail!("+sinkhorn applies to fmaps pipeline methods and REFINER@PUBLISHED"),
            }
        }
        if no_stop {
            match &mut source {
                MapSource::Pipeline(cache) => cache.params.starts.select_at = None,
                _ => bail!("+no-stop applies to fmaps pipeline methods"),
            }
        }
        Ok(source)
    }

    fn open_nn(
        c: &Collection,
        method: &str,
        peer_dir: &std::path::Path,
    ) -> anyhow::Result<MapSource> {
        if let Some(params) = crate::learn::learned_method(method)? {
            return Ok(MapSource::Pipeline(Box::new(PipelineCache {
                params,
                shapes: HashMap::new(),
                landmarks: 0,
            })));
        }
        if let Some((refine, starts, restart_below)) = pipeline_method(method)? {
            // As `fmaps match`: the stop of the starts, and the eigenpairs
            // the pipeline uses.
            let mut params = fmaps::MatchParams::default();
            params.starts.select_at = fmaps::pipeline::default_select_at(&refine);
            params.refinement = refine;
            params.starts.sizes = starts;
            params.starts.restart_below = restart_below;
            params.k_process = params.k_process_needed();
            return Ok(MapSource::Pipeline(Box::new(PipelineCache {
                params,
                shapes: HashMap::new(),
                landmarks: 0,
            })));
        }
        if let Some((refiner, published)) = method.split_once('@')
            && !method.starts_with("fmaps-")
        {
            let refine = refiner_method(refiner)?;
            let k = match &refine {
                fmaps::pipeline::Refinement::ZoomOut { zoomout, .. } => zoomout.k_start,
                _ => fmaps::MatchParams::default().k,
            };
            let mut params = fmaps::MatchParams::default();
            params.k = k;
            params.k_process = k.max(refine.k_needed());
            params.descriptors.eigenpairs = params.descriptors.eigenpairs.min(params.k_process);
            params.refinement = refine;
            return Ok(MapSource::Refined {
                published: c.published_maps(published)?,
                cache: Box::new(PipelineCache {
                    params,
                    shapes: HashMap::new(),
                    landmarks: 0,
                }),
            });
        }
        if let Some(name) = method.strip_prefix("saved:") {
            // Maps saved by an earlier `--save-maps` run, evaluated again
            // (e.g. with exact geodesics after a Dijkstra run).
            let dir = root().join("target/eval/maps").join(name);
            if !dir.is_dir() {
                bail!(
                    "{} not found: run cargo xtask eval --save-maps first",
                    dir.display()
                );
            }
            return Ok(MapSource::PyFm {
                dir,
                seconds: HashMap::new(),
            });
        }
        if let Some(stage) = method.strip_prefix("pyfm:") {
            let base = root().join(peer_dir).join(format!("pyfm-{}", c.name()));
            let dir = base.join("maps").join(stage);
            if !dir.is_dir() {
                bail!(
                    "{} not found: run ../shared/peers/pyfm_pipeline.py <dataset> --out {} --orient-weight 1 first",
                    dir.display(),
                    base.display()
                );
            }
            let seconds = pyfm_seconds(&base.join("timings.jsonl"), stage)?;
            return Ok(MapSource::PyFm { dir, seconds });
        }
        Ok(MapSource::Published(c.published_maps(method)?))
    }

    /// The map A -> B, the seconds it took to compute (when known) and, for
    /// the pipeline, its orientation score and starts (else null).
    fn map(
        &mut self,
        c: &Collection,
        meshes: &HashMap<String, TriMesh>,
        a: &str,
        b: &str,
    ) -> anyhow::Result<Option<MethodMap>> {
        use serde_json::Value::Null;
        match self {
            MapSource::Published(m) => Ok(m.read(a, b)?.map(|t| (t, None, Null, None))),
            MapSource::PyFm { dir, seconds } => {
                let path = dir.join(format!("{a}_{b}.map"));
                if !path.exists() {
                    return Ok(None);
                }
                let t = fmaps::mesh_io::read_map(&path)?;
                Ok(Some((
                    t,
                    seconds.get(&(a.into(), b.into())).copied(),
                    Null,
                    None,
                )))
            }
            MapSource::Refined { published, cache } => {
                let Some(init) = published.read(a, b)? else {
                    return Ok(None);
                };
                let t = Instant::now();
                cache.prepare(c, meshes, &[a, b])?;
                let r = fmaps::pipeline::refine_point_map(
                    &cache.shapes[a],
                    &cache.shapes[b],
                    &init,
                    &cache.params,
                )
                .with_context(|| format!("{} {a} -> {b}", c.name()))?;
                let info =
                    json!({"orientation": r.orientation, "orientation_init": r.orientation_init});
                Ok(Some((r.t_ab, Some(t.elapsed().as_secs_f64()), info, None)))
            }
            MapSource::Pipeline(cache) => {
                let t = Instant::now();
                for s in [a, b] {
                    if !cache.shapes.contains_key(s) {
                        let p = fmaps::pipeline::prepare(&meshes[s], &cache.params)
                            .with_context(|| format!("{} {s}", c.name()))?;
                        cache.shapes.insert(s.to_string(), p);
                    }
                }
                let mut params = std::borrow::Cow::Borrowed(&cache.params);
                if cache.landmarks > 0 {
                    let (ma, mb) = (&meshes[a], &meshes[b]);
                    let gt = c.ground_truth(a, b, ma.n_vertices(), mb.n_vertices())?;
                    let picked = farthest_points(ma, gt.source(), cache.landmarks);
                    params.to_mut().descriptors.landmarks = picked
                        .iter()
                        .map(|&i| (gt.source()[i], gt.target()[i]))
                        .collect();
                }
                let r =
                    fmaps::pipeline::match_prepared(&cache.shapes[a], &cache.shapes[b], &params)
                        .with_context(|| format!("{} {a} -> {b}", c.name()))?;
                let info = json!({"orientation": r.orientation, "starts": r.starts,
                    "confidence": r.confidence.map(|c| json!({"metric_distortion": c.distortion,
                        "long_range": c.long_range, "likely_wrong": c.likely_wrong})),
                    "landmarks": params.descriptors.landmarks});
                Ok(Some((
                    r.t_ab,
                    Some(t.elapsed().as_secs_f64()),
                    info,
                    Some(r.t_ab_init),
                )))
            }
        }
    }
}

/// The refinement of an fmaps pipeline method, `None` for other methods:
/// `fmaps-default` (what `fmaps match` runs without flags, also called
/// `smooth-shells`), `fmaps-init` (none), `fmaps-icp` (10 iterations), `fmaps-zoomout`
/// (50 -> 150 step 5, pyFM's schedule in `pyfm_pipeline.py`) or
/// `fmaps-zoomout:START:FINAL:STEP`; any of them with `@K1,K2,..` appended
/// adds starts at those initial sizes ([`fmaps::MatchParams::starts`]),
/// and `@K1,K2<SCORE` tries them only when the first map's orientation
/// score is below SCORE ([`fmaps::pipeline::Starts::restart_below`]). The
/// ZoomOut methods start from [`fmaps::pipeline::default_starts`] as
/// well unless told otherwise, as `fmaps match` does; `@none`: one start.
fn pipeline_method(method: &str) -> anyhow::Result<Option<PipelineMethod>> {
    use fmaps::pipeline::Refinement;
    let (method, starts, restart_below) = match method.split_once('@') {
        Some((m, spec)) if m.starts_with("fmaps-") => {
            let (list, below) =
                match spec.split_once('<') {
                    Some((l, t)) => (
                        l,
                        Some(t.parse::<f64>().with_context(|| {
                            format!("method {m}@{spec}: expected @K1,K2,..<SCORE")
                        })?),
                    ),
                    None => (spec, None),
                };
            let starts = if list == "none" {
                Vec::new()
            } else {
                list.split(',')
                    .map(str::parse)
                    .collect::<Result<Vec<usize>, _>>()
                    .with_context(|| format!("method {m}@{spec}: expected @K1,K2,.. or @none"))?
            };
            (m, starts, below)
        }
        _ if method.starts_with("fmaps-zoomout") => (
            method,
            fmaps::pipeline::default_starts(fmaps::pipeline::RefinerKind::Zoomout, usize::MAX),
            None,
        ),
        _ => (method, Vec::new(), None),
    };
    Ok(Some((
        match method {
            "fmaps-init" => Refinement::None,
            "fmaps-icp" => Refinement::Icp(fmaps::refine::Icp::default()),
            "fmaps-zoomout" => Refinement::default_zoomout(),
            // `fmaps match` without flags, also under the refiner's own name.
            "fmaps-default" | "smooth-shells" => Refinement::recommended(),
            // `fmaps match --second-opinion`.
            "fmaps-second-opinion" => {
                let mut options = fmaps::pipeline::RefineOptions::default();
                options.second_opinion = true;
                fmaps::pipeline::named_refinement(
                    fmaps::pipeline::RefinerKind::SmoothShells,
                    &options,
                )?
            }
            "fmaps-bijective-zoomout"
            | "fmaps-discrete"
            | "fmaps-bcicp"
            | "fmaps-smooth-shells" => refiner_method(&method[6..])?,
            m if m.starts_with("fmaps-smooth-shells:") => refiner_method(&m[6..])?,
            m => match m.strip_prefix("fmaps-zoomout:") {
                Some(spec) => Refinement::ZoomOut {
                    zoomout: fmaps::refine::ZoomOut::with_schedule(spec)
                        .with_context(|| format!("method {m}"))?,
                    samples: None,
                },
                None => return Ok(None),
            },
        },
        starts,
        restart_below,
    )))
}

impl PipelineCache {
    /// Prepares (eigenbases) the shapes not prepared yet.
    fn prepare(
        &mut self,
        c: &Collection,
        meshes: &HashMap<String, TriMesh>,
        names: &[&str],
    ) -> anyhow::Result<()> {
        for &s in names {
            if !self.shapes.contains_key(s) {
                let p = fmaps::pipeline::prepare(&meshes[s], &self.params)
                    .with_context(|| format!("{} {s}", c.name()))?;
                self.shapes.insert(s.to_string(), p);
            }
        }
        Ok(())
    }
}

/// The same refinement converting with the Fast Sinkhorn Filter.
fn with_sinkhorn(
    r: &fmaps::pipeline::Refinement,
    method: &str,
) -> anyhow::Result<fmaps::pipeline::Refinement> {
    use fmaps::pipeline::Refinement;
    let p = Some(fmaps::solve::sinkhorn::Sinkhorn::default());
    Ok(match r {
        Refinement::None => bail!("{method}+sinkhorn: the method has no refinement"),
        Refinement::Icp(icp) => Refinement::Icp(fmaps::refine::Icp {
            sinkhorn: p,
            ..*icp
        }),
        Refinement::ZoomOut { zoomout, samples } => Refinement::ZoomOut {
            zoomout: fmaps::refine::ZoomOut {
                sinkhorn: p,
                ..zoomout.clone()
            },
            samples: *samples,
        },
        Refinement::Custom(_) => {
            let preset = method
                .trim_start_matches("fmaps-")
                .split(['@', ':'])
                .next()
                .unwrap_or("");
            let mut d = fmaps::refine::DiscreteOp::preset(preset)?;
            d.sinkhorn = p;
            Refinement::Custom(std::sync::Arc::new(d))
        }
    })
}

/// The refinement, the extra starts and the restart bar of a pipeline method.
type PipelineMethod = (fmaps::pipeline::Refinement, Vec<usize>, Option<f64>);

/// Per-pair seconds of one pyFM stage's map, counted like ours: loading,
/// Laplacians and eigenbases (0 for shapes cached from earlier pairs),
/// descriptors, the fit and the conversion.
fn pyfm_seconds(
    path: &std::path::Path,
    stage: &str,
) -> anyhow::Result<HashMap<(String, String), f64>> {
    let mut out = HashMap::new();
    let Ok(text) = std::fs::read_to_string(path) else {
        return Ok(out);
    };
    let keys: &[&str] = match stage {
        "fm" => &["fit", "p2p"],
        "fm_icp" => &["fit", "p2p", "icp"],
        "fm_zoomout" => &["fit", "p2p", "zoomout"],
        "fm_orient" => &["fit_orient", "p2p_orient"],
        "fm_orient_icp" => &["fit_orient", "p2p_orient", "icp_orient"],
        "fm_orient_zoomout" => &["fit_orient", "p2p_orient", "zoomout_orient"],
        _ => return Ok(out),
    };
    for line in text.lines() {
        let v: serde_json::Value = serde_json::from_str(line)?;
        let t = &v["times"];
        let base: f64 = ["load", "setup", "laplacian", "eig", "descr"]
            .iter()
            .chain(keys)
            .filter_map(|k| t[*k].as_f64())
            .sum();
        let pair = (
            v["pair"][0].as_str().unwrap_or("").to_string(),
            v["pair"][1].as_str().unwrap_or("").to_string(),
        );
        out.insert(pair, base);
    }
    Ok(out)
}

/// The file-name suffix of a run over a subset of the test pairs, so that
/// a long collection can be run in chunks (`--offset 0 --pairs 50`,
/// `--offset 50 --pairs 50`, ...) without one chunk overwriting another:
/// empty for a whole collection.
fn subset_suffix(args: &Args) -> String {
    if args.offset == 0 && args.stride <= 1 && args.pairs.is_none() {
        return String::new();
    }
    let mut s = format!("@{}", args.offset);
    if args.stride > 1 {
        s += &format!("s{}", args.stride);
    }
    if let Some(n) = args.pairs {
        s += &format!("n{n}");
    }
    s
}

pub fn eval(args: &Args) -> anyhow::Result<()> {
    let bcicp = bcicp_dir(args.data.as_deref())?;
    let collections = collections_or_default(&args.collections);
    let out_dir = root().join("target/eval");
    std::fs::create_dir_all(&out_dir)?;
    let params = EvalParams::default();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()?;
    let mut rows = Vec::new();
    for cname in &collections {
        let (c, pairs) = collection_pairs(&bcicp, cname)?;
        let mut pairs: Vec<(String, String)> = pairs
            .into_iter()
            .skip(args.offset)
            .step_by(args.stride.max(1))
            .collect();
        if let Some(n) = args.pairs {
            pairs.truncate(n);
        }
        let methods = if args.methods.is_empty() {
            c.published_methods()?
        } else {
            args.methods.clone()
        };
        let mut meshes: HashMap<String, TriMesh> = HashMap::new();
        for method in &methods {
            let mut maps = MapSource::open(&c, method, &args.peer_dir)
                .with_context(|| format!("method {method} of {cname}"))?;
            let mut map_seconds = Vec::new();
            let bar = ProgressBar::new(pairs.len() as u64).with_style(
                ProgressStyle::with_template(
                    "{msg:32} [{bar:30}] {pos}/{len} {elapsed_precise} eta {eta}",
                )?
                .progress_chars("=> "),
            );
            bar.set_message(format!("{cname} {method}"));
            let mut per_pair = Vec::new();
            let maps_dir = out_dir
                .join("maps")
                .join(format!("{cname}-{method}{}", subset_suffix(args)));
            if args.save_maps {
                std::fs::create_dir_all(&maps_dir)?;
            }
            let mut missing = 0;
            let mut curve_sum = vec![0.0; params.n_thresholds];
            let mut geodesic_name = "";
            let t0 = Instant::now();
            for (a, b) in &pairs {
                bar.inc(1);
                for s in [a, b] {
                    if !meshes.contains_key(s) {
                        meshes.insert(s.clone(), c.read_mesh(s)?);
                    }
                }
                let Some((t_ab, secs, info, init)) =
                    pool.install(|| maps.map(&c, &meshes, a, b))?
                else {
                    missing += 1;
                    continue;
                };
                map_seconds.extend(secs);
                if args.save_maps {
                    fmaps::mesh_io::write_map(maps_dir.join(format!("{a}_{b}.map")), &t_ab)?;
                }
                let (ma, mb) = (&meshes[a], &meshes[b]);
                if t_ab.len() != ma.n_vertices() {
                    bail!(
                        "{method} {a}_{b}.map has {} lines, {a} has {} vertices",
                        t_ab.len(),
                        ma.n_vertices()
                    );
                }
                let gt = c.ground_truth(a, b, ma.n_vertices(), mb.n_vertices())?;
                let solver: Box<dyn DistanceSolver> = match args.geodesic.as_str() {
                    "exact" => Box::new(ExactSolver::new(mb)?),
                    "dijkstra" => Box::new(DijkstraSolver::new(mb)),
                    other => bail!("unknown geodesic method '{other}' (exact, dijkstra)"),
                };
                let r = evaluate(mb, solver.as_ref(), &t_ab, &gt, None, &params)?;
                // With --save-maps, the pipeline's initial map too: which
                // stage went wrong.
                let init_error = match init.filter(|_| args.save_maps) {
                    Some(init) => {
                        fmaps::mesh_io::write_map(
                            maps_dir.join(format!("{a}_{b}.init.map")),
                            &init,
                        )?;
                        Some(evaluate(mb, solver.as_ref(), &init, &gt, None, &params)?.mean_error)
                    }
                    None => None,
                };
                geodesic_name = r.geodesic;
                curve_sum
                    .iter_mut()
                    .zip(&r.curve)
                    .for_each(|(s, c)| *s += c);
                per_pair.push(json!({
                    "source": a, "target": b, "mean_error": r.mean_error, "sym_mean_error": r.sym_mean_error,
                    "auc": r.auc, "coverage": r.coverage, "seconds": r.seconds, "map_seconds": secs,
                    "pipeline": info, "init_mean_error": init_error,
                }));
            }
            bar.finish_and_clear();
            let n = per_pair.len().max(1) as f64;
            let avg = |key: &str| per_pair.iter().filter_map(|p| p[key].as_f64()).sum::<f64>() / n;
            let curve: Vec<f64> = curve_sum.iter().map(|s| s / n).collect();
            let auc = fmaps::eval::area_under(&thresholds(&params), &curve);
            let row = json!({
                "collection": cname, "method": method, "pairs": per_pair.len(), "missing": missing,
                "geodesic": geodesic_name,
                "mean_error": avg("mean_error"), "sym_mean_error": avg("sym_mean_error"), "auc": auc,
                "coverage": avg("coverage"), "seconds_per_pair": t0.elapsed().as_secs_f64() / n,
                "map_seconds_per_pair": if map_seconds.is_empty() { serde_json::Value::Null } else {
                    json!(map_seconds.iter().sum::<f64>() / map_seconds.len() as f64) },
                "threads": if matches!(maps, MapSource::Pipeline(_)) { json!(pool.current_num_threads()) } else { serde_json::Value::Null },
                "thresholds": thresholds(&params), "curve": curve, "per_pair": per_pair,
            });
            let path = out_dir.join(format!("{cname}-{method}{}.json", subset_suffix(args)));
            let tmp = path.with_extension("json.tmp");
            std::fs::write(&tmp, serde_json::to_string_pretty(&row)?)?;
            std::fs::rename(&tmp, &path)?;
            rows.push(row);
        }
    }
    println!(
        "{:<16} {:<24} {:>6} {:>10} {:>10} {:>7} {:>9} {:>9} {:>8}  geodesics",
        "collection",
        "method",
        "pairs",
        "mean x100",
        "sym x100",
        "AUC",
        "coverage",
        "map s",
        "eval s"
    );
    for r in &rows {
        println!(
            "{:<16} {:<24} {:>6} {:>10.3} {:>10.3} {:>7.4} {:>9.4} {:>9} {:>8.2}  {}",
            r["collection"].as_str().unwrap_or(""),
            r["method"].as_str().unwrap_or(""),
            format!(
                "{}{}",
                r["pairs"],
                if r["missing"].as_u64().unwrap_or(0) > 0 {
                    "*"
                } else {
                    ""
                }
            ),
            100.0 * r["mean_error"].as_f64().unwrap_or(f64::NAN),
            100.0 * r["sym_mean_error"].as_f64().unwrap_or(f64::NAN),
            r["auc"].as_f64().unwrap_or(f64::NAN),
            r["coverage"].as_f64().unwrap_or(f64::NAN),
            r["map_seconds_per_pair"]
                .as_f64()
                .map_or("-".to_string(), |v| format!("{v:.3}")),
            r["seconds_per_pair"].as_f64().unwrap_or(f64::NAN),
            r["geodesic"].as_str().unwrap_or(""),
        );
    }
    println!(
        "(* some pairs had no map; errors are d/sqrt(area) x100, AUC of the mean cumulative curve on [0, 0.25];\n \
         map s: seconds per pair to compute the map (shapes prepared once per run, as pyfm_pipeline.py does); eval s: evaluation)"
    );
    for cname in &collections {
        let time = |m: &str| {
            rows.iter()
                .find(|r| r["collection"] == cname.as_str() && r["method"] == m)
                .and_then(|r| r["map_seconds_per_pair"].as_f64())
        };
        for (ours_m, peer_m) in [
            ("fmaps-init", "pyfm:fm_orient"),
            ("fmaps-icp", "pyfm:fm_orient_icp"),
            // The single-start ZoomOut is pyFM's pipeline step for step.
            ("fmaps-zoomout@none", "pyfm:fm_orient_zoomout"),
        ] {
            if let (Some(ours), Some(peer)) = (time(ours_m), time(peer_m)) {
                println!(
                    "{cname}: {ours_m} computes a map {:.1}x faster than pyFM's same pipeline {peer_m} ({ours:.3} s vs {peer:.3} s per pair)",
                    peer / ours
                );
            }
        }
    }
    for cname in &collections {
        let series: Vec<fmaps_viz::plot::Series> = rows
            .iter()
            .filter(|r| r["collection"] == cname.as_str())
            .map(|r| fmaps_viz::plot::Series {
                label: format!(
                    "{} (mean {:.2}, AUC {:.3})",
                    r["method"].as_str().unwrap_or(""),
                    100.0 * r["mean_error"].as_f64().unwrap_or(f64::NAN),
                    r["auc"].as_f64().unwrap_or(f64::NAN)
                ),
                x: serde_json::from_value(r["thresholds"].clone()).unwrap_or_default(),
                y: serde_json::from_value(r["curve"].clone()).unwrap_or_default(),
            })
            .collect();
        let png = out_dir.join(format!("{cname}-curves.png"));
        let title = format!("{cname}: cumulative geodesic error");
        fmaps_viz::plot::cumulative_curves(&title, params.max_threshold, &series).save_png(&png)?;
        println!("curves: {}", png.display());
    }
    println!("per-pair results: {}", out_dir.display());
    Ok(())
}

fn thresholds(p: &EvalParams) -> Vec<f64> {
    (0..p.n_thresholds)
        .map(|j| p.max_threshold * j as f64 / (p.n_thresholds.max(2) - 1) as f64)
        .collect()
}
