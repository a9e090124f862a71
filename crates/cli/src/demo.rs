//! `fmaps demo`: the default pipeline on two built-in pairs, a
//! near-isometric one (the creature in two poses) and a non-isometric one
//! (two generated bodies of different builds in different poses), with
//! exact-geodesic errors and pictures; on the bodies also the learned
//! pipeline (`fmaps match --features learned`), next to the default.

use std::path::Path;
use std::time::Instant;

use fmaps::eval::{EvalParams, GroundTruth, MapReport, evaluate};
use fmaps::geodesic::ExactSolver;
use fmaps::mesh_io::TriMesh;
use fmaps::pipeline::{MatchParams, MatchResult, Refinement, match_prepared, prepare};
use fmaps::viz::{self, View, plot};
use serde_json::{Value, json};

use crate::outputs::Staged;
use crate::{Failure, emit, outln, runtime};

/// One built-in pair with its ground truth.
struct Case {
    /// What the pair is, for the report.
    title: String,
    /// Prefix of its pictures' file names.
    prefix: &'static str,
    a: TriMesh,
    b: TriMesh,
    truth: GroundTruth,
    /// The A vertex of each ground-truth row (for per-vertex pictures).
    rows: Vec<usize>,
}

/// What the default pipeline did on a case.
struct Outcome {
    r: MatchResult,
    init: MapReport,
    refined: MapReport,
    spectra: f64,
    eval_seconds: f64,
    /// The learned pipeline's map and its evaluation (the bodies only).
    learned: Option<(MatchResult, MapReport)>,
}

pub(crate) fn run(out_dir: &Path, subdivisions: u32, as_json: bool) -> Result<(), Failure> {
    if !(3..=6).contains(&subdivisions) {
        return Err(crate::input(anyhow::anyhow!(
            "--subdivisions {subdivisions}: use 3..=6 (3 = 642 vertices, 4 = 2,562, 5 = 10,242; the default refinement needs more than 200)"
        )));
    }
    let t0 = Instant::now();
    let spinner = crate::Spinner::new("generating the built-in pairs");
    let cases = cases(subdivisions)?;
    let mut params = MatchParams::unrefined();
    params.refinement = Refinement::recommended();
    std::fs::create_dir_all(out_dir)
        .map_err(|e| runtime(anyhow::anyhow!("{}: {e}", out_dir.display())))?;
    // Every picture is staged and all are renamed into place at the end:
    // a failure leaves the folder as it was.
    let mut staged = Staged::default();
    let mut written = Vec::new();
    let mut outcomes = Vec::new();
    for case in &cases {
        spinner.stage(&format!(
            "{}: eigenbases, functional map, refinement",
            case.title
        ));
        let o = run_case(case, &params, !case.prefix.is_empty())?;
        spinner.stage(&format!("{}: pictures", case.title));
        pictures(case, &o, out_dir, &mut staged, &mut written)?;
        outcomes.push(o);
    }
    staged.commit()?;
    let total = t0.elapsed().as_secs_f64();
    drop(spinner);

    let refine_name = outcomes[0].r.refine.as_ref().map(|x| x.method.clone());
    if as_json {
        let case_json = |c: &Case, o: &Outcome| -> Value {
            let st = &o.r.times;
            json!({
                "pair": c.title, "n_source": c.a.n_vertices(), "n_target": c.b.n_vertices(),
                "seconds": {"spectra": o.spectra, "descriptors": st.descriptors,
                    "operators": st.operators, "solve": st.solve, "point_map": st.point_map,
                    "refine": st.refine, "evaluation": o.eval_seconds},
                "mean_error_init": o.init.mean_error, "mean_error": o.refined.mean_error,
                "sym_mean_error": o.refined.sym_mean_error,
                "auc_init": o.init.auc, "auc": o.refined.auc, "orientation": o.r.orientation,
                "learned": o.learned.as_ref().map(|(r, rep)| json!({
                    "mean_error": rep.mean_error, "sym_mean_error": rep.sym_mean_error,
                    "auc": rep.auc, "seconds": r.times.total,
                    "refine": r.refine.as_ref().map(|x| x.method.clone()),
                })),
            })
        };
        let (iso, noniso) = (&outcomes[0], &outcomes[1]);
        let v = json!({
            "n_vertices": cases[0].a.n_vertices(), "k": params.k, "refine": refine_name,
            "seconds": {"spectra": iso.spectra, "refine": iso.r.times.refine, "total": total},
            "mean_error_init": iso.init.mean_error, "mean_error": iso.refined.mean_error,
            "auc_init": iso.init.auc, "auc": iso.refined.auc, "orientation": iso.r.orientation,
            "geodesic": iso.refined.geodesic, "pictures": written,
            "pairs": [case_json(&cases[0], iso), case_json(&cases[1], noniso)],
        });
        return emit(&format!("{v}\n"));
    }
    let mut o = String::new();
    outln!(
        o,
        "fmaps demo: the default pipeline ({}) on two built-in pairs",
        refine_name.as_deref().unwrap_or("no refinement")
    );
    for (c, r) in cases.iter().zip(&outcomes) {
        let st = &r.r.times;
        outln!(
            o,
            "{} ({} -> {} vertices)",
            c.title,
            c.a.n_vertices(),
            c.b.n_vertices()
        );
        let front = st.descriptors + st.operators + st.solve + st.point_map;
        for (name, sec) in [
            ("eigenbases (both)", r.spectra),
            ("initial map", front),
            ("refinement", st.refine),
            ("exact evaluation", r.eval_seconds),
        ] {
            outln!(o, "  {name:<18} {sec:>7.3} s");
        }
        let sym = r.refined.sym_mean_error.map_or(String::new(), |s| {
            format!(" (symmetry-aware {:.2})", 100.0 * s)
        });
        outln!(
            o,
            "  mean geodesic error x100 (exact, / sqrt(area)): initial map {:.2}, refined {:.2}{sym}",
            100.0 * r.init.mean_error,
            100.0 * r.refined.mean_error
        );
        outln!(
            o,
            "  AUC on [0, 0.25]: {:.3} -> {:.3}; orientation score {:.3}",
            r.init.auc,
            r.refined.auc,
            r.r.orientation
        );
        if let Some((lr, rep)) = &r.learned {
            let sym = rep.sym_mean_error.map_or(String::new(), |s| {
                format!(" (symmetry-aware {:.2})", 100.0 * s)
            });
            outln!(
                o,
                "  learned features (--features learned, {:.2} s): mean error x100 {:.2}{sym}, AUC {:.3}",
                lr.times.total,
                100.0 * rep.mean_error,
                rep.auc
            );
        }
    }
    outln!(o, "total {total:.2} s; pictures in {}:", out_dir.display());
    for p in &written {
        outln!(o, "  {p}");
    }
    emit(&o)
}

/// The library's built-in pairs as cases (the non-isometric one's
/// pictures prefixed `noniso-`; errors drawn on A's ground-truth rows).
fn cases(subdivisions: u32) -> Result<Vec<Case>, Failure> {
    let pairs = fmaps::demo::demo_pairs(subdivisions).map_err(|e| runtime(anyhow::anyhow!(e)))?;
    pairs
        .into_iter()
        .map(|p| {
            Ok(Case {
                truth: p.truth().map_err(runtime)?,
                rows: p.gt_a,
                prefix: if p.name == "bodies" { "noniso-" } else { "" },
                title: p.title,
                a: p.a,
                b: p.b,
            })
        })
        .collect()
}

fn run_case(case: &Case, params: &MatchParams, learned: bool) -> Result<Outcome, Failure> {
    let t = Instant::now();
    let learned_params = if learned {
        let l = fmaps::pipeline::LearnedFeatures::shipped().map_err(runtime)?;
        Some(MatchParams::learned(case.a.n_vertices(), case.b.n_vertices(), l).map_err(runtime)?)
    } else {
        None
    };
    let mut single = params.clone();
    if let Some(l) = &learned_params {
        // One preparation serves both pipelines.
        single.features = l.features.clone();
        single.k_process = single.k_process.max(l.k_process);
    }
    single.spectrum.threads = 1;
    let (pa, pb) = rayon::join(|| prepare(&case.a, &single), || prepare(&case.b, &single));
    let (pa, pb) = (pa.map_err(runtime)?, pb.map_err(runtime)?);
    let spectra = t.elapsed().as_secs_f64();
    let r = match_prepared(&pa, &pb, params).map_err(runtime)?;
    let t = Instant::now();
    let solver = ExactSolver::new(&case.b).map_err(runtime)?;
    let ep = EvalParams::default();
    let eval = |t_ab: &[usize]| -> Result<MapReport, Failure> {
        evaluate(&case.b, &solver, t_ab, &case.truth, None, &ep).map_err(runtime)
    };
    let (init, refined) = (eval(&r.t_ab_init)?, eval(&r.t_ab)?);
    let eval_seconds = t.elapsed().as_secs_f64();
    let learned = match &learned_params {
        Some(p) => {
            let l = match_prepared(&pa, &pb, p).map_err(runtime)?;
            let rep = eval(&l.t_ab)?;
            Some((l, rep))
        }
        None => None,
    };
    Ok(Outcome {
        r,
        init,
        refined,
        spectra,
        eval_seconds,
        learned,
    })
}

/// The pictures of a case (names with the case's prefix), staged.
fn pictures(
    case: &Case,
    o: &Outcome,
    out_dir: &Path,
    staged: &mut Staged,
    written: &mut Vec<String>,
) -> Result<(), Failure> {
    let (a, b, r) = (&case.a, &case.b, &o.r);
    let view = View::default();
    let mut save = |img: viz::Image, name: &str| -> Result<(), Failure> {
        let p = out_dir.join(format!("{}{name}", case.prefix));
        staged.stage(&p, |tmp| Ok(img.save_png(tmp)?))?;
        written.push(p.display().to_string());
        Ok(())
    };
    let (img, cs, ct) = fmaps::pictures::color_transfer(a, b, &r.t_ab, &view).map_err(runtime)?;
    save(img, "color-transfer.png")?;
    let (img_init, _, _) =
        fmaps::pictures::color_transfer(a, b, &r.t_ab_init, &view).map_err(runtime)?;
    save(img_init, "color-transfer-init.png")?;
    if let Some((l, _)) = &o.learned {
        let (img, _, _) = fmaps::pictures::color_transfer(a, b, &l.t_ab, &view).map_err(runtime)?;
        save(img, "learned-color-transfer.png")?;
    }
    let (img, _, _) =
        fmaps::pictures::texture_transfer(a, b, &r.t_ab, 12, &view).map_err(runtime)?;
    save(img, "texture-transfer.png")?;
    let vmax = 0.1;
    for (rep, name, title) in [
        (&o.refined, "error.png", "error, default pipeline"),
        (&o.init, "error-init.png", "error, initial map"),
    ] {
        let per_vertex = fmaps::pictures::vertex_values(a, &case.rows, &rep.errors);
        let img =
            fmaps::pictures::error_map(a, &per_vertex, vmax, title, &view).map_err(runtime)?;
        save(img, name)?;
    }
    save(
        plot::heatmap(
            &format!("C_BA, refined ({0} x {0})", r.c_ba.nrows()),
            &r.c_ba,
            1.0,
        ),
        "fmap.png",
    )?;
    let mut series = vec![
        plot::Series {
            label: format!("initial map ({:.2})", 100.0 * o.init.mean_error),
            x: o.init.thresholds.clone(),
            y: o.init.curve.clone(),
        },
        plot::Series {
            label: format!("default pipeline ({:.2})", 100.0 * o.refined.mean_error),
            x: o.refined.thresholds.clone(),
            y: o.refined.curve.clone(),
        },
    ];
    if let Some((_, rep)) = &o.learned {
        series.push(plot::Series {
            label: format!("learned features ({:.2})", 100.0 * rep.mean_error),
            x: rep.thresholds.clone(),
            y: rep.curve.clone(),
        });
    }
    save(
        plot::cumulative_curves(
            &format!("{}: cumulative geodesic error", case.title),
            EvalParams::default().max_threshold,
            &series,
        ),
        "curves.png",
    )?;
    for (mesh, colors, name) in [(a, &cs, "source.ply"), (b, &ct, "target.ply")] {
        let p = out_dir.join(format!("{}{name}", case.prefix));
        staged.stage(&p, |tmp| {
            Ok(fmaps::mesh_io::save_colored_ply(tmp, mesh, colors)?)
        })?;
        written.push(p.display().to_string());
    }
    // The interactive viewer: the map, its error, picking.
    let per_vertex = fmaps::pictures::vertex_values(a, &case.rows, &o.refined.errors);
    let page = crate::viewer_page::ViewerPage {
        title: case.title.clone(),
        names: ["source".into(), "target".into()],
        meshes: [a, b],
        t_ab: &r.t_ab,
        error: Some((&per_vertex, vmax)),
        up: view.up,
    }
    .html()?;
    let p = out_dir.join(format!("{}viewer.html", case.prefix));
    staged.stage(&p, |tmp| Ok(std::fs::write(tmp, page.as_bytes())?))?;
    written.push(p.display().to_string());
    Ok(())
}
