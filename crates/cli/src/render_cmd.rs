//! `fmaps render ...`: pictures of maps and shapes.

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::{Subcommand, ValueEnum};
use fmaps::mesh_io::TriMesh;
use fmaps::viz::{self, Axis, Image, View, plot};
use serde_json::json;

use crate::value_files::{read_curve, read_matrix, read_values};
use crate::viewer_page::{ViewerPage, viewer_page};
use crate::{EvalFiles, EvalInputs, Failure, GeodesicMethod, emit, input, load, runtime};

/// Camera options shared by the mesh pictures.
#[derive(clap::Args, Clone)]
pub(crate) struct ViewArgs {
    /// Width of one view in pixels.
    #[arg(long, default_value_t = 480)]
    width: usize,
    /// Height of one view in pixels.
    #[arg(long, default_value_t = 480)]
    height: usize,
    /// The shapes' vertical axis (FAUST and the built-in shapes: y;
    /// TOSCA: z).
    #[arg(long, value_enum, default_value_t = Up::Y)]
    up: Up,
    /// Turn about the vertical axis, degrees (0: look at the front).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    yaw: f64,
    /// Tilt towards the viewer after the turn, degrees.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pitch: f64,
}

#[derive(Clone, Copy, ValueEnum)]
enum Up {
    X,
    Y,
    Z,
}

impl ViewArgs {
    fn view(&self) -> Result<View, Failure> {
        if !(16..=8192).contains(&self.width) || !(16..=8192).contains(&self.height) {
            return Err(input(anyhow::anyhow!(
                "--width {} --height {}: use 16..=8192 pixels",
                self.width,
                self.height
            )));
        }
        Ok(View {
            up: match self.up {
                Up::X => Axis::X,
                Up::Y => Axis::Y,
                Up::Z => Axis::Z,
            },
            width: self.width,
            height: self.height,
            yaw: self.yaw.to_radians(),
            pitch: self.pitch.to_radians(),
            ..View::default()
        })
    }
}

#[derive(Subcommand)]
pub(crate) enum RenderCommand {
    /// Colour (or texture) transfer: the source coloured by position on
    /// the left, the target coloured through the map on the right; where
    /// the colours agree, the map is right.
    #[command(after_help = "Examples:\n  \
fmaps render transfer tr_reg_000.off tr_reg_001.off --map A_B.map --out transfer.png\n  \
fmaps render transfer cat0.off cat1.off --map A_B.map --up z --yaw 90 --texture --ply cat\n\n\
--texture draws a checkerboard projected from the camera onto the source instead of\n\
position colours; --ply P also writes P-source.ply and P-target.ply with vertex colours.")]
    Transfer {
        /// Source mesh A.
        source: PathBuf,
        /// Target mesh B.
        target: PathBuf,
        /// The map A -> B (.map: one 1-based B vertex per A vertex;
        /// .npy/.npz: 0-based).
        #[arg(long)]
        map: PathBuf,
        /// A checkerboard texture instead of position colours.
        #[arg(long)]
        texture: bool,
        /// Checkerboard squares along the longer side of the picture.
        #[arg(long, default_value_t = 10)]
        squares: usize,
        /// Output PNG (default transfer.png; without --html only).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write the interactive viewer instead (with --out, as well): one
        /// self-contained HTML page (both shapes turning together, colour
        /// and texture transfer, click a point on A to see its image on B).
        #[arg(long, value_name = "FILE.html")]
        html: Option<PathBuf>,
        /// Also write coloured PLY: PREFIX-source.ply, PREFIX-target.ply.
        #[arg(long, value_name = "PREFIX")]
        ply: Option<PathBuf>,
        #[command(flatten)]
        view: ViewArgs,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Heat map of a map's geodesic error on the source, with a colour
    /// bar (errors / sqrt(area of B), as `fmaps eval`).
    #[command(after_help = "Example:\n  \
fmaps render error --source A.off --target B.off --map A_B.map \\\n      \
--gt-source corres/A.vts --gt-target corres/B.vts --vmax 0.1 --out error.png\n\n\
Ground truth covers only some vertices of remeshed datasets; the others show the error of the\n\
nearest covered vertex. With --sym-gt-target the symmetry-aware error is drawn.")]
    Error {
        #[command(flatten)]
        files: EvalFiles,
        /// Geodesic method.
        #[arg(long, value_enum, default_value_t = GeodesicMethod::Exact)]
        geodesic: GeodesicMethod,
        /// Error at the top of the colour scale (larger errors saturate).
        #[arg(long, default_value_t = 0.1)]
        vmax: f64,
        /// Output PNG (default error.png; without --html only).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write the interactive viewer instead (with --out, as well): one
        /// self-contained HTML page with the error view, the colour and
        /// texture transfer and picking.
        #[arg(long, value_name = "FILE.html")]
        html: Option<PathBuf>,
        /// Also write the coloured source as PLY.
        #[arg(long)]
        ply: Option<PathBuf>,
        #[command(flatten)]
        view: ViewArgs,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// A functional map as a heat map (red positive, blue negative; the
    /// seed's Figure 1).
    #[command(after_help = "Example:\n  \
fmaps match A.off B.off --save-fmap C.txt && fmaps render fmap C.txt --out fmap.png\n\n\
The matrix file has one row per line, entries separated by spaces (as --save-fmap writes).")]
    Fmap {
        /// Matrix as text.
        matrix: PathBuf,
        /// |C_ij| at the top of the colour scale.
        #[arg(long, default_value_t = 1.0)]
        vmax: f64,
        /// Title drawn above the matrix.
        #[arg(long)]
        title: Option<String>,
        /// Output PNG.
        #[arg(long, default_value = "fmap.png")]
        out: PathBuf,
        /// Print one JSON object (size, sparsity).
        #[arg(long)]
        json: bool,
    },
    /// The shape drawn with three Laplace–Beltrami eigenfunctions as its
    /// coordinates, coloured by its original position (the seed's
    /// Figure 10).
    #[command(
        after_help = "Example:\n  fmaps render embedding tr_reg_000.off --eigs 1,2,3 --out embedding.png"
    )]
    Embedding {
        /// Mesh file.
        mesh: PathBuf,
        /// Three eigenfunction indices (0 is the constant one).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "1,2,3",
            value_name = "I,J,K"
        )]
        eigs: Vec<usize>,
        /// Output PNG.
        #[arg(long, default_value = "embedding.png")]
        out: PathBuf,
        /// Camera (--up picks which eigenfunction is drawn vertical).
        #[command(flatten)]
        view: ViewArgs,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Cumulative error curves (fraction of points below each error) of
    /// one or more `fmaps eval --json` reports, in one plot.
    #[command(after_help = "Example:\n  \
fmaps eval ... --map init.map --json > init.json\n  \
fmaps eval ... --map zoomout.map --json > zoomout.json\n  \
fmaps render curves init.json zoomout.json --out curves.png\n\n\
Each curve is labelled with its file name (or --label, once per file) and its mean error x100.")]
    Curves {
        /// Reports written by `fmaps eval --json`.
        #[arg(required = true)]
        reports: Vec<PathBuf>,
        /// Labels, one per report, in order.
        #[arg(long)]
        label: Vec<String>,
        /// Plot title.
        #[arg(long, default_value = "cumulative geodesic error")]
        title: String,
        /// Output PNG.
        #[arg(long, default_value = "curves.png")]
        out: PathBuf,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// A per-vertex scalar field (one number per line, e.g. the output of
    /// `fmaps geodesic --out`) with a colour bar.
    #[command(after_help = "Example:\n  \
fmaps geodesic tr_reg_000.off --source 0 --out dist.txt\n  \
fmaps render scalar tr_reg_000.off --values dist.txt --title distance --out dist.png")]
    Scalar {
        /// Mesh file.
        mesh: PathBuf,
        /// Values, one per vertex and line (`inf`/`nan` are drawn grey), or
        /// a NumPy vector (.npy/.npz).
        #[arg(long)]
        values: PathBuf,
        /// Bottom of the colour scale (default: the smallest finite value).
        #[arg(long, allow_hyphen_values = true)]
        vmin: Option<f64>,
        /// Top of the colour scale (default: the largest finite value).
        #[arg(long, allow_hyphen_values = true)]
        vmax: Option<f64>,
        /// Colour bar title.
        #[arg(long, default_value = "")]
        title: String,
        /// Output PNG.
        #[arg(long, default_value = "scalar.png")]
        out: PathBuf,
        /// Also write the coloured mesh as PLY.
        #[arg(long)]
        ply: Option<PathBuf>,
        #[command(flatten)]
        view: ViewArgs,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Learned features as colours (their first three principal
    /// components, shared by every mesh drawn): with two meshes, where
    /// the colours agree the features agree.
    #[command(after_help = "Examples:\n  \
fmaps render features tr_reg_080.off tr_reg_091.off --out features.png\n  \
fmaps render features cat0.off --model cats.npz --up z")]
    Features {
        /// Mesh files, drawn side by side.
        #[arg(required = true, num_args = 1..=4)]
        meshes: Vec<PathBuf>,
        /// Model file of `fmaps train` (default: the model shipped with
        /// fmaps).
        #[arg(long)]
        model: Option<PathBuf>,
        /// Output PNG.
        #[arg(long, default_value = "features.png")]
        out: PathBuf,
        #[command(flatten)]
        view: ViewArgs,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
}

/// The `--ply PREFIX` files of `render transfer`.
fn transfer_ply(prefix: &Path, side: &str) -> PathBuf {
    PathBuf::from(format!("{}-{side}.ply", prefix.display()))
}

impl RenderCommand {
    /// The files the command reads and those it writes.
    fn files(&self) -> (Vec<&Path>, Vec<PathBuf>) {
        let mut outs = Vec::new();
        let ins: Vec<&Path> = match self {
            RenderCommand::Transfer {
                source,
                target,
                map,
                out,
                html,
                ply,
                ..
            } => {
                outs.extend(png_out(out, html, "transfer.png"));
                outs.extend(html.clone());
                if let Some(p) = ply {
                    outs.extend(["source", "target"].map(|side| transfer_ply(p, side)));
                }
                vec![source, target, map]
            }
            RenderCommand::Error {
                files,
                out,
                html,
                ply,
                ..
            } => {
                outs.extend(png_out(out, html, "error.png"));
                outs.extend(html.clone());
                outs.extend(ply.clone());
                let mut ins: Vec<&Path> = vec![
                    &files.source,
                    &files.target,
                    &files.map,
                    &files.gt_source,
                    &files.gt_target,
                ];
                ins.extend(files.sym_gt_target.as_deref());
                ins
            }
            RenderCommand::Fmap { matrix, out, .. } => {
                outs.push(out.clone());
                vec![matrix]
            }
            RenderCommand::Embedding { mesh, out, .. } => {
                outs.push(out.clone());
                vec![mesh]
            }
            RenderCommand::Features {
                meshes, model, out, ..
            } => {
                outs.push(out.clone());
                meshes.iter().chain(model).map(PathBuf::as_path).collect()
            }
            RenderCommand::Curves { reports, out, .. } => {
                outs.push(out.clone());
                reports.iter().map(PathBuf::as_path).collect()
            }
            RenderCommand::Scalar {
                mesh,
                values,
                out,
                ply,
                ..
            } => {
                outs.push(out.clone());
                outs.extend(ply.clone());
                vec![mesh, values]
            }
        };
        (ins.into_iter().map(|p| p as &Path).collect(), outs)
    }
}

/// The pictures and PLY files of one command, written together at the end
/// (none of them if anything fails).
#[derive(Default)]
struct Written {
    staged: crate::outputs::Staged,
    names: Vec<String>,
}

pub(crate) fn run(cmd: RenderCommand) -> Result<(), Failure> {
    let t = Instant::now();
    let (ins, outs) = cmd.files();
    let out_refs: Vec<&Path> = outs.iter().map(PathBuf::as_path).collect();
    crate::outputs::check_outputs(&ins, &out_refs)?;
    let mut written = Written::default();
    let mut extra = serde_json::Map::new();
    let mut o = String::new();
    let json = match cmd {
        RenderCommand::Transfer {
            source,
            target,
            map,
            texture,
            squares,
            out,
            html,
            ply,
            view,
            json,
        } => {
            let view = view.view()?;
            let png = png_out(&out, &html, "transfer.png");
            let (a, b) = (load(&source)?, load(&target)?);
            let t_ab = crate::read_indices(&map, b.n_vertices(), false)?;
            if t_ab.len() != a.n_vertices() {
                return Err(input(anyhow::anyhow!(
                    "{}: {} lines, but {} has {} vertices (one target per source vertex)",
                    map.display(),
                    t_ab.len(),
                    source.display(),
                    a.n_vertices()
                )));
            }
            let (img, cs, ct) = if texture {
                fmaps::pictures::texture_transfer(&a, &b, &t_ab, squares.max(1), &view)
            } else {
                fmaps::pictures::color_transfer(&a, &b, &t_ab, &view)
            }
            .map_err(runtime)?;
            if let Some(out) = &png {
                save(&img, out, &mut written)?;
            }
            if let Some(page) = &html {
                let scene = viewer_page([&source, &target], [&a, &b], &t_ab, None, view.up);
                save_html(&scene, page, &mut written)?;
            }
            if let Some(prefix) = ply {
                for (mesh, colors, side) in [(&a, &cs, "source"), (&b, &ct, "target")] {
                    save_ply(mesh, colors, &transfer_ply(&prefix, side), &mut written)?;
                }
            }
            json
        }
        RenderCommand::Error {
            files,
            geodesic,
            vmax,
            out,
            html,
            ply,
            view,
            json,
        } => {
            let view = view.view()?;
            let png = png_out(&out, &html, "error.png");
            positive("--vmax", vmax)?;
            let EvalInputs {
                a,
                b,
                t_ab,
                gt_source,
                gt,
            } = files.load()?;
            let spinner = crate::Spinner::new(format!("{} geodesics", geodesic.name()));
            let solver = crate::distance_solver(&b, &files.target, geodesic)?;
            let r = fmaps::eval::evaluate(
                &b,
                solver.as_ref(),
                &t_ab,
                &gt,
                None,
                &fmaps::eval::EvalParams::default(),
            )
            .map_err(crate::input_on(&files.target))?;
            drop(spinner);
            let (errors, title) = match &r.sym_errors {
                Some(s) => (s, "symmetry-aware error"),
                None => (&r.errors, "geodesic error"),
            };
            let per_vertex = fmaps::pictures::vertex_values(&a, &gt_source, errors);
            let img =
                fmaps::pictures::error_map(&a, &per_vertex, vmax, title, &view).map_err(runtime)?;
            if let Some(out) = &png {
                save(&img, out, &mut written)?;
            }
            if let Some(page) = &html {
                let scene = viewer_page(
                    [&files.source, &files.target],
                    [&a, &b],
                    &t_ab,
                    Some((&per_vertex, vmax)),
                    view.up,
                );
                save_html(&scene, page, &mut written)?;
            }
            if let Some(p) = ply {
                save_ply(
                    &a,
                    &viz::scalar_colors(&per_vertex, 0.0, vmax),
                    &p,
                    &mut written,
                )?;
            }
            extra.insert("mean_error".into(), json!(r.mean_error));
            extra.insert("sym_mean_error".into(), json!(r.sym_mean_error));
            extra.insert("geodesic".into(), json!(r.geodesic));
            if !json {
                let sym = r
                    .sym_mean_error
                    .map(|s| format!(", symmetry-aware {:.3}", 100.0 * s))
                    .unwrap_or_default();
                crate::outln!(
                    o,
                    "mean error x100 {:.3}{sym} ({} geodesics)",
                    100.0 * r.mean_error,
                    r.geodesic
                );
            }
            json
        }
        RenderCommand::Fmap {
            matrix,
            vmax,
            title,
            out,
            json,
        } => {
            positive("--vmax", vmax)?;
            let c = read_matrix(&matrix)?;
            let title = title.unwrap_or_else(|| {
                format!(
                    "{} ({} x {})",
                    matrix
                        .file_name()
                        .map_or(String::new(), |s| s.to_string_lossy().into_owned()),
                    c.nrows(),
                    c.ncols()
                )
            });
            save(&plot::heatmap(&title, &c, vmax), &out, &mut written)?;
            let small = c.iter().filter(|x| x.abs() < 0.1).count();
            let sparsity = small as f64 / c.len().max(1) as f64;
            extra.insert("rows".into(), json!(c.nrows()));
            extra.insert("cols".into(), json!(c.ncols()));
            extra.insert("sparsity".into(), json!(sparsity));
            if !json {
                crate::outln!(
                    o,
                    "{} x {}; {:.1}% of entries below 0.1 in magnitude",
                    c.nrows(),
                    c.ncols(),
                    100.0 * sparsity
                );
            }
            json
        }
        RenderCommand::Embedding {
            mesh,
            eigs,
            out,
            view,
            json,
        } => {
            let view = view.view()?;
            let which: [usize; 3] = eigs.as_slice().try_into().map_err(|_| {
                input(anyhow::anyhow!(
                    "--eigs takes three indices, e.g. 1,2,3 (got {})",
                    eigs.len()
                ))
            })?;
            let top = which.iter().max().copied().unwrap_or(0);
            if top > MAX_EIG_INDEX {
                return Err(input(anyhow::anyhow!(
                    "--eigs: index {top} is above {MAX_EIG_INDEX} (eigenfunctions that high oscillate below the resolution of a picture)"
                )));
            }
            let m = load(&mesh)?;
            let k = top + 1;
            if k >= m.n_vertices() {
                return Err(input(anyhow::anyhow!(
                    "--eigs: index {top} needs more eigenpairs than {} has vertices",
                    mesh.display()
                )));
            }
            let s = fmaps::spectrum(&m, k, &fmaps::SpectrumParams::default())
                .map_err(|e| crate::spectrum::spectrum_failure(e, &mesh.display().to_string()))?;
            let img =
                fmaps::pictures::spectral_embedding(&m, &s.basis, which, &view).map_err(runtime)?;
            save(&img, &out, &mut written)?;
            extra.insert(
                "eigenvalues".into(),
                json!(which.map(|j| s.basis.eigenvalues[j])),
            );
            json
        }
        RenderCommand::Features {
            meshes,
            model,
            out,
            view,
            json,
        } => {
            let view = view.view()?;
            let model = match &model {
                Some(p) => fmaps::learn::model::Model::load(p).map_err(input)?,
                None => fmaps::learn::model::Model::shipped().map_err(runtime)?,
            };
            let loaded = meshes
                .iter()
                .map(|p| load(p))
                .collect::<Result<Vec<_>, _>>()?;
            let features = meshes
                .iter()
                .zip(&loaded)
                .map(|(p, m)| model.features(m).map_err(crate::input_on(p)))
                .collect::<Result<Vec<_>, _>>()?;
            let img = fmaps::pictures::features_picture(
                &loaded.iter().collect::<Vec<_>>(),
                &features.iter().collect::<Vec<_>>(),
                &view,
            )
            .map_err(runtime)?;
            save(&img, &out, &mut written)?;
            extra.insert("features".into(), json!(model.architecture().outputs));
            json
        }
        RenderCommand::Curves {
            reports,
            label,
            title,
            out,
            json,
        } => {
            if !label.is_empty() && label.len() != reports.len() {
                return Err(input(anyhow::anyhow!(
                    "{} --label for {} reports: give one per report or none",
                    label.len(),
                    reports.len()
                )));
            }
            let mut series = Vec::new();
            let mut max_threshold = 0.0f64;
            for (i, path) in reports.iter().enumerate() {
                let (x, y, mean) = read_curve(path)?;
                max_threshold = max_threshold.max(x.last().copied().unwrap_or(0.0));
                let name = label.get(i).cloned().unwrap_or_else(|| {
                    path.file_stem()
                        .map_or(String::new(), |s| s.to_string_lossy().into_owned())
                });
                series.push(plot::Series {
                    label: format!("{name} ({:.2})", 100.0 * mean),
                    x,
                    y,
                });
            }
            save(
                &plot::cumulative_curves(&title, max_threshold, &series),
                &out,
                &mut written,
            )?;
            json
        }
        RenderCommand::Scalar {
            mesh,
            values,
            vmin,
            vmax,
            title,
            out,
            ply,
            view,
            json,
        } => {
            let view = view.view()?;
            let m = load(&mesh)?;
            let v = read_values(&values, m.n_vertices())?;
            let finite = v.iter().copied().filter(|x| x.is_finite());
            let lo = vmin.unwrap_or_else(|| finite.clone().fold(f64::INFINITY, f64::min));
            let hi = vmax.unwrap_or_else(|| finite.fold(f64::NEG_INFINITY, f64::max));
            if !lo.is_finite() || !hi.is_finite() || hi <= lo {
                return Err(input(anyhow::anyhow!(
                    "{}: no usable colour range (vmin {lo}, vmax {hi}); give --vmin/--vmax",
                    values.display()
                )));
            }
            let colors = viz::scalar_colors(&v, lo, hi);
            let img = viz::render(m.vertices(), m.faces(), &colors, &view).map_err(runtime)?;
            let bar = viz::colorbar(view.height, lo, hi, &title);
            save(&Image::hstack(&[img, bar], viz::WHITE), &out, &mut written)?;
            if let Some(p) = ply {
                save_ply(&m, &colors, &p, &mut written)?;
            }
            extra.insert("vmin".into(), json!(lo));
            extra.insert("vmax".into(), json!(hi));
            json
        }
    };
    let Written { staged, names } = written;
    staged.commit()?;
    let written = names;
    let seconds = t.elapsed().as_secs_f64();
    if json {
        extra.insert("written".into(), json!(written));
        extra.insert("seconds".into(), json!(seconds));
        return emit(&format!("{}\n", serde_json::Value::Object(extra)));
    }
    for p in &written {
        crate::outln!(o, "wrote {p}");
    }
    emit(&o)
}

/// The highest eigenfunction `render embedding` draws.
const MAX_EIG_INDEX: usize = 1000;

fn positive(flag: &str, x: f64) -> Result<(), Failure> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(input(anyhow::anyhow!("{flag} {x}: must be positive")))
    }
}

/// The PNG a picture command writes: `--out`, or without `--html` the
/// default name.
fn png_out(out: &Option<PathBuf>, html: &Option<PathBuf>, default: &str) -> Option<PathBuf> {
    match (out, html) {
        (Some(o), _) => Some(o.clone()),
        (None, None) => Some(PathBuf::from(default)),
        (None, Some(_)) => None,
    }
}

/// Writes the interactive viewer page (staged with the other outputs).
fn save_html(page: &ViewerPage<'_>, path: &Path, written: &mut Written) -> Result<(), Failure> {
    let text = page.html()?;
    written
        .staged
        .stage(path, |tmp| Ok(std::fs::write(tmp, text.as_bytes())?))?;
    written.names.push(path.display().to_string());
    Ok(())
}

fn save(img: &Image, path: &Path, written: &mut Written) -> Result<(), Failure> {
    written.staged.stage(path, |tmp| Ok(img.save_png(tmp)?))?;
    written.names.push(path.display().to_string());
    Ok(())
}

fn save_ply(
    mesh: &TriMesh,
    colors: &[[u8; 3]],
    path: &Path,
    written: &mut Written,
) -> Result<(), Failure> {
    written.staged.stage(path, |tmp| {
        Ok(fmaps::mesh_io::save_colored_ply(tmp, mesh, colors)?)
    })?;
    written.names.push(path.display().to_string());
    Ok(())
}
