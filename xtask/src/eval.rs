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
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;

use crate::util::{data_dir, root};

/// Options of `cargo xtask eval`.
#[derive(clap::Args)]
pub struct Args {
    /// Collections to evaluate (default: FAUST and TOSCA_Isometric).
    #[arg(long = "collection")]
    collections: Vec<String>,
    /// Only the first N test pairs (default: all).
    #[arg(long)]
    pairs: Option<usize>,
    /// Methods (default: every published method found in maps/).
    #[arg(long = "method")]
    methods: Vec<String>,
    /// Dataset directory (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Geodesic method: exact or dijkstra.
    #[arg(long, default_value = "exact")]
    geodesic: String,
}

pub fn eval(args: &Args) -> anyhow::Result<()> {
    let bcicp = data_dir(args.data.as_deref()).join("bcicp");
    if !bcicp.is_dir() {
        bail!(
            "{} not found: pass --data or set FMAPS_DATA",
            bcicp.display()
        );
    }
    let collections = if args.collections.is_empty() {
        vec!["FAUST".to_string(), "TOSCA_Isometric".to_string()]
    } else {
        args.collections.clone()
    };
    let out_dir = root().join("target/eval");
    std::fs::create_dir_all(&out_dir)?;
    let params = EvalParams::default();
    let mut rows = Vec::new();
    for cname in &collections {
        let c = Collection::open(&bcicp, cname)?;
        let mut pairs = c.test_pairs()?;
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
            let maps = c
                .published_maps(method)
                .with_context(|| format!("method {method} of {cname}"))?;
            let bar = ProgressBar::new(pairs.len() as u64).with_style(
                ProgressStyle::with_template(
                    "{msg:32} [{bar:30}] {pos}/{len} {elapsed_precise} eta {eta}",
                )?
                .progress_chars("=> "),
            );
            bar.set_message(format!("{cname} {method}"));
            let mut per_pair = Vec::new();
            let mut missing = 0;
            let mut curve_sum = vec![0.0; params.n_thresholds];
            let mut geodesic_name = "";
            let t0 = Instant::now();
            for (a, b) in &pairs {
                bar.inc(1);
                let Some(t_ab) = maps.read(a, b)? else {
                    missing += 1;
                    continue;
                };
                for s in [a, b] {
                    if !meshes.contains_key(s) {
                        meshes.insert(s.clone(), c.read_mesh(s)?);
                    }
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
                geodesic_name = r.geodesic;
                curve_sum
                    .iter_mut()
                    .zip(&r.curve)
                    .for_each(|(s, c)| *s += c);
                per_pair.push(json!({
                    "source": a, "target": b, "mean_error": r.mean_error, "sym_mean_error": r.sym_mean_error,
                    "auc": r.auc, "coverage": r.coverage, "seconds": r.seconds,
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
                "thresholds": thresholds(&params), "curve": curve, "per_pair": per_pair,
            });
            let path = out_dir.join(format!("{cname}-{method}.json"));
            std::fs::write(&path, serde_json::to_string_pretty(&row)?)?;
            rows.push(row);
        }
    }
    println!(
        "{:<16} {:<16} {:>6} {:>10} {:>10} {:>7} {:>9} {:>8}  geodesics",
        "collection", "method", "pairs", "mean x100", "sym x100", "AUC", "coverage", "s/pair"
    );
    for r in &rows {
        println!(
            "{:<16} {:<16} {:>6} {:>10.3} {:>10.3} {:>7.4} {:>9.4} {:>8.2}  {}",
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
            r["seconds_per_pair"].as_f64().unwrap_or(f64::NAN),
            r["geodesic"].as_str().unwrap_or(""),
        );
    }
    println!(
        "(* some pairs had no map; errors are d/sqrt(area) x100, AUC of the mean cumulative curve on [0, 0.25])"
    );
    for cname in &collections {
        let series: Vec<crate::plot::Series> = rows
            .iter()
            .filter(|r| r["collection"] == cname.as_str())
            .map(|r| crate::plot::Series {
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
        crate::plot::line_plot_png(
            &png,
            &crate::plot::Plot {
                title: &title,
                x_label: "geodesic error / sqrt(area)",
                y_label: "fraction of points",
                x_range: (0.0, params.max_threshold),
                y_range: (0.0, 1.0),
                x_ticks: vec![0.0, 0.05, 0.1, 0.15, 0.2, 0.25],
                y_ticks: vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0],
            },
            &series,
        )?;
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
