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

mod batch;
mod demo;
mod descr_files;
mod eval;
mod geodesic;
mod info;
mod match_cmd;
mod outputs;
mod refine_cmd;
mod render_cmd;
mod spectrum;
mod train_cmd;
mod value_files;
mod viewer_page;
mod weights;

use eval::eval;
use geodesic::geodesic;
use info::info;
use match_cmd::{MatchArgs, match_cmd};
use spectrum::spectrum;

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
    /// The default pipeline on two built-in pairs with known
    /// correspondence: an asymmetric creature and a bent, renumbered copy
    /// (near-isometric), and two generated bodies of different builds in
    /// different poses (non-isometric); exact-geodesic errors and pictures.
    #[command(
        after_help = "Examples:\n  fmaps demo\n  fmaps demo --out pictures --subdivisions 5 --json\n\n\
Writes, per pair (the non-isometric one prefixed noniso-), color-transfer.png (and -init),\n\
texture-transfer.png, error.png / error-init.png, fmap.png, curves.png and source.ply /\n\
target.ply (coloured, for MeshLab)."
    )]
    Demo {
        /// Folder for the pictures (created).
        #[arg(long, default_value = "fmaps-demo")]
        out: PathBuf,
        /// Resolution of the creature pair: the icosphere's subdivisions (4 = 2,562
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
    /// Train a DiffusionNet feature extractor on a collection of meshes,
    /// unsupervised (deep functional maps: the regularised functional-map
    /// layer, bijectivity, orthogonality and coupling losses; no ground
    /// truth read). Resumes from its checkpoint.
    #[command(after_help = "Examples:\n  \
fmaps train FAUST/vtx_5k/tr_reg_00*.off --out model.npz --steps 200 --curve losses.png\n  \
fmaps train train.txt --data meshes --out model.npz --cache ops --stop-after 50\n\n\
A killed or stopped run continues from its checkpoint (model.checkpoint.npz by default) when\n\
the same command runs again; the model file is written when the last step is done.")]
    Train(Box<train_cmd::TrainArgs>),
    /// Match the pairs of a collection: resumable (finished pairs are
    /// skipped), each shape's eigenbasis computed once and cached on disk,
    /// optionally one shard of a job array; one JSON line per pair.
    #[command(after_help = "Examples:\n  \
fmaps batch test_pairs.txt --data FAUST/vtx_5k --out faust-maps --corres FAUST/vtx_5k/corres\n  \
fmaps batch pairs.txt --data meshes --out maps --shard $SLURM_ARRAY_TASK_ID/16 -- --refine zoomout\n  \
parallel fmaps --threads 1 batch pairs.txt --data meshes --out maps --shard {}/8 ::: $(seq 8)\n\n\
Writes A_B.map (1-based, as fmaps match --out) and A_B.json per pair, report.jsonl (every\n\
finished pair of the file, in order) and bases/ (the eigenbasis cache, .npz files keyed by\n\
the mesh file's content and the parameters; np.load reads them). Run it again to resume after a kill.")]
    Batch(batch::BatchArgs),
    /// Refine a point map from elsewhere (another tool, a learned method,
    /// a published benchmark map) with ICP or ZoomOut.
    #[command(after_help = "Examples:\n  \
fmaps refine A.off B.off --init-map A_B_init.map --out A_B.map\n  \
fmaps refine A.off B.off --init-map A_B_init.map --refine zoomout --zoomout 30:200:1 --k 30 --json\n\n\
The map's functional map is its pull-back between the eigenbases (--k x --k); the refinement\n\
starts there, so the quality of an initial map and of a refiner can be measured apart.")]
    Refine(refine_cmd::RefineArgs),
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
(n, the lumped mass diagonal); in Python: phi = np.load('FILE.npy'), and phi.T @ (mass[:, None] * phi) = I.\n\
--out FILE.npz writes one archive with the arrays eigenvectors, eigenvalues and mass."
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

/// Set when an output is `-` (standard output): the report then goes to
/// standard error, so that standard output carries the output alone.
pub(crate) static STDOUT_IS_AN_OUTPUT: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// Prints a buffer (to standard error when standard output carries an
/// output); a closed pipe (`fmaps ... | head`) is not an error.
pub(crate) fn emit(text: &str) -> Result<(), Failure> {
    use std::io::Write as _;
    let r = if STDOUT_IS_AN_OUTPUT.load(std::sync::atomic::Ordering::Relaxed) {
        let mut out = std::io::stderr().lock();
        out.write_all(text.as_bytes()).and_then(|()| out.flush())
    } else {
        let mut out = std::io::stdout().lock();
        out.write_all(text.as_bytes()).and_then(|()| out.flush())
    };
    match r {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => r.map_err(runtime),
    }
}

/// A failure with its exit code: 2 for bad input, 1 for a runtime failure.
struct Failure(u8, anyhow::Error);

/// The error and its causes, each cause only when the text so far does
/// not already say it (library errors often quote their source), so that
/// no message is printed twice.
fn message(e: &anyhow::Error) -> String {
    let mut out = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !out.contains(&c) {
            out.push_str(": ");
            out.push_str(&c);
        }
    }
    out
}

fn input<E: Into<anyhow::Error>>(e: E) -> Failure {
    Failure(2, e.into())
}

fn runtime<E: Into<anyhow::Error>>(e: E) -> Failure {
    Failure(1, e.into())
}

/// More threads than this many per core only cost start-up time (a
/// hundred thousand threads took a minute before anything ran).
const THREADS_PER_CORE: usize = 4;

fn main() -> ExitCode {
    let cli = Cli::parse();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if cli.threads > THREADS_PER_CORE * cores {
        eprintln!(
            "error: --threads {}: at most {} on this machine ({THREADS_PER_CORE} per core, {cores} cores; 0 = all cores)",
            cli.threads,
            THREADS_PER_CORE * cores
        );
        return ExitCode::from(2);
    }
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
        Command::Train(args) => train_cmd::train_cmd(&args),
        Command::Batch(args) => batch::batch(&args),
        Command::Refine(args) => refine_cmd::refine_cmd(&args),
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
            eprintln!("error: {}", message(&e));
            ExitCode::from(code)
        }
    }
}

fn load(path: &Path) -> Result<TriMesh, Failure> {
    mesh_io::read_mesh(path).map_err(input)
}

/// A bad-input failure about the mesh at `path` (the message names it).
fn input_on<E>(path: &Path) -> impl Fn(E) -> Failure + '_
where
    E: std::error::Error + Send + Sync + 'static,
{
    move |e| input(anyhow::Error::new(e).context(path.display().to_string()))
}

/// The geodesic solver `method` on `mesh` (read from `path`, which errors
/// name).
fn distance_solver(
    mesh: &TriMesh,
    path: &Path,
    method: GeodesicMethod,
) -> Result<Box<dyn fmaps::geodesic::DistanceSolver>, Failure> {
    use fmaps::geodesic::{DijkstraSolver, ExactSolver, HeatParams, HeatSolver};
    let on = input_on(path);
    Ok(match method {
        GeodesicMethod::Exact => Box::new(ExactSolver::new(mesh).map_err(on)?),
        GeodesicMethod::ExactOrdered => Box::new(
            ExactSolver::new(mesh)
                .map_err(on)?
                .with_algorithm(fmaps::geodesic::ExactAlgorithm::WindowOrdered),
        ),
        GeodesicMethod::Heat => {
            Box::new(HeatSolver::new(mesh, &HeatParams::default()).map_err(on)?)
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
    /// The map A -> B (.map, 1-based; .npy/.npz, 0-based).
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
        .map_err(|e| {
            input(anyhow::Error::new(e).context(format!(
                "ground truth {} / {}",
                files.gt_source.display(),
                files.gt_target.display()
            )))
        })?;
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
    if mesh_io::arrays::is_numpy(p) {
        // NumPy files hold 0-based indices.
        let v = mesh_io::arrays::read_indices(p).map_err(input)?;
        if let Some((i, &x)) = v.iter().enumerate().find(|(_, x)| **x >= n) {
            return Err(input(anyhow::anyhow!(
                "{}: entry {i} is {x}, outside 0..{n} (0-based vertex indices; the mesh has {n} vertices)",
                p.display()
            )));
        }
        return Ok(v);
    }
    let v = if vts {
        mesh_io::read_vts(p)
    } else {
        mesh_io::read_map(p)
    }
    .map_err(input)?;
    mesh_io::check_indices(&v, n, Some(p)).map_err(input)?;
    Ok(v)
}

/// A pipeline error as a failure: bad input (exit 2) for parameters the
/// meshes cannot satisfy and meshes the pipeline cannot use, as in `fmaps
/// spectrum`; else a runtime failure. `file`: the mesh it is about.
pub(crate) fn match_failure(e: fmaps::pipeline::MatchError, file: Option<&Path>) -> Failure {
    use fmaps::pipeline::MatchError;
    let code = match e {
        MatchError::InvalidParameter(_)
        | MatchError::InvalidShape { .. }
        | MatchError::Spectrum {
            source:
                fmaps::eigensolve::Error::InvalidK { .. }
                | fmaps::eigensolve::Error::NonPositiveMass { .. }
                | fmaps::eigensolve::Error::InvalidParameter(_),
            ..
        }
        // A refinement the options do not allow on these meshes (too few
        // samples for the schedule, too few eigenpairs).
        | MatchError::Refine(
            fmaps::refine::Error::InvalidParameter(_)
            | fmaps::refine::Error::NotEnoughEigenpairs { .. }
            | fmaps::refine::Error::SingularSample { .. },
        ) => 2,
        _ => 1,
    };
    let e = anyhow::Error::new(e);
    Failure(
        code,
        match file {
            Some(p) => e.context(p.display().to_string()),
            None => e,
        },
    )
}
