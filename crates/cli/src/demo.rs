//! `fmaps demo`: the whole method on the built-in creature pair, with
//! exact-geodesic errors and pictures.

use std::path::Path;
use std::time::Instant;

use fmaps::eval::{EvalParams, GroundTruth, MapReport, evaluate};
use fmaps::geodesic::ExactSolver;
use fmaps::mesh_io::generate::creature_pair;
use fmaps::pipeline::{MatchParams, Refinement, match_prepared, prepare};
use fmaps::viz::{self, View, plot};
use serde_json::json;

use crate::{Failure, emit, outln, runtime};

pub(crate) fn run(out_dir: &Path, subdivisions: u32, as_json: bool) -> Result<(), Failure> {
    if !(3..=6).contains(&subdivisions) {
        return Err(crate::input(anyhow::anyhow!(
            "--subdivisions {subdivisions}: use 3..=6 (3 = 642 vertices, 4 = 2,562, 5 = 10,242; ZoomOut to 150 eigenpairs needs more than 162)"
        )));
    }
    let t0 = Instant::now();
    let spinner = crate::Spinner::new("generating the built-in pair");
    let pair = creature_pair(subdivisions);
    let (a, b) = (&pair.source, &pair.target);
    let n = a.n_vertices();
    let params = MatchParams {
        refine: Refinement::default_zoomout(),
        ..MatchParams::default()
    };
    spinner.stage("Laplacians and eigenbases of both shapes");
    let t = Instant::now();
    let mut single = params.clone();
    single.spectrum.threads = 1;
    let (pa, pb) = rayon::join(|| prepare(a, &single), || prepare(b, &single));
    let (pa, pb) = (pa.map_err(runtime)?, pb.map_err(runtime)?);
    let spectra = t.elapsed().as_secs_f64();
    spinner.stage("descriptors, functional map, ZoomOut");
    let r = match_prepared(&pa, &pb, &params).map_err(runtime)?;
    spinner.stage("exact geodesic errors");

    let t = Instant::now();
    let gt = GroundTruth::new((0..n).collect(), pair.truth.clone(), None).map_err(runtime)?;
    let solver = ExactSolver::new(b).map_err(runtime)?;
    let ep = EvalParams::default();
    let eval = |t_ab: &[usize]| -> Result<MapReport, Failure> {
        evaluate(b, &solver, t_ab, &gt, None, &ep).map_err(runtime)
    };
    let (init, refined) = (eval(&r.t_ab_init)?, eval(&r.t_ab)?);
    let eval_seconds = t.elapsed().as_secs_f64();

    spinner.stage("pictures");
    std::fs::create_dir_all(out_dir)
        .map_err(|e| runtime(anyhow::anyhow!("{}: {e}", out_dir.display())))?;
    let view = View::default();
    // Every picture is staged and all are renamed into place at the end:
    // a failure leaves the folder as it was.
    let mut staged = crate::outputs::Staged::default();
    let mut written = Vec::new();
    let mut save = |img: viz::Image, name: &str| -> Result<(), Failure> {
        let p = out_dir.join(name);
        staged.stage(&p, |tmp| Ok(img.save_png(tmp)?))?;
        written.push(p.display().to_string());
        Ok(())
    };
    let (img, cs, ct) = fmaps::pictures::color_transfer(a, b, &r.t_ab, &view).map_err(runtime)?;
    save(img, "color-transfer.png")?;
    let (img_init, _, _) =
        fmaps::pictures::color_transfer(a, b, &r.t_ab_init, &view).map_err(runtime)?;
    save(img_init, "color-transfer-init.png")?;
    let (img, _, _) =
        fmaps::pictures::texture_transfer(a, b, &r.t_ab, 12, &view).map_err(runtime)?;
    save(img, "texture-transfer.png")?;
    let vmax = 0.1;
    for (rep, name, title) in [
        (&refined, "error-zoomout.png", "error, ZoomOut"),
        (&init, "error-init.png", "error, initial"),
    ] {
        let img =
            fmaps::pictures::error_map(a, &rep.errors, vmax, title, &view).map_err(runtime)?;
        save(img, name)?;
    }
    save(
        plot::heatmap(
            &format!("C_BA after ZoomOut ({0} x {0})", r.c_ba.nrows()),
            &r.c_ba,
            1.0,
        ),
        "fmap.png",
    )?;
    let img =
        fmaps::pictures::spectral_embedding(a, &pa.basis, [1, 2, 3], &view).map_err(runtime)?;
    save(img, "spectral-embedding.png")?;
    let series = vec![
        plot::Series {
            label: format!("initial map ({:.2})", 100.0 * init.mean_error),
            x: init.thresholds.clone(),
            y: init.curve.clone(),
        },
        plot::Series {
            label: format!("after ZoomOut ({:.2})", 100.0 * refined.mean_error),
            x: refined.thresholds.clone(),
            y: refined.curve.clone(),
        },
    ];
    save(
        plot::cumulative_curves(
            "built-in creature pair: cumulative geodesic error",
            ep.max_threshold,
            &series,
        ),
        "curves.png",
    )?;
    for (mesh, colors, name) in [(a, &cs, "source.ply"), (b, &ct, "target.ply")] {
        let p = out_dir.join(name);
        staged.stage(&p, |tmp| {
            Ok(viz::write_colored_ply(
                tmp,
                mesh.vertices(),
                mesh.faces(),
                colors,
            )?)
        })?;
        written.push(p.display().to_string());
    }
    staged.commit()?;
    let total = t0.elapsed().as_secs_f64();
    drop(spinner);

    let st = &r.times;
    if as_json {
        let v = json!({
            "n_vertices": n, "k": params.k, "refine": r.refine.as_ref().map(|x| x.method.clone()),
            "seconds": {"spectra": spectra, "descriptors": st.descriptors, "operators": st.operators,
                "solve": st.solve, "point_map": st.point_map, "refine": st.refine,
                "evaluation": eval_seconds, "total": total},
            "mean_error_init": init.mean_error, "mean_error": refined.mean_error,
            "auc_init": init.auc, "auc": refined.auc, "orientation": r.orientation,
            "geodesic": refined.geodesic, "pictures": written,
        });
        return emit(&format!("{v}\n"));
    }
    let mut o = String::new();
    outln!(
        o,
        "fmaps demo: the built-in creature at rest -> walking ({n} vertices each; target renumbered and moved)"
    );
    for (name, sec) in [
        ("eigenbases (both)", spectra),
        ("descriptors", st.descriptors),
        ("operators", st.operators),
        ("solve", st.solve),
        ("point map", st.point_map),
        ("ZoomOut 50->150", st.refine),
        ("exact evaluation", eval_seconds),
        ("total", total),
    ] {
        outln!(o, "  {name:<18} {sec:>7.3} s");
    }
    outln!(
        o,
        "mean geodesic error x100 (exact, / sqrt(area)): initial map {:.2}, after ZoomOut {:.2}",
        100.0 * init.mean_error,
        100.0 * refined.mean_error
    );
    outln!(
        o,
        "AUC on [0, 0.25]: {:.3} -> {:.3}; orientation score {:.3}",
        init.auc,
        refined.auc,
        r.orientation
    );
    outln!(o, "pictures in {}:", out_dir.display());
    for p in &written {
        outln!(o, "  {p}");
    }
    emit(&o)
}
