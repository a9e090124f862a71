//! The `fmaps` command-line tool.
#![forbid(unsafe_code)]

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};
use fmaps::laplacian::MassKind;
use fmaps::mesh_io::{self, TriMesh};
use fmaps::{Backend, SpectrumParams};
use serde_json::json;

mod demo;
mod render_cmd;

#[derive(Parser)]
#[command(
    name = "fmaps",
    version,
    about = "Non-rigid 3D shape matching with functional maps"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Threads for every parallel stage (0 = all cores); also accepted
    /// after the subcommand.
    #[arg(long, global = true, default_value_t = 0)]
    threads: usize,
}

#[derive(Subcommand)]
enum Command {
    /// The whole method on a built-in pair with known correspondence (an
    /// asymmetric creature and a bent, renumbered copy): eigenbases, WKS,
    /// functional map, ZoomOut, exact-geodesic errors, and pictures.
    #[command(
        after_help = "Examples:\n  fmaps demo\n  fmaps demo --out pictures --subdivisions 5 --json\n\n\
Writes color-transfer.png (and -init), texture-transfer.png, error-zoomout.png / error-init.png,\n\
fmap.png, spectral-embedding.png, curves.png and source.ply / target.ply (coloured, for MeshLab)."
    )]
    Demo {
        /// Folder for the pictures (created).
        #[arg(long, default_value = "fmaps-demo")]
        out: PathBuf,
        /// Mesh resolution: the icosphere's subdivisions (4 = 2,562
        /// vertices, 5 = 10,242).
        #[arg(long, default_value_t = 4)]
        subdivisions: u32,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Match two shapes: eigenbases, WKS descriptors, the functional map
    /// (exact solve with the orientation term), point map A -> B.
    #[command(
        after_help = "Examples:\n  fmaps match tr_reg_000.off tr_reg_001.off --out tr_reg_000_tr_reg_001.map\n  \
fmaps match tr_reg_000.off tr_reg_001.off --refine zoomout --zoomout 30:200:1 --out A_B.map\n  \
fmaps match cat0.off cat1.off --k 60 --json --save-fmap C.txt\n\n\
Defaults are the literature's automatic pipeline (pyFM's): 200 eigenpairs, 100 WKS from 128,\n\
a 50 x 50 map, weights descr 0.1, lap 1e-3 (resolvent mask), dcomm 1, orientation 1."
    )]
    Match(MatchArgs),
    /// Pictures as PNG (and coloured PLY for MeshLab): colour or texture
    /// transfer through a map, its error heat map, a functional-map
    /// matrix, a spectral embedding, any per-vertex scalar field.
    #[command(subcommand)]
    Render(render_cmd::RenderCommand),
    /// Validate a mesh: counts, defects, components, boundary, genus.
    #[command(after_help = "Example:\n  fmaps info tr_reg_000.off --json")]
    Info {
        /// Mesh file (.off, .obj, .ply).
        mesh: PathBuf,
        /// Print one JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// The first k Laplace–Beltrami eigenpairs of a mesh (L φ = λ M φ).
    #[command(
        after_help = "Examples:\n  fmaps spectrum --builtin sphere --k 36\n  fmaps spectrum tr_reg_000.off --k 100 --json --out basis.npy\n\n\
--out FILE.npy writes the eigenvectors (n x k, float64), FILE_eigenvalues.npy (k) and FILE_mass.npy\n\
(n, the lumped mass diagonal); in Python: phi = np.load('FILE.npy'), and phi.T @ (mass[:, None] * phi) = I."
    )]
    Spectrum {
        /// Mesh file (.off, .obj, .ply); omit with --builtin.
        #[arg(required_unless_present = "builtin")]
        mesh: Option<PathBuf>,
        /// Use a generated mesh instead of a file: a unit sphere (10,242
        /// vertices, exact eigenvalues l(l+1)) or a torus.
        #[arg(long, value_enum, conflicts_with = "mesh")]
        builtin: Option<Builtin>,
        /// Number of eigenpairs.
        #[arg(long, short = 'k', default_value_t = 100)]
        k: usize,
        /// Eigensolver backend.
        #[arg(long, default_value = "native")]
        backend: Backend,
        /// Mass matrix.
        #[arg(long, value_enum, default_value_t = Mass::Lumped)]
        mass: Mass,
        /// Block size of the native solver (tuning; default chosen by
        /// benchmark).
        #[arg(long)]
        block_size: Option<usize>,
        /// Print one JSON object (eigenvalues in full precision).
        #[arg(long)]
        json: bool,
        /// Write the basis as .npy (see below).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Evaluate a point map against ground truth (normalized geodesic error).
    #[command(
        after_help = "Example:\n  fmaps eval --source A.off --target B.off --map A_B.map \\\n      --gt-source corres/A.vts --gt-target corres/B.vts --sym-gt-target corres/B.sym.vts --json\n\n\
The map file holds, for every vertex of A, a 1-based vertex of B. Errors are\n\
d_B(T(a_i), b_i) / sqrt(area(B)) (not x100); --json prints mean_error, sym_mean_error,\n\
auc (area under the cumulative curve on [0, 0.25], normalized), coverage, geodesic, seconds."
    )]
    Eval {
        #[command(flatten)]
        files: EvalFiles,
        /// The reverse map B -> A, for bijectivity.
        #[arg(long)]
        reverse_map: Option<PathBuf>,
        /// Geodesic method.
        #[arg(long, value_enum, default_value_t = GeodesicMethod::Exact)]
        geodesic: GeodesicMethod,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Geodesic distances from source vertices to every vertex.
    #[command(
        after_help = "Example:\n  fmaps geodesic tr_reg_000.off --source 0 --out dist.txt\n\n\
Vertex indices are 0-based. Several --source give the distance to the nearest one.\n\
--out writes one distance per line (17 significant digits); unreachable vertices are inf."
    )]
    Geodesic {
        /// Mesh file (.off, .obj, .ply).
        mesh: PathBuf,
        /// Source vertex (0-based); repeat for several.
        #[arg(long, required = true)]
        source: Vec<usize>,
        /// Method.
        #[arg(long, value_enum, default_value_t = GeodesicMethod::Exact)]
        method: GeodesicMethod,
        /// Output file (one distance per line).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print a JSON summary (method, seconds, max distance).
        #[arg(long)]
        json: bool,
    },
}

/// Options of `fmaps match`.
#[derive(clap::Args)]
struct MatchArgs {
    /// Source mesh A (.off, .obj, .ply).
    source: PathBuf,
    /// Target mesh B.
    target: PathBuf,
    /// Output map T: A -> B, one 1-based B vertex per A vertex (the
    /// dataset's .map format).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Size of the functional map (k x k).
    #[arg(long, short = 'k', default_value_t = 50)]
    k: usize,
    /// Eigenpairs computed per shape.
    #[arg(long, default_value_t = 200)]
    k_process: usize,
    /// Descriptor family.
    #[arg(long, default_value = "wks")]
    descriptor: fmaps::pipeline::DescriptorKind,
    /// Descriptor samples (WKS energies or HKS times).
    #[arg(long, default_value_t = 100)]
    n_descr: usize,
    /// Landmark file: one pair `a b` of 1-based vertex indices (source,
    /// target) per line, or one index used on both shapes.
    #[arg(long)]
    landmarks: Option<PathBuf>,
    /// Relative weight of the orientation-preserving term (0 = off).
    #[arg(long, default_value_t = 1.0)]
    w_orient: f64,
    /// Refinement of the initial map (`--zoomout` alone implies zoomout).
    #[arg(long, value_enum)]
    refine: Option<RefineKind>,
    /// ZoomOut schedule START:FINAL:STEP (the basis grows from START to
    /// FINAL by STEP; FINAL eigenpairs are computed if k-process is lower).
    #[arg(long, value_name = "START:FINAL:STEP")]
    zoomout: Option<String>,
    /// ICP iterations (stops earlier at a fixed point).
    #[arg(long, default_value_t = 10)]
    icp_iterations: usize,
    /// Run the ZoomOut iterations on this many farthest points per shape
    /// (the paper's fast variant); the final map covers all vertices.
    #[arg(long)]
    refine_samples: Option<usize>,
    /// Bijective ZoomOut: refine both directions together.
    #[arg(long)]
    bijective: bool,
    /// Convert maps with the adjoint of C (initial map and refinement).
    #[arg(long)]
    adjoint: bool,
    /// Multi-start: also run from initial maps of these sizes and keep
    /// the final map whose orientation is best preserved; `none` for a
    /// single start. Default: `20,30` with --refine zoomout (measured:
    /// fewer left/right swaps, see README), none otherwise.
    #[arg(long, value_name = "K1,K2,..|none")]
    starts: Option<String>,
    /// With several starts: try the further starts only when the first
    /// map's orientation score is below this (well-oriented pairs cost one
    /// run).
    #[arg(long, value_name = "SCORE")]
    restart_below: Option<f64>,
    /// Write C_BA (k x k, functions on B to functions on A) as text.
    #[arg(long)]
    save_fmap: Option<PathBuf>,
    /// Print one JSON object (stage times, map metrics, energy).
    #[arg(long)]
    json: bool,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum RefineKind {
    /// No refinement.
    None,
    /// Spectral ICP (orthogonal Procrustes) at the map's size.
    Icp,
    /// ZoomOut spectral upsampling.
    Zoomout,
}

#[derive(Clone, Copy, ValueEnum)]
enum GeodesicMethod {
    /// Exact polyhedral distances (VTP window propagation with saddle
    /// shadows).
    Exact,
    /// Exact, by the independent window-ordered reference scheme (slower;
    /// for cross-checks).
    ExactOrdered,
    /// The heat method (approximate, fast for many sources).
    Heat,
    /// Shortest paths along edges (an upper bound).
    Dijkstra,
}

impl GeodesicMethod {
    fn name(self) -> &'static str {
        match self {
            GeodesicMethod::Exact => "exact",
            GeodesicMethod::ExactOrdered => "exact-ordered",
            GeodesicMethod::Heat => "heat-method",
            GeodesicMethod::Dijkstra => "Dijkstra",
        }
    }
}

/// A spinner with the current stage and the elapsed time on stderr, drawn
/// only when stderr is a terminal (never in pipes, files or tests);
/// cleared when dropped.
pub(crate) struct Spinner(indicatif::ProgressBar);

impl Spinner {
    pub(crate) fn new(stage: impl Into<std::borrow::Cow<'static, str>>) -> Spinner {
        let bar = indicatif::ProgressBar::new_spinner();
        if let Ok(style) = indicatif::ProgressStyle::with_template("{spinner} {elapsed:>3} {msg}") {
            bar.set_style(style);
        }
        bar.set_message(stage);
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        Spinner(bar)
    }

    pub(crate) fn stage(&self, stage: &str) {
        self.0.set_message(stage.to_string());
    }
}

impl Drop for Spinner {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum Builtin {
    Sphere,
    Torus,
}

#[derive(Clone, Copy, ValueEnum)]
enum Mass {
    Lumped,
    Voronoi,
}

/// Appends a line to an output buffer (printed at once by [`emit`], so a
/// closed pipe never interrupts a half-written report).
macro_rules! outln_impl {
    ($o:expr, $($t:tt)*) => {{
        use std::fmt::Write as _;
        let _ = writeln!($o, $($t)*);
    }};
}

pub(crate) use outln_impl as outln;

/// Prints a buffer; a closed pipe (`fmaps ... | head`) is not an error.
pub(crate) fn emit(text: &str) -> Result<(), Failure> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => r.map_err(runtime),
    }
}

/// A failure with its exit code: 2 for bad input, 1 for a runtime failure.
struct Failure(u8, anyhow::Error);

fn input<E: Into<anyhow::Error>>(e: E) -> Failure {
    Failure(2, e.into())
}

fn runtime<E: Into<anyhow::Error>>(e: E) -> Failure {
    Failure(1, e.into())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Err(e) = rayon::ThreadPoolBuilder::new()
        .num_threads(cli.threads)
        .build_global()
    {
        eprintln!("error: --threads {}: {e}", cli.threads);
        return ExitCode::from(1);
    }
    let result = match cli.command {
        Command::Demo {
            out,
            subdivisions,
            json,
        } => demo::run(&out, subdivisions, json),
        Command::Info { mesh, json } => info(&mesh, json),
        Command::Match(args) => match_cmd(&args),
        Command::Geodesic {
            mesh,
            source,
            method,
            out,
            json,
        } => geodesic(&mesh, &source, method, out.as_deref(), json),
        Command::Eval {
            files,
            reverse_map,
            geodesic,
            json,
        } => eval(&files, reverse_map.as_deref(), geodesic, json),
        Command::Render(cmd) => render_cmd::run(cmd),
        Command::Spectrum {
            mesh,
            builtin,
            k,
            backend,
            mass,
            block_size,
            json,
            out,
        } => spectrum(
            mesh.as_deref(),
            builtin,
            k,
            backend,
            mass,
            block_size,
            json,
            out.as_deref(),
        ),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure(code, e)) => {
            eprintln!("error: {e:#}");
            ExitCode::from(code)
        }
    }
}

fn load(path: &Path) -> Result<TriMesh, Failure> {
    mesh_io::read_mesh(path).map_err(input)
}

fn info(path: &Path, json: bool) -> Result<(), Failure> {
    let mesh = load(path)?;
    let mut o = String::new();
    let r = mesh.validate();
    if json {
        let mut v = serde_json::to_value(&r).map_err(runtime)?;
        v["mesh"] = json!(path.display().to_string());
        v["is_manifold"] = json!(r.is_manifold());
        v["is_closed_manifold"] = json!(r.is_closed_manifold());
        v["is_clean"] = json!(r.is_clean());
        return emit(&format!(
            "{}\n",
            serde_json::to_string_pretty(&v).map_err(runtime)?
        ));
    }
    let list = |v: &[usize]| -> String {
        if v.is_empty() {
            "none".into()
        } else {
            let head: Vec<String> = v.iter().take(8).map(|x| x.to_string()).collect();
            format!(
                "{} ({}{})",
                v.len(),
                head.join(", "),
                if v.len() > 8 { ", ..." } else { "" }
            )
        }
    };
    outln!(o, "{}", path.display());
    outln!(
        o,
        "  vertices {}  faces {}  edges {}",
        r.n_vertices,
        r.n_faces,
        r.n_edges
    );
    outln!(
        o,
        "  area {:.6}  bounding box {:?} .. {:?}",
        r.area,
        r.bounding_box[0],
        r.bounding_box[1]
    );
    outln!(
        o,
        "  connected components {}  boundary loops {} ({} edges)",
        r.connected_components,
        r.boundary_loops,
        r.boundary_edges
    );
    outln!(
        o,
        "  Euler characteristic {}  genus {}",
        r.euler_characteristic,
        r.genus
            .map_or("undefined (not a manifold)".into(), |g| g.to_string())
    );
    outln!(o, "  degenerate faces {}", list(&r.degenerate_faces));
    outln!(o, "  duplicate faces {}", list(&r.duplicate_faces));
    outln!(o, "  non-manifold edges {}", r.non_manifold_edges.len());
    outln!(
        o,
        "  non-manifold vertices {}",
        list(&r.non_manifold_vertices)
    );
    outln!(
        o,
        "  unreferenced vertices {}",
        list(&r.unreferenced_vertices)
    );
    outln!(
        o,
        "  inconsistently oriented edges {}",
        r.inconsistently_oriented_edges
    );
    outln!(
        o,
        "  verdict: {}",
        if r.is_clean() {
            "clean manifold mesh"
        } else if r.is_manifold() {
            "manifold, with the defects above"
        } else {
            "NOT a manifold"
        }
    );
    emit(&o)
}

#[allow(clippy::too_many_arguments)]
fn spectrum(
    path: Option<&Path>,
    builtin: Option<Builtin>,
    k: usize,
    backend: Backend,
    mass: Mass,
    block_size: Option<usize>,
    json: bool,
    out: Option<&Path>,
) -> Result<(), Failure> {
    let t = Instant::now();
    let (name, mesh) = match (path, builtin) {
        (Some(p), _) => (p.display().to_string(), load(p)?),
        (None, Some(Builtin::Sphere)) => (
            "builtin unit sphere (icosphere, 5 subdivisions)".to_string(),
            mesh_io::generate::icosphere(1.0, 5),
        ),
        (None, Some(Builtin::Torus)) => (
            "builtin torus R=1, r=0.4".to_string(),
            mesh_io::generate::torus(1.0, 0.4, 160, 64),
        ),
        (None, None) => return Err(input(anyhow::anyhow!("give a mesh file or --builtin"))),
    };
    let load_s = t.elapsed().as_secs_f64();
    let params = SpectrumParams {
        mass: match mass {
            Mass::Lumped => MassKind::Lumped,
            Mass::Voronoi => MassKind::Voronoi,
        },
        backend,
        threads: rayon::current_num_threads(),
        block_size,
    };
    let spinner = Spinner::new(format!("{k} eigenpairs of {} vertices", mesh.n_vertices()));
    let s = fmaps::spectrum(&mesh, k, &params);
    drop(spinner);
    let s = s.map_err(|e| match e {
        fmaps::eigensolve::Error::InvalidK { .. }
        | fmaps::eigensolve::Error::NonPositiveMass { .. }
        | fmaps::eigensolve::Error::InvalidParameter(_) => input(e),
        _ => runtime(e),
    })?;
    let b = &s.basis;
    if let Some(out) = out {
        write_basis(out, b)
            .with_context(|| format!("writing {}", out.display()))
            .map_err(runtime)?;
    }
    let peak = peak_rss_mb();
    let exact: Option<Vec<f64>> = matches!(builtin, Some(Builtin::Sphere)).then(|| {
        (0..)
            .flat_map(|l: usize| std::iter::repeat_n((l * (l + 1)) as f64, 2 * l + 1))
            .take(k)
            .collect()
    });
    let mut o = String::new();
    if json {
        let v = json!({
            "mesh": name,
            "n_vertices": mesh.n_vertices(),
            "n_faces": mesh.n_faces(),
            "k": k,
            "backend": b.report.backend,
            "shift": b.report.shift,
            "threads": rayon::current_num_threads(),
            "seconds": { "load": load_s, "laplacian": s.times.laplacian, "factorization": s.times.factorization, "eigensolve": s.times.eigensolve },
            "restarts": b.report.restarts,
            "operator_applications": b.report.operator_applications,
            "max_residual": b.report.max_residual(),
            "orthonormality_error": b.report.orthonormality_error,
            "skipped_degenerate_faces": s.skipped_faces.len(),
            "peak_rss_mb": peak,
            "eigenvalues": b.eigenvalues.as_slice(),
            "residuals": b.report.residuals,
        });
        return emit(&format!(
            "{}\n",
            serde_json::to_string(&v).map_err(runtime)?
        ));
    }
    outln!(
        o,
        "{name}: {} vertices, {} faces",
        mesh.n_vertices(),
        mesh.n_faces()
    );
    if !s.skipped_faces.is_empty() {
        outln!(
            o,
            "warning: {} degenerate faces were left out of the Laplacian",
            s.skipped_faces.len()
        );
    }
    outln!(
        o,
        "{} backend, k = {k}, shift {:.4}: {} restarts, {} operator applications",
        b.report.backend,
        b.report.shift,
        b.report.restarts,
        b.report.operator_applications
    );
    outln!(
        o,
        "seconds: load {:.3}  laplacian {:.4}  factorization {:.3}  eigensolve {:.3}  (peak memory {})",
        load_s,
        s.times.laplacian,
        s.times.factorization,
        s.times.eigensolve,
        peak.map_or("n/a".into(), |m| format!("{m:.0} MB"))
    );
    outln!(
        o,
        "max residual ‖Lφ − λMφ‖_M⁻¹ = {:.2e}, max |ΦᵀMΦ − I| = {:.2e}",
        b.report.max_residual(),
        b.report.orthonormality_error
    );
    match &exact {
        Some(ex) => {
            outln!(o, "   i   eigenvalue          exact l(l+1)   rel. error");
            for (i, (l, e)) in b.eigenvalues.iter().zip(ex).enumerate() {
                let rel = if *e > 0.0 {
                    format!("{:.2e}", (l - e).abs() / e)
                } else {
                    "-".into()
                };
                outln!(o, "{i:4}   {l:<18.10} {e:<14} {rel}");
            }
        }
        None => {
            outln!(o, "   i   eigenvalue");
            for (i, l) in b.eigenvalues.iter().enumerate() {
                outln!(o, "{i:4}   {l:.12}");
            }
        }
    }
    if let Some(out) = out {
        outln!(o, "wrote {} (+ _eigenvalues.npy, _mass.npy)", out.display());
    }
    emit(&o)
}

fn geodesic(
    path: &Path,
    sources: &[usize],
    method: GeodesicMethod,
    out: Option<&Path>,
    json: bool,
) -> Result<(), Failure> {
    let mesh = load(path)?;
    let t = Instant::now();
    let solver = distance_solver(&mesh, method)?;
    let d = solver.distances(sources).map_err(input)?;
    let seconds = t.elapsed().as_secs_f64();
    if let Some(out) = out {
        let mut text = String::with_capacity(d.len() * 20);
        for x in &d {
            outln!(text, "{x:.17e}");
        }
        std::fs::write(out, text)
            .with_context(|| format!("writing {}", out.display()))
            .map_err(runtime)?;
    }
    let max = d
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    let unreachable = d.iter().filter(|x| x.is_infinite()).count();
    if json {
        let v = json!({"mesh": path.display().to_string(), "method": solver.name(), "sources": sources,
            "seconds": seconds, "max_distance": max, "unreachable": unreachable});
        return emit(&format!("{v}\n"));
    }
    let mut o = String::new();
    outln!(
        o,
        "{}: {} distances from {} source(s) in {seconds:.3} s; max {max:.6}, {unreachable} unreachable",
        solver.name(),
        d.len(),
        sources.len()
    );
    if out.is_none() {
        for x in &d {
            outln!(o, "{x:.17e}");
        }
    }
    emit(&o)
}

fn distance_solver(
    mesh: &TriMesh,
    method: GeodesicMethod,
) -> Result<Box<dyn fmaps::geodesic::DistanceSolver>, Failure> {
    use fmaps::geodesic::{DijkstraSolver, ExactSolver, HeatParams, HeatSolver};
    Ok(match method {
        GeodesicMethod::Exact => Box::new(ExactSolver::new(mesh).map_err(input)?),
        GeodesicMethod::ExactOrdered => Box::new(
            ExactSolver::new(mesh)
                .map_err(input)?
                .with_algorithm(fmaps::geodesic::ExactAlgorithm::WindowOrdered),
        ),
        GeodesicMethod::Heat => {
            Box::new(HeatSolver::new(mesh, &HeatParams::default()).map_err(input)?)
        }
        GeodesicMethod::Dijkstra => Box::new(DijkstraSolver::new(mesh)),
    })
}

/// The files of `fmaps eval` and `fmaps render error`: a pair, a map and
/// its ground truth.
#[derive(clap::Args)]
pub(crate) struct EvalFiles {
    /// Source mesh A.
    #[arg(long)]
    source: PathBuf,
    /// Target mesh B.
    #[arg(long)]
    target: PathBuf,
    /// The map A -> B (.map, 1-based).
    #[arg(long)]
    map: PathBuf,
    /// Ground truth on A (.vts, 1-based).
    #[arg(long)]
    gt_source: PathBuf,
    /// Ground truth on B (.vts, 1-based), line-aligned with --gt-source.
    #[arg(long)]
    gt_target: PathBuf,
    /// Mirrored ground truth on B (.sym.vts) for the symmetry-aware error.
    #[arg(long)]
    sym_gt_target: Option<PathBuf>,
}

/// What [`EvalFiles::load`] reads.
pub(crate) struct EvalInputs {
    pub(crate) a: TriMesh,
    pub(crate) b: TriMesh,
    pub(crate) t_ab: Vec<usize>,
    /// Source vertex of each ground-truth point.
    pub(crate) gt_source: Vec<usize>,
    pub(crate) gt: fmaps::eval::GroundTruth,
}

impl EvalFiles {
    /// Reads and checks the meshes, the map (one 1-based target per
    /// source vertex) and the ground truth.
    pub(crate) fn load(&self) -> Result<EvalInputs, Failure> {
        let files = self;
        let a = load(&files.source)?;
        let b = load(&files.target)?;
        let t_ab = read_indices(&files.map, b.n_vertices(), false)?;
        if t_ab.len() != a.n_vertices() {
            return Err(input(anyhow::anyhow!(
                "{}: {} lines, but the source mesh has {} vertices (one target per source vertex)",
                files.map.display(),
                t_ab.len(),
                a.n_vertices()
            )));
        }
        let gt_source = read_indices(&files.gt_source, a.n_vertices(), true)?;
        let gt = fmaps::eval::GroundTruth::new(
            gt_source.clone(),
            read_indices(&files.gt_target, b.n_vertices(), true)?,
            files
                .sym_gt_target
                .as_deref()
                .map(|p| read_indices(p, b.n_vertices(), true))
                .transpose()?,
        )
        .map_err(input)?;
        Ok(EvalInputs {
            a,
            b,
            t_ab,
            gt_source,
            gt,
        })
    }
}

/// A `.vts` or `.map` file (1-based) as 0-based indices below `n`.
fn read_indices(p: &Path, n: usize, vts: bool) -> Result<Vec<usize>, Failure> {
    let v = if vts {
        mesh_io::read_vts(p)
    } else {
        mesh_io::read_map(p)
    }
    .map_err(input)?;
    mesh_io::check_indices(&v, n, Some(p)).map_err(input)?;
    Ok(v)
}

fn eval(
    files: &EvalFiles,
    reverse_map: Option<&Path>,
    method: GeodesicMethod,
    json: bool,
) -> Result<(), Failure> {
    use fmaps::eval::{EvalParams, evaluate};
    let t = Instant::now();
    let EvalInputs { a, b, t_ab, gt, .. } = files.load()?;
    let t_ba = reverse_map
        .map(|p| read_indices(p, a.n_vertices(), false))
        .transpose()?;
    let spinner = Spinner::new(format!("{} geodesics on the target", method.name()));
    let solver = distance_solver(&b, method)?;
    let r = evaluate(
        &b,
        solver.as_ref(),
        &t_ab,
        &gt,
        t_ba.as_deref(),
        &EvalParams::default(),
    )
    .map_err(input)?;
    drop(spinner);
    let seconds = t.elapsed().as_secs_f64();
    if json {
        let v = json!({
            "mean_error": r.mean_error, "sym_mean_error": r.sym_mean_error, "auc": r.auc,
            "coverage": r.coverage, "bijectivity": r.bijectivity, "geodesic": r.geodesic,
            "seconds": seconds, "n_points": r.errors.len(),
            "thresholds": r.thresholds, "curve": r.curve,
        });
        return emit(&format!("{v}\n"));
    }
    let mut o = String::new();
    outln!(
        o,
        "{} ground-truth points, {} geodesics, {seconds:.3} s",
        r.errors.len(),
        r.geodesic
    );
    outln!(
        o,
        "mean error {:.6} (x100: {:.3})",
        r.mean_error,
        100.0 * r.mean_error
    );
    if let Some(s) = r.sym_mean_error {
        outln!(
            o,
            "symmetry-aware mean error {s:.6} (x100: {:.3})",
            100.0 * s
        );
    }
    outln!(
        o,
        "AUC on [0, 0.25]: {:.4}; coverage {:.4}",
        r.auc,
        r.coverage
    );
    if let Some(bij) = r.bijectivity {
        outln!(o, "bijectivity {bij:.4}");
    }
    emit(&o)
}

/// FILE.npy: eigenvectors; FILE_eigenvalues.npy; FILE_mass.npy.
fn write_basis(out: &Path, b: &fmaps::eigensolve::SpectralBasis) -> anyhow::Result<()> {
    let stem = out.with_extension("");
    let sibling = |suffix: &str| PathBuf::from(format!("{}_{suffix}.npy", stem.display()));
    fmaps::npy::save_f64(out, &[b.n(), b.k()], b.eigenvectors.as_slice())?;
    fmaps::npy::save_f64(&sibling("eigenvalues"), &[b.k()], b.eigenvalues.as_slice())?;
    fmaps::npy::save_f64(&sibling("mass"), &[b.n()], b.mass.as_slice())?;
    Ok(())
}

/// Peak resident memory of this process (Linux), in MB.
fn peak_rss_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn read_landmarks(path: &Path) -> Result<Vec<(usize, usize)>, Failure> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| input(anyhow::anyhow!("{}: {e}", path.display())))?;
    let mut out = Vec::new();
    for (line_no, line) in text.lines().enumerate() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.is_empty() {
            continue;
        }
        let parse = |f: &str| -> Result<usize, Failure> {
            match f.parse::<usize>() {
                Ok(v) if v >= 1 => Ok(v - 1),
                _ => Err(input(anyhow::anyhow!(
                    "{}:{}: '{f}' is not a 1-based vertex index",
                    path.display(),
                    line_no + 1
                ))),
            }
        };
        match fields.as_slice() {
            [a] => {
                let a = parse(a)?;
                out.push((a, a));
            }
            [a, b] => out.push((parse(a)?, parse(b)?)),
            _ => {
                return Err(input(anyhow::anyhow!(
                    "{}:{}: expected one or two vertex indices, found {}",
                    path.display(),
                    line_no + 1,
                    fields.len()
                )));
            }
        }
    }
    Ok(out)
}

/// The refinement asked for on the command line.
fn refinement(args: &MatchArgs) -> Result<fmaps::pipeline::Refinement, Failure> {
    use fmaps::pipeline::Refinement;
    let kind = match (args.refine, &args.zoomout) {
        (Some(k), _) => k,
        (None, Some(_)) => RefineKind::Zoomout,
        (None, None) => RefineKind::None,
    };
    let bad = |m: String| Err(input(anyhow::anyhow!(m)));
    Ok(match kind {
        RefineKind::None => Refinement::None,
        RefineKind::Icp => Refinement::Icp(fmaps_refine::Icp {
            max_iterations: args.icp_iterations,
            adjoint: args.adjoint,
        }),
        RefineKind::Zoomout => {
            let (k_start, k_final, step) = match &args.zoomout {
                None => (50, 150, 5),
                Some(text) => {
                    let parts: Vec<Option<usize>> =
                        text.split(':').map(|p| p.trim().parse().ok()).collect();
                    match parts.as_slice() {
                        [Some(a), Some(b), Some(c)] if *a > 0 && a <= b && *c > 0 => (*a, *b, *c),
                        _ => {
                            return bad(format!(
                                "--zoomout '{text}': expected START:FINAL:STEP with 0 < START <= FINAL and STEP >= 1, e.g. 30:200:1"
                            ));
                        }
                    }
                }
            };
            if k_start > args.k {
                return bad(format!(
                    "--zoomout starts at {k_start}, but the initial map is only {k} x {k} (--k {k})",
                    k = args.k
                ));
            }
            Refinement::ZoomOut {
                zoomout: fmaps_refine::ZoomOut {
                    k_start,
                    k_final,
                    step,
                    adjoint: args.adjoint,
                    bijective: args.bijective,
                    subsample: None,
                },
                samples: args.refine_samples,
            }
        }
    })
}

fn match_cmd(args: &MatchArgs) -> Result<(), Failure> {
    use fmaps::pipeline::{MatchError, MatchParams, match_shapes_with_progress};
    let t = Instant::now();
    let a = load(&args.source)?;
    let b = load(&args.target)?;
    let load_seconds = t.elapsed().as_secs_f64();
    let mut params = MatchParams {
        k: args.k,
        k_process: args.k_process,
        k_descr: 128.min(args.k_process),
        descriptor: args.descriptor,
        n_descr: args.n_descr,
        w_orient: args.w_orient,
        ..MatchParams::default()
    };
    if let Some(p) = &args.landmarks {
        params.landmarks = read_landmarks(p)?;
    }
    params.adjoint = args.adjoint;
    params.refine = refinement(args)?;
    params.starts = match args.starts.as_deref().map(str::trim) {
        Some("none") => Vec::new(),
        Some(list) => match list.split(',').map(|s| s.trim().parse::<usize>()).collect() {
            Ok(v) => v,
            Err(_) => {
                return Err(input(anyhow::anyhow!(
                    "--starts '{list}': expected sizes K1,K2,.. (e.g. 20,30) or none"
                )));
            }
        },
        // The default further starts, those the computed basis allows.
        None if matches!(params.refine, fmaps::pipeline::Refinement::ZoomOut { .. }) => {
            let k_process = params.k_process.max(params.refine.k_needed());
            fmaps::pipeline::ZOOMOUT_STARTS
                .into_iter()
                .filter(|&s| s <= k_process)
                .collect()
        }
        None => Vec::new(),
    };
    if args.restart_below.is_some() && params.starts.is_empty() {
        return Err(input(anyhow::anyhow!(
            "--restart-below needs further starts (--starts K1,K2, or --refine zoomout)"
        )));
    }
    params.restart_below = args.restart_below;
    params.k_process = params.k_process.max(params.refine.k_needed());
    let spinner = Spinner::new("matching");
    let r = match_shapes_with_progress(&a, &b, &params, &|s| spinner.stage(s)).map_err(
        |e| match e {
            MatchError::InvalidParameter(_) => input(e),
            e => runtime(e),
        },
    )?;
    drop(spinner);
    if let Some(out) = &args.out {
        mesh_io::write_map(out, &r.t_ab).map_err(runtime)?;
    }
    if let Some(path) = &args.save_fmap {
        let mut text = String::new();
        for row in r.c_ba.row_iter() {
            let cells: Vec<String> = row.iter().map(|v| format!("{v:.17e}")).collect();
            outln!(text, "{}", cells.join(" "));
        }
        std::fs::write(path, text)
            .map_err(|e| runtime(anyhow::anyhow!("{}: {e}", path.display())))?;
    }
    let total = t.elapsed().as_secs_f64();
    if args.json {
        let v = json!({
            "source": args.source.display().to_string(),
            "target": args.target.display().to_string(),
            "n_source": a.n_vertices(), "n_target": b.n_vertices(), "k": args.k,
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
            })),
            "orientation": r.orientation,
            "starts": r.starts,
            "changed_by_refinement": r.t_ab.iter().zip(&r.t_ab_init).filter(|(x, y)| x != y).count(),
            "energy": r.energy,
            "energy_terms": {"descr": r.energy_terms[0], "lap": r.energy_terms[1],
                "dcomm": r.energy_terms[2], "orient": r.energy_terms[3]},
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
    outln!(
        o,
        "orientation score of the map: {:.3} (1: preserved, -1: mirrored)",
        r.orientation
    );
    for s in &r.starts {
        outln!(
            o,
            "  start k = {:<4} orientation {:.3} ({:.2} s){}",
            s.k,
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
