//! `fmaps match`: two meshes to a point map (and C).

use super::*;

use fmaps::pipeline::MatchParams;
use fmaps::refine::Icp;
use fmaps::refine::starts::StartSelection;

/// The library's defaults, which the flags show and use.
fn defaults() -> MatchParams {
    MatchParams::default()
}

/// Options of `fmaps match`.
#[derive(clap::Args)]
pub(crate) struct MatchArgs {
    /// Source mesh A (.off, .obj, .ply).
    source: PathBuf,
    /// Target mesh B.
    target: PathBuf,
    /// Output map T: A -> B, one B vertex per A vertex: 1-based text (the
    /// datasets' .map format), or 0-based int64 in FILE.npy / FILE.npz.
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Size of the functional map (k x k).
    #[arg(long, short = 'k', default_value_t = defaults().k)]
    k: usize,
    /// Eigenpairs computed per shape (at least what the refinement
    /// needs). Default: those the pipeline uses (`k_process_needed`: 200
    /// for the default Smooth Shells, 150 for ZoomOut 50:150, 128 without
    /// refinement).
    #[arg(long)]
    k_process: Option<usize>,
    /// Descriptor family.
    #[arg(long, default_value_t = defaults().descriptors.kind)]
    descriptor: fmaps::pipeline::DescriptorKind,
    /// Descriptor samples (WKS energies or HKS times).
    #[arg(long, default_value_t = defaults().descriptors.n)]
    n_descr: usize,
    /// Landmark file: one pair `a b` of 1-based vertex indices (source,
    /// target) per line, or one index used on both shapes. They enter the
    /// descriptors, and with three or more Smooth Shells takes its rigid
    /// alignment from them (no orientation search): the way out of a map
    /// aligned the wrong way round.
    #[arg(long)]
    landmarks: Option<PathBuf>,
    #[command(flatten)]
    weights: crate::weights::WeightFlags,
    #[command(flatten)]
    pub(crate) descr_files: crate::descr_files::DescriptorFiles,
    /// Refinement of the initial map. Default: smooth-shells (the most
    /// accurate here, near-isometric and non-isometric; docs/benchmarks.md),
    /// or zoomout when only --zoomout is given; `none` keeps the initial
    /// map.
    #[arg(long, value_parser = refiner_kind_parser())]
    refine: Option<fmaps::pipeline::RefinerKind>,
    #[command(flatten)]
    pub(crate) refiner: RefinerFlags,
    /// Multi-start: also run from initial maps of these sizes and keep
    /// one final map by --select; `none` for a single start. Default:
    /// `8,20` with --refine zoomout, bijective-zoomout or discrete
    /// (measured: fewer swapped parts, docs/benchmarks.md), none otherwise.
    #[arg(long, value_name = "K1,K2,..|none")]
    starts: Option<String>,
    /// With several starts: keep the final map of lowest area distortion
    /// (default; measured, docs/benchmarks.md), of lowest conformal distortion, or
    /// of best orientation.
    #[arg(long, value_enum, default_value_t = SelectKind::Area)]
    select: SelectKind,
    /// With several starts: try the further starts only when the first
    /// map's orientation score is below this (well-oriented pairs cost one
    /// run).
    #[arg(long, value_name = "SCORE")]
    restart_below: Option<f64>,
    /// With several starts and a ZoomOut schedule: stop every start's
    /// ZoomOut at size K, keep the best start there (by --select) and
    /// finish only that one. Default: the middle of the schedule (100 for
    /// 50:150:5); `none`: every start runs to the end.
    #[arg(long, value_name = "K|none")]
    select_at: Option<String>,
    /// B is a mirror image of A: look for an orientation-reversing map
    /// (the descriptor solve's orientation term reversed; Smooth Shells
    /// aligns A's reflection). Without it, maps preserve orientation and
    /// the orientation score reported tells whether a pair needs it.
    #[arg(long)]
    mirrored: bool,
    /// The shapes are not near-isometric (different people, different
    /// animals, different builds): Smooth Shells screens all eight rigid
    /// orientations by a short alignment and chooses the final map by area
    /// distortion and orientation together (about the default's time: its
    /// initialisation runs on fewer samples; the accuracy table of docs/benchmarks.md,
    /// column `non-isometric`). Other refinements ignore
    /// it. With learned features and --adapt, the adaptation also
    /// minimises the Dirichlet energy of the soft point maps (a
    /// smoothness term).
    #[arg(long)]
    non_isometric: bool,
    /// Smooth Shells runs both settings, the default's and
    /// --non-isometric's, and keeps the map that distorts area least
    /// (twice the time; better than either alone between different
    /// builds or species: docs/benchmarks.md, section Confidence). With
    /// learned features: the default descriptor pipeline (so) runs too,
    /// and the least distorting of its map and the learned one is kept.
    #[arg(long)]
    second_opinion: bool,
    /// Where the per-vertex features come from: `descriptors` (spectral
    /// descriptors and the functional-map energy), `learned` (the
    /// DiffusionNet model shipped with fmaps, trained without labels on
    /// the FAUST training shapes) or `learned=MODEL` (a model file of
    /// `fmaps train`). With learned features and no refinement flag, the
    /// learned map is pulled back at size 100 (unless -k says otherwise)
    /// and refined by ZoomOut to 200 in steps of 20 (the most accurate of
    /// the refinements measured from it, docs/benchmarks.md).
    #[arg(
        long,
        default_value = "descriptors",
        value_name = "descriptors|learned[=MODEL]"
    )]
    features: String,
    /// With learned features: adapt the model to the pair first, by N
    /// steps of its unsupervised training losses on these two shapes (the
    /// model file is not changed).
    #[arg(long, value_name = "N")]
    adapt: Option<usize>,
    /// With learned features: read the initial point map off the
    /// features (`features`: the most similar target vertex, default) or
    /// off their functional map (`spectral`: the regularised layer the
    /// network was trained with, size -k, then the spectral embedding).
    #[arg(long, value_name = "features|spectral")]
    point_map: Option<fmaps::pipeline::LearnedPointMap>,
    /// Keep the meshes' own units: no scaling to unit area before the
    /// eigenbases (by default each shape is scaled to unit area, so that
    /// the map does not depend on the units of either mesh).
    #[arg(long)]
    no_area_normalize: bool,
    /// Write C_BA (k x k, functions on B to functions on A, between the
    /// bases of the unit-area shapes unless --no-area-normalize) as text,
    /// or float64 in FILE.npy / FILE.npz.
    #[arg(long)]
    pub(crate) save_fmap: Option<PathBuf>,
    /// Print one JSON object (stage times, map metrics, energy).
    #[arg(long)]
    pub(crate) json: bool,
}

/// `--refine NAME`: the facade's [`RefinerKind`](fmaps::pipeline::RefinerKind),
/// with its names and one-line summaries as the possible values (one enum
/// for the command line, the library and Python).
pub(crate) fn refiner_kind_parser()
-> impl clap::builder::TypedValueParser<Value = fmaps::pipeline::RefinerKind> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    use fmaps::pipeline::RefinerKind;
    PossibleValuesParser::new(
        RefinerKind::ALL.map(|k| PossibleValue::new(k.name()).help(k.summary())),
    )
    .map(|name| {
        name.parse::<RefinerKind>()
            .expect("the possible values are the kinds' names")
    })
}

/// `--select`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum SelectKind {
    /// Lowest conformal distortion of the final map.
    Conformal,
    /// Best orientation score of the final map.
    Orientation,
    /// Lowest area distortion of the final map.
    Area,
}

/// The refiners' own flags, shared by `fmaps match` (and `batch`) and
/// `fmaps refine`.
#[derive(clap::Args, Clone)]
pub(crate) struct RefinerFlags {
    /// ZoomOut schedule START:FINAL:STEP (the basis grows from START to
    /// FINAL by STEP; FINAL eigenpairs are computed when fewer would be;
    /// default: `fmaps_refine::ZoomOut::default()`'s, 50:150:5).
    #[arg(long, value_name = "START:FINAL:STEP")]
    pub(crate) zoomout: Option<String>,
    /// ICP iterations (stops earlier at a fixed point).
    #[arg(long, default_value_t = Icp::default().max_iterations)]
    icp_iterations: usize,
    /// Run the ZoomOut iterations on N farthest points per shape (the
    /// paper's fast variant; the final map covers all vertices), or on
    /// every vertex (`all`). Default: every vertex up to 20000 vertices in
    /// the larger mesh, 10000 samples above
    /// (`fmaps::pipeline::default_refine_samples`; the output says so).
    #[arg(long, value_name = "N|all", value_parser = parse_refine_samples)]
    refine_samples: Option<SamplesFlag>,
    /// Bijective ZoomOut: refine both directions together.
    #[arg(long)]
    bijective: bool,
    /// Convert maps with the adjoint of C (in `match`, the initial map's
    /// conversion too).
    #[arg(long)]
    pub(crate) adjoint: bool,
    /// How the refiners turn C into a point map: nearest neighbours, or
    /// the Fast Sinkhorn Filter (entropic transport on a sparse k-NN
    /// support; closer to bijective, slower).
    #[arg(long, value_enum, default_value_t = ConversionKind::Nn)]
    conversion: ConversionKind,
}

/// `--refine-samples`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SamplesFlag {
    /// Every vertex.
    All,
    /// This many farthest points per shape.
    Count(usize),
}

fn parse_refine_samples(text: &str) -> Result<SamplesFlag, String> {
    match text {
        "all" => Ok(SamplesFlag::All),
        _ => match text.parse::<usize>() {
            Ok(n) if n > 0 => Ok(SamplesFlag::Count(n)),
            _ => Err(format!(
                "'{text}': expected a number of samples N >= 1 or all"
            )),
        },
    }
}

impl RefinerFlags {
    /// The farthest points per shape ZoomOut's iterations run on for
    /// meshes of `n_a` and `n_b` vertices (`None`: every vertex), and
    /// whether that was chosen automatically (no `--refine-samples`).
    pub(crate) fn samples(&self, n_a: usize, n_b: usize) -> (Option<usize>, bool) {
        match self.refine_samples {
            Some(SamplesFlag::All) => (None, false),
            Some(SamplesFlag::Count(n)) => (Some(n), false),
            None => {
                let auto = fmaps::pipeline::RefineSampling::default().samples_for(n_a, n_b);
                (auto, auto.is_some())
            }
        }
    }

    /// The library's refinement options for these flags, a map of size
    /// `k`, the given orientation settings and meshes of `n_a` and `n_b`
    /// vertices.
    pub(crate) fn options(
        &self,
        k: usize,
        mirrored: bool,
        non_isometric: bool,
        (n_a, n_b): (usize, usize),
    ) -> fmaps::pipeline::RefineOptions {
        let mut o = fmaps::pipeline::RefineOptions::default();
        o.k = k;
        o.schedule = self.zoomout.clone();
        o.icp_iterations = self.icp_iterations;
        o.samples = self.samples(n_a, n_b).0;
        o.bijective = self.bijective;
        o.adjoint = self.adjoint;
        o.sinkhorn = self.conversion == ConversionKind::Sinkhorn;
        o.mirrored = mirrored;
        o.non_isometric = non_isometric;
        o
    }
}

/// `--conversion`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ConversionKind {
    /// Nearest neighbours.
    Nn,
    /// The Fast Sinkhorn Filter (Pai et al. 2021), default parameters.
    Sinkhorn,
}

pub(crate) fn read_landmarks(path: &Path) -> Result<mesh_io::Landmarks, Failure> {
    mesh_io::read_landmarks(path).map_err(input)
}

/// The refinement asked for on the command line: its kind (without
/// refinement flags the facade's default for meshes of `n_a` and `n_b`
/// vertices) and the options it is built from.
fn refinement(
    args: &MatchArgs,
    (n_a, n_b): (usize, usize),
    learned: bool,
) -> (fmaps::pipeline::RefinerKind, fmaps::pipeline::RefineOptions) {
    use fmaps::pipeline::RefinerKind;
    let kind = match (args.refine, &args.refiner.zoomout) {
        (Some(k), _) => k,
        (None, Some(_)) => RefinerKind::Zoomout,
        (None, None) if learned && RefinerKind::default_for(n_a.min(n_b)) != RefinerKind::None => {
            RefinerKind::Zoomout
        }
        (None, None) => RefinerKind::default_for(n_a.min(n_b)),
    };
    let mut options = args
        .refiner
        .options(args.k, args.mirrored, args.non_isometric, (n_a, n_b));
    options.second_opinion = args.second_opinion;
    (kind, options)
}

/// A refinement the options do not allow: bad input about --zoomout.
pub(crate) fn zoomout_failure(e: fmaps::pipeline::MatchError) -> Failure {
    input(anyhow::Error::new(e).context("--zoomout"))
}

/// The pipeline's parameters for the command line `args` (the library's
/// defaults where a flag is not given) and meshes of `sizes.0` and
/// `sizes.1` vertices.
pub(crate) fn params_of(args: &MatchArgs, sizes: (usize, usize)) -> Result<MatchParams, Failure> {
    // Before the refinement is known: the given value, or the library's
    // default (then lowered to what the pipeline uses, below).
    let mut params = MatchParams::for_meshes(sizes.0, sizes.1);
    params.k_process = args.k_process.unwrap_or(defaults().k_process);
    params.k = args.k;
    let d = &mut params.descriptors;
    d.eigenpairs = d.eigenpairs.min(params.k_process);
    d.kind = args.descriptor;
    d.n = args.n_descr;
    if let Some(p) = &args.landmarks {
        d.landmarks = read_landmarks(p)?.pairs;
    }
    d.given = args.descr_files.load(sizes)?;
    params.energy.weights = args.weights.weights();
    params.energy.orient_reversing = args.mirrored;
    params.adjoint = args.refiner.adjoint;
    params.area_normalize = !args.no_area_normalize;
    let learned = crate::train_cmd::learned_features(&args.features, args.adapt, args.point_map)?
        .map(|l| {
            if args.non_isometric {
                l.non_isometric()
            } else {
                l
            }
        });
    let (kind, mut options) = refinement(args, sizes, learned.is_some());
    if learned.is_some() && args.refine.is_none() && args.refiner.zoomout.is_none() {
        use fmaps::pipeline::LearnedFeatures;
        if args.k == defaults().k {
            params.k = LearnedFeatures::DEFAULT_K;
        }
        options.k = params.k;
        options.schedule = Some(LearnedFeatures::default_schedule(params.k));
    }
    params
        .set_refinement(kind, &options)
        .map_err(zoomout_failure)?;
    if let Some(text) = args.starts.as_deref() {
        params.starts.sizes =
            parse_starts(text).map_err(|e| input(anyhow::anyhow!("--starts {e}")))?;
    }
    if args.restart_below.is_some() && params.starts.sizes.is_empty() {
        return Err(input(anyhow::anyhow!(
            "--restart-below needs further starts (--starts K1,K2, or --refine zoomout)"
        )));
    }
    params.starts.restart_below = args.restart_below;
    match args.select_at.as_deref() {
        None => {}
        Some("none") => params.starts.select_at = None,
        Some(text) => match text.parse::<usize>() {
            Ok(k) if k > 0 => params.starts.select_at = Some(k),
            _ => {
                return Err(input(anyhow::anyhow!(
                    "--select-at '{text}': expected a size K >= 1 or none"
                )));
            }
        },
    };
    if let Some(l) = learned {
        // The learned map is one start: the starts vary the descriptor
        // solve's size.
        if args.starts.is_some() {
            return Err(input(anyhow::anyhow!(
                "--starts varies the descriptor solve: learned features give one start"
            )));
        }
        params.starts.sizes.clear();
        params.features = fmaps::pipeline::Features::Learned(l);
    }
    params.starts.select = match args.select {
        SelectKind::Conformal => StartSelection::Conformal,
        SelectKind::Orientation => StartSelection::Orientation,
        SelectKind::Area => StartSelection::Area,
    };
    params.k_process = match args.k_process {
        Some(k) => k.max(params.refinement.k_needed()),
        None => params.k_process_needed(),
    };
    if args.second_opinion && matches!(params.features, fmaps::pipeline::Features::Learned(_)) {
        params = params
            .with_axiomatic_opinion(sizes.0, sizes.1)
            .map_err(zoomout_failure)?;
    }
    Ok(params)
}

/// Parses `--starts`: `none` (a single start) or sizes `K1,K2,..` (each at
/// least 1; spaces around commas allowed).
pub(crate) fn parse_starts(text: &str) -> Result<Vec<usize>, String> {
    let text = text.trim();
    if text == "none" {
        return Ok(Vec::new());
    }
    text.split(',')
        .map(|s| match s.trim().parse::<usize>() {
            Ok(k) if k >= 1 => Ok(k),
            _ => Err(format!(
                "'{text}': expected sizes K1,K2,.. (each at least 1, e.g. 20,30) or none"
            )),
        })
        .collect()
}

pub(crate) fn match_cmd(args: &MatchArgs) -> Result<(), Failure> {
    use fmaps::pipeline::{MatchError, match_shapes_with_progress};
    let outs: Vec<&Path> = [&args.out, &args.save_fmap]
        .into_iter()
        .flatten()
        .map(PathBuf::as_path)
        .collect();
    let mut ins: Vec<&Path> = vec![&args.source, &args.target];
    ins.extend(args.descr_files.paths());
    crate::outputs::check_outputs(&ins, &outs)?;
    let t = Instant::now();
    let a = load(&args.source)?;
    let b = load(&args.target)?;
    let load_seconds = t.elapsed().as_secs_f64();
    let params = params_of(args, (a.n_vertices(), b.n_vertices()))?;
    if let Some(p) = &args.landmarks {
        // Out-of-range landmarks, named by file and line as written.
        read_landmarks(p)?
            .check(a.n_vertices(), b.n_vertices(), Some(p))
            .map_err(input)?;
    }
    let spinner = Spinner::new("matching");
    let r = match_shapes_with_progress(&a, &b, &params, &|s| spinner.stage(s)).map_err(|e| {
        // The file of the shape an error is about, when it is about one.
        let file = match &e {
            MatchError::Spectrum { shape, .. } | MatchError::InvalidShape { shape, .. } => {
                Some(if *shape == "target" {
                    args.target.as_path()
                } else {
                    args.source.as_path()
                })
            }
            _ => None,
        };
        match_failure(e, file)
    })?;
    drop(spinner);
    if let Some(c) = r.confidence.as_ref().filter(|c| c.likely_wrong) {
        eprintln!(
            "warning: this map is likely wrong (metric distortion {:.3}, area distortion {:.3}): {}; try --second-opinion, or --landmarks FILE",
            c.distortion,
            c.area_distortion,
            c.advice().unwrap_or_default()
        );
    }
    crate::outputs::write_map_outputs(
        args.out.as_deref(),
        args.save_fmap.as_deref(),
        &r.t_ab,
        &r.c_ba,
    )?;
    let quality = fmaps::eval::map_quality(&r.t_ab, &a, &b, None).map_err(runtime)?;
    let total = t.elapsed().as_secs_f64();
    // The sampling ZoomOut ran with, and whether it was chosen from the
    // meshes' sizes.
    let (samples, auto_samples) = match &params.refinement {
        fmaps::pipeline::Refinement::ZoomOut { samples, .. } => (
            *samples,
            args.refiner.samples(a.n_vertices(), b.n_vertices()).1,
        ),
        _ => (None, false),
    };
    if args.json {
        let v = json!({
            "source": args.source.display().to_string(),
            "target": args.target.display().to_string(),
            "n_source": a.n_vertices(), "n_target": b.n_vertices(), "k": args.k,
            "area_normalized": params.area_normalize,
            "features": match &params.features {
                fmaps::pipeline::Features::Learned(l) => json!({
                    "kind": "learned", "adapt": l.adaptation.steps,
                    "adapt_dirichlet": l.adaptation.recipe.weights.dirichlet,
                    "point_map": l.point_map.name(),
                    "model": args.features.strip_prefix("learned=").unwrap_or("shipped"),
                }),
                _ => json!({"kind": "descriptors"}),
            },
            "input_areas": {"source": a.area(), "target": b.area()},
            "out": args.out.as_ref().map(|p| p.display().to_string()),
            "seconds": {"load": load_seconds, "spectra": r.times.spectra,
                "descriptors": r.times.descriptors, "operators": r.times.operators,
                "solve": r.times.solve, "point_map": r.times.point_map,
                "refine": r.times.refine, "total": total},
            "refine": r.refine.as_ref().map(|rep| json!({
                "method": rep.method, "iterations": rep.iterations.len(),
                "converged": rep.converged, "nn_searches": rep.nn_searches,
                "nn_seconds": rep.nn_seconds, "seconds": rep.seconds,
                "final_k": r.c_ba.ncols(),
                "changed_per_iteration": rep.iterations.iter().map(|i| i.changed).collect::<Vec<_>>(),
                "seconds_per_iteration": rep.iterations.iter().map(|i| i.seconds).collect::<Vec<_>>(),
            })),
            "refine_samples": {"per_shape": samples, "automatic": auto_samples},
            "orientation": r.orientation,
            "passed_over": r.passed_over,
            "confidence": r.confidence.map(|c| json!({
                "metric_distortion": c.distortion, "long_range": c.long_range,
                "area_distortion": c.area_distortion, "likely_wrong": c.likely_wrong,
                "warn_above": {"metric_distortion": fmaps::pipeline::Confidence::WARN_ABOVE,
                    "area_distortion": fmaps::pipeline::Confidence::WARN_AREA_ABOVE},
                "advice": c.advice(), "seconds": c.seconds,
            })),
            "quality": quality,
            "starts": r.starts,
            "changed_by_refinement": r.t_ab.iter().zip(&r.t_ab_init).filter(|(x, y)| x != y).count(),
            "energy": r.energy,
            "energy_terms": {"descr": r.energy_terms.descr, "lap": r.energy_terms.lap,
                "dcomm": r.energy_terms.dcomm, "orient": r.energy_terms.orient},
            "orthonormality": r.metrics.orthonormality,
            "laplacian_commutativity": r.metrics.laplacian_commutativity,
            "sparsity": r.metrics.sparsity,
        });
        return emit(&format!("{v}\n"));
    }
    let mut o = String::new();
    outln!(
        o,
        "{} ({} vertices) -> {} ({} vertices), k = {}",
        args.source.display(),
        a.n_vertices(),
        args.target.display(),
        b.n_vertices(),
        args.k
    );
    let st = &r.times;
    for (name, sec) in [
        ("load", load_seconds),
        ("eigenbases (both)", st.spectra),
        ("descriptors", st.descriptors),
        ("operators", st.operators),
        ("solve", st.solve),
        ("point map", st.point_map),
        ("refinement", st.refine),
        ("total", total),
    ] {
        outln!(o, "  {name:<18} {sec:>8.3} s");
    }
    outln!(
        o,
        "C_BA: ||C^T C - I|| = {:.3}, Laplacian commutativity {:.3}, {:.1}% of entries below 0.1",
        r.metrics.orthonormality,
        r.metrics.laplacian_commutativity,
        100.0 * r.metrics.sparsity
    );
    if args.refine.is_none()
        && args.refiner.zoomout.is_none()
        && fmaps::pipeline::RefinerKind::default_for(a.n_vertices().min(b.n_vertices()))
            == fmaps::pipeline::RefinerKind::None
    {
        outln!(
            o,
            "refinement: none (the default, Smooth Shells, needs meshes of more than {} vertices; --refine zoomout or icp with a smaller basis)",
            fmaps::pipeline::Refinement::recommended().k_needed()
        );
    }
    if let Some(rep) = &r.refine {
        let changed = r
            .t_ab
            .iter()
            .zip(&r.t_ab_init)
            .filter(|(x, y)| x != y)
            .count();
        outln!(
            o,
            "refinement: {rep}; {changed} of {} vertices moved",
            r.t_ab.len()
        );
    }
    if let (Some(m), true) = (samples, auto_samples) {
        outln!(
            o,
            "ZoomOut iterations on {m} farthest points per shape, the final map on every vertex: chosen because a mesh has more than {} vertices (--refine-samples all: every vertex)",
            fmaps::pipeline::RefineSampling::default().above
        );
    }
    outln!(
        o,
        "orientation score of the map: {:.3} (1: preserved, -1: mirrored)",
        r.orientation
    );
    outln!(
        o,
        "map quality (no ground truth): coverage {:.3}, collapsed faces {:.3}, area distortion {:.3}, conformal distortion {:.3}",
        quality.coverage,
        quality.collapsed_faces,
        quality.area_distortion,
        quality.conformal_distortion
    );
    if let Some(p) = &r.passed_over {
        outln!(
            o,
            "second opinion: kept this map over the {} pipeline's ({}, area distortion {:.3})",
            p.features,
            p.refiner.as_deref().unwrap_or("no refinement"),
            p.area_distortion
        );
    }
    if let Some(c) = r.confidence {
        outln!(
            o,
            "confidence: metric distortion {:.3}, area distortion {:.3} (above {} or {}: likely globally wrong)",
            c.distortion,
            c.area_distortion,
            fmaps::pipeline::Confidence::WARN_ABOVE,
            fmaps::pipeline::Confidence::WARN_AREA_ABOVE
        );
    }
    if let Some(k) = params.starts_stop() {
        let kf = r.c_ba.ncols();
        outln!(
            o,
            "starts scored at k = {k}, where only the kept one went on to {kf} (--select-at none: every start to the end):"
        );
    }
    for s in &r.starts {
        outln!(
            o,
            "  start k = {:<4} area distortion {:.3}, conformal distortion {:.3}, orientation {:.3} ({:.2} s){}",
            s.k,
            s.quality.area_distortion,
            s.quality.conformal_distortion,
            s.orientation,
            s.seconds,
            if s.chosen { "  <- kept" } else { "" }
        );
    }
    match &args.out {
        Some(p) => outln!(o, "wrote {}", p.display()),
        None => outln!(o, "(no --out: map not written)"),
    }
    emit(&o)
}

#[cfg(test)]
mod tests {
    use clap::Parser;
    use fmaps::pipeline::{MatchParams, RefineSampling, Refinement, RefinerKind, default_starts};
    use fmaps::refine::Icp;

    use super::{params_of, parse_starts};
    use crate::{Cli, Command};

    fn parse(extra: &[&str]) -> MatchParams {
        parse_sized(extra, (5000, 5000))
    }

    /// [`parse`] for meshes of `sizes` vertices.
    fn parse_sized(extra: &[&str], sizes: (usize, usize)) -> MatchParams {
        let mut argv = vec!["fmaps", "match", "a.off", "b.off"];
        argv.extend(extra);
        match Cli::try_parse_from(argv).unwrap().command {
            Command::Match(args) => params_of(&args, sizes).unwrap_or_else(|_| panic!("{extra:?}")),
            _ => unreachable!("a match command"),
        }
    }

    /// ZoomOut samples above `RefineSampling::above` vertices in the
    /// larger mesh unless told (`--refine-samples N|all`); other
    /// refinements never.
    #[test]
    fn zoomout_samples_large_meshes_by_default() {
        let policy = RefineSampling::default();
        let samples = |extra: &[&str], sizes| match parse_sized(extra, sizes).refinement {
            Refinement::ZoomOut { samples, .. } => samples,
            other => panic!("{other:?}"),
        };
        let z = ["--refine", "zoomout"];
        let (small, large) = (policy.above, policy.above + 1);
        assert_eq!(samples(&z, (small, small)), None);
        assert_eq!(samples(&z, (5000, large)), Some(policy.samples));
        assert_eq!(samples(&z, (large, 5000)), Some(policy.samples));
        let all = ["--refine", "zoomout", "--refine-samples", "all"];
        assert_eq!(samples(&all, (large, large)), None);
        let n = ["--refine", "zoomout", "--refine-samples", "700"];
        assert_eq!(samples(&n, (small, small)), Some(700));
        for bad in ["0", "-3", "many", ""] {
            let argv = ["fmaps", "match", "a.off", "b.off", "--refine-samples", bad];
            assert!(Cli::try_parse_from(argv).is_err(), "{bad:?}");
        }
    }

    /// `fmaps match` without flags runs `MatchParams::default()` (on meshes
    /// large enough for Smooth Shells) and `MatchParams::for_meshes` on
    /// any meshes, field for field; its refinement flags build the
    /// refiners' defaults: the defaults live once.
    #[test]
    fn cli_defaults_are_the_library_defaults() {
        let same = |p: &MatchParams, d: &MatchParams| {
            assert_eq!(format!("{p:#?}"), format!("{d:#?}"));
        };
        same(&parse(&[]), &MatchParams::default());
        same(
            &parse_sized(&[], (100, 5000)),
            &MatchParams::for_meshes(100, 5000),
        );
        assert!(matches!(
            MatchParams::for_meshes(100, 5000).refinement,
            Refinement::None
        ));
        // The refiner's Debug shows its parameters: the comparison above
        // sees them.
        assert!(format!("{:?}", MatchParams::default().refinement).contains("levels: 50"));
        assert!(matches!(
            parse(&["--refine", "none"]).refinement,
            Refinement::None
        ));
        let p = parse(&["--refine", "zoomout"]);
        match &p.refinement {
            Refinement::ZoomOut {
                zoomout,
                samples: None,
            } => {
                let z = fmaps::refine::ZoomOut::default();
                assert_eq!(
                    (zoomout.k_start, zoomout.k_final, zoomout.step),
                    (z.k_start, z.k_final, z.step)
                );
                assert_eq!(p.starts.sizes, default_starts(RefinerKind::Zoomout, 200));
                assert_eq!(p.starts.sizes, [8, 20]);
                assert_eq!(p.starts.select_at, Some(100));
            }
            other => panic!("{other:?}"),
        }
        match parse(&["--refine", "icp"]).refinement {
            Refinement::Icp(icp) => assert_eq!(icp, Icp::default()),
            other => panic!("{other:?}"),
        }
    }

    /// Without `--k-process`, the eigenpairs the pipeline reads (the
    /// default Smooth Shells: the library's 200); with it, the value
    /// given, raised to what the refinement needs.
    #[test]
    fn k_process_defaults_to_what_the_pipeline_uses() {
        let k = |extra: &[&str]| parse(extra).k_process;
        assert_eq!(k(&[]), MatchParams::default().k_process);
        assert_eq!(k(&[]), parse(&[]).k_process_needed());
        assert_eq!(k(&["--refine", "zoomout"]), 150);
        assert_eq!(k(&["--refine", "zoomout", "--zoomout", "30:200:1"]), 200);
        assert_eq!(k(&["--refine", "none"]), 128);
        assert_eq!(k(&["--refine", "none", "--k", "160"]), 160);
        assert_eq!(k(&["--refine", "none", "--starts", "8,170"]), 170);
        assert_eq!(k(&["--refine", "zoomout", "--k-process", "180"]), 180);
        assert_eq!(k(&["--refine", "zoomout", "--k-process", "60"]), 150);
    }

    #[test]
    fn starts_parse_as_sizes_or_none() {
        assert_eq!(parse_starts("20, 30"), Ok(vec![20, 30]));
        assert_eq!(parse_starts(" none "), Ok(vec![]));
        for bad in ["20,,30", "0", "-1", "", "a,b", "20;30"] {
            assert!(parse_starts(bad).is_err(), "{bad:?}");
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(
            std::env::var("FMAPS_FUZZ_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(256)
        ))]

    #[test]
    fn starts_parse_exactly_the_grammar(text in "[0-9, a-z]{0,20}|none| none |[0-9]{1,22}(,[0-9]{1,22}){0,3}") {
        let expected: Option<Vec<usize>> = if text.trim() == "none" {
            Some(Vec::new())
        } else {
            text.trim()
                .split(',')
                .map(|s| {
                    let s = s.trim();
                    (!s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()))
                        .then(|| s.parse::<usize>().ok())
                        .flatten()
                        .filter(|&k| k >= 1)
                })
                .collect()
        };
        proptest::prop_assert_eq!(parse_starts(&text).ok(), expected, "{:?}", text);
    }

    #[test]
    fn starts_round_trip(ks in proptest::collection::vec(1usize..100_000, 1..6)) {
        let text = ks.iter().map(|k| k.to_string()).collect::<Vec<_>>().join(",");
        proptest::prop_assert_eq!(parse_starts(&text), Ok(ks));
    }
    }
}
