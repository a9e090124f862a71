//! `fmaps refine`: refine a point map from elsewhere.

use super::*;

use fmaps::pipeline::{MatchParams, Refinement};

use crate::match_cmd::refiner_kind_parser;
use crate::match_failure;
use fmaps::pipeline::RefinerKind;

/// Options of `fmaps refine`.
#[derive(clap::Args)]
pub(crate) struct RefineArgs {
    /// Source mesh A (.off, .obj, .ply).
    source: PathBuf,
    /// Target mesh B.
    target: PathBuf,
    /// The map to refine, A -> B, from any tool: one B vertex per A vertex,
    /// 1-based text (.map), or 0-based integers in a NumPy file (.npy,
    /// .npz; any integer dtype).
    #[arg(long)]
    init_map: PathBuf,
    /// The refinement.
    #[arg(long, value_parser = refiner_kind_parser(), default_value = "zoomout")]
    refine: RefinerKind,
    /// Size of the map's functional map (k x k) that the refinement starts
    /// from (ZoomOut: at least START).
    #[arg(long, short = 'k', default_value_t = MatchParams::default().k)]
    k: usize,
    #[command(flatten)]
    refiner: crate::match_cmd::RefinerFlags,
    /// Keep the meshes' own units (no scaling to unit area).
    #[arg(long)]
    no_area_normalize: bool,
    /// Output map T: A -> B (.map, 1-based; .npy/.npz, 0-based int64).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write the refined C_BA as text (or float64 .npy/.npz).
    #[arg(long)]
    save_fmap: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// The refinement for meshes of `sizes.0` and `sizes.1` vertices.
fn refinement(args: &RefineArgs, sizes: (usize, usize)) -> Result<Refinement, Failure> {
    let options = args.refiner.options(args.k, false, false, sizes);
    fmaps::pipeline::named_refinement(args.refine, &options)
        .map_err(crate::match_cmd::zoomout_failure)
}

pub(crate) fn refine_cmd(args: &RefineArgs) -> Result<(), Failure> {
    use fmaps::pipeline::{prepare, refine_point_map};
    let outs: Vec<&Path> = [&args.out, &args.save_fmap]
        .into_iter()
        .flatten()
        .map(PathBuf::as_path)
        .collect();
    crate::outputs::check_outputs(&[&args.source, &args.target, &args.init_map], &outs)?;
    let t = Instant::now();
    let a = load(&args.source)?;
    let b = load(&args.target)?;
    let t_ab = read_indices(&args.init_map, b.n_vertices(), false)?;
    if t_ab.len() != a.n_vertices() {
        return Err(input(anyhow::anyhow!(
            "{}: {} lines, but {} has {} vertices (one target per source vertex)",
            args.init_map.display(),
            t_ab.len(),
            args.source.display(),
            a.n_vertices()
        )));
    }
    let refine = refinement(args, (a.n_vertices(), b.n_vertices()))?;
    let mut params = MatchParams::unrefined();
    params.k = args.k;
    params.refinement = refine;
    params.adjoint = args.refiner.adjoint;
    params.area_normalize = !args.no_area_normalize;
    params.k_process = args.k.max(params.refinement.k_needed());
    // No descriptors are computed; keep their size within the basis.
    params.descriptors.eigenpairs = params.descriptors.eigenpairs.min(params.k_process);
    if params.k == 0 {
        return Err(input(anyhow::anyhow!(
            "--k 0: the map needs at least one basis function"
        )));
    }
    let spinner = Spinner::new("eigenbases of both shapes");
    let mut single = params.clone();
    single.spectrum.threads = 1;
    let (pa, pb) = rayon::join(|| prepare(&a, &single), || prepare(&b, &single));
    let pa = pa.map_err(|e| match_failure(e, Some(&args.source)))?;
    let pb = pb.map_err(|e| match_failure(e, Some(&args.target)))?;
    let spectra = t.elapsed().as_secs_f64();
    spinner.stage("refinement");
    let r = refine_point_map(&pa, &pb, &t_ab, &params).map_err(runtime)?;
    drop(spinner);
    crate::outputs::write_map_outputs(
        args.out.as_deref(),
        args.save_fmap.as_deref(),
        &r.t_ab,
        &r.c_ba,
    )?;
    let quality = fmaps::eval::map_quality(&r.t_ab, &a, &b, None).map_err(runtime)?;
    let quality_init = fmaps::eval::map_quality(&r.t_ab_init, &a, &b, None).map_err(runtime)?;
    let changed = r
        .t_ab
        .iter()
        .zip(&r.t_ab_init)
        .filter(|(x, y)| x != y)
        .count();
    let total = t.elapsed().as_secs_f64();
    if args.json {
        let v = json!({
            "source": args.source.display().to_string(),
            "target": args.target.display().to_string(),
            "init_map": args.init_map.display().to_string(),
            "n_source": a.n_vertices(), "n_target": b.n_vertices(), "k": args.k,
            "area_normalized": params.area_normalize,
            "out": args.out.as_ref().map(|p| p.display().to_string()),
            "seconds": {"load_and_spectra": spectra, "refine": r.seconds, "total": total},
            "refine": r.refine.as_ref().map(|rep| json!({
                "method": rep.method, "iterations": rep.iterations.len(),
                "converged": rep.converged, "nn_searches": rep.nn_searches,
                "final_k": r.c_ba.ncols(),
            })),
            "orientation_init": r.orientation_init,
            "orientation": r.orientation,
            "quality_init": quality_init,
            "quality": quality,
            "changed_by_refinement": changed,
            "init_orthonormality": r.metrics_init.orthonormality,
            "init_laplacian_commutativity": r.metrics_init.laplacian_commutativity,
        });
        return emit(&format!("{v}\n"));
    }
    let mut o = String::new();
    outln!(
        o,
        "{} ({} vertices) -> {} ({} vertices): map from {}",
        args.source.display(),
        a.n_vertices(),
        args.target.display(),
        b.n_vertices(),
        args.init_map.display()
    );
    outln!(o, "  eigenbases       {spectra:>8.3} s");
    outln!(o, "  refinement       {:>8.3} s", r.seconds);
    if let Some(rep) = &r.refine {
        outln!(
            o,
            "{}: {} iterations, final k = {}; {changed} of {} vertices moved",
            rep.method,
            rep.iterations.len(),
            r.c_ba.ncols(),
            a.n_vertices()
        );
    }
    outln!(
        o,
        "orientation score {:.3} -> {:.3} (1: preserved, -1: mirrored)",
        r.orientation_init,
        r.orientation
    );
    for (name, q) in [("given", quality_init), ("refined", quality)] {
        outln!(
            o,
            "{name:>8} map: coverage {:.3}, collapsed faces {:.3}, area distortion {:.3}, conformal distortion {:.3}",
            q.coverage,
            q.collapsed_faces,
            q.area_distortion,
            q.conformal_distortion
        );
    }
    match &args.out {
        Some(p) => outln!(o, "wrote {}", p.display()),
        None => outln!(o, "(no --out: map not written)"),
    }
    emit(&o)
}
