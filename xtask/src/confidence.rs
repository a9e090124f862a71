//! `cargo xtask confidence`: does a score without ground truth see a
//! globally wrong map? For each collection and method evaluated with
//! `cargo xtask eval --save-maps`, every saved map is scored without
//! ground truth (metric distortion, [`fmaps::eval::metric_distortion`];
//! area and conformal distortion, [`fmaps::eval::map_quality`]) next to
//! its true error from the evaluation's report. Printed: per method the
//! bad maps (true error above `--bad` ×100), the area under the ROC curve
//! of each score as a detector of them, the precision and recall of the
//! warning (metric or area distortion above its threshold, as `fmaps
//! match` warns); across methods, the error of keeping per pair the
//! map of lowest metric distortion, beside the best map per pair (the
//! oracle). Written to `target/eval/confidence-<collection>.json`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use fmaps::eval::{map_quality, metric_distortion};
use serde_json::json;

use crate::util::{bcicp_dir, root};

/// Options of `cargo xtask confidence`.
#[derive(clap::Args)]
pub struct Args {
    /// Collections (any of `cargo xtask eval`'s), evaluated with --save-maps.
    #[arg(long = "collection", required = true)]
    collections: Vec<String>,
    /// Methods evaluated on them (their reports and saved maps are read).
    #[arg(long = "method", required = true)]
    methods: Vec<String>,
    /// A map is bad when its true mean error is above this (×100).
    #[arg(long, default_value_t = 30.0)]
    bad: f64,
    /// The warning threshold of metric distortion whose precision and
    /// recall are reported (with --warn-area-above: either above warns).
    #[arg(long, default_value_t = fmaps::pipeline::Confidence::WARN_ABOVE)]
    warn_above: f64,
    /// The warning threshold of area distortion.
    #[arg(long, default_value_t = fmaps::pipeline::Confidence::WARN_AREA_ABOVE)]
    warn_area_above: f64,
    /// Samples of the metric distortion.
    #[arg(long, default_value_t = fmaps::pipeline::Confidence::SAMPLES)]
    samples: usize,
    /// Print every pair: true error, the initial map's, the scores.
    #[arg(long)]
    per_pair: bool,
    /// Dataset directory (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    data: Option<PathBuf>,
}

/// A score of a scored map.
type ScoreOf = dyn Fn(&Scored) -> f64;

/// One scored map.
struct Scored {
    source: String,
    target: String,
    error: f64,
    /// The pipeline's initial map's error (before refinement), when saved.
    init_error: Option<f64>,
    distortion: f64,
    long_range: f64,
    area: f64,
    conformal: f64,
}

/// Area under the ROC curve of `score` as a detector of `bad` (the chance
/// that a bad map scores above a good one, ties half): 1 separates
/// perfectly, 0.5 is chance. `None` when either class is empty.
fn auc(items: &[(f64, bool)]) -> Option<f64> {
    let bad: Vec<f64> = items.iter().filter(|x| x.1).map(|x| x.0).collect();
    let good: Vec<f64> = items.iter().filter(|x| !x.1).map(|x| x.0).collect();
    if bad.is_empty() || good.is_empty() {
        return None;
    }
    let mut wins = 0.0;
    for b in &bad {
        for g in &good {
            wins += if b > g {
                1.0
            } else if b == g {
                0.5
            } else {
                0.0
            };
        }
    }
    Some(wins / (bad.len() * good.len()) as f64)
}

/// A map is bad when its error (x100) is above `bad`.
fn is_bad_error(error: f64, bad: f64) -> bool {
    error > bad
}

/// `cargo xtask confidence`.
pub fn confidence(args: &Args) -> anyhow::Result<()> {
    use rayon::prelude::*;
    let bcicp = bcicp_dir(args.data.as_deref())?;
    let out_dir = root().join("target/eval");
    for cname in &args.collections {
        let (c, pairs) = crate::eval::collection_pairs(&bcicp, cname)?;
        // Every shape of the collection's pairs, read once for all methods.
        let mut names: Vec<&String> = pairs.iter().flat_map(|(a, b)| [a, b]).collect();
        names.sort();
        names.dedup();
        let meshes: std::collections::HashMap<String, fmaps::mesh_io::TriMesh> = names
            .par_iter()
            .map(|&s| Ok((s.clone(), c.read_mesh(s)?)))
            .collect::<anyhow::Result<_>>()?;
        let mesh = |s: &str| {
            meshes
                .get(s)
                .with_context(|| format!("{s} is not a shape of {cname}'s pairs"))
        };
        let mut by_method = Vec::new();
        let mut report = Vec::new();
        println!("{cname}: bad = mean error above {} x100", args.bad);
        println!(
            "{:<40} {:>5} {:>9} {:>4}  {:>8} {:>8} {:>8} {:>8}  {:>9} {:>7}",
            "method",
            "pairs",
            "mean x100",
            "bad",
            "AUC dist",
            "AUC long",
            "AUC area",
            "AUC conf",
            "precision",
            "recall"
        );
        for method in &args.methods {
            let json_path = out_dir.join(format!("{cname}-{method}.json"));
            let maps_dir = out_dir.join("maps").join(format!("{cname}-{method}"));
            let eval: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(&json_path).with_context(|| {
                    format!("{}: run cargo xtask eval --save-maps", json_path.display())
                })?)?;
            let Some(per_pair) = eval["per_pair"].as_array() else {
                bail!("{}: no per_pair", json_path.display());
            };
            let scored: Vec<Scored> = per_pair
                .par_iter()
                .map(|p| -> anyhow::Result<Scored> {
                    let (a, b) = (
                        p["source"].as_str().unwrap_or_default(),
                        p["target"].as_str().unwrap_or_default(),
                    );
                    let t = fmaps::mesh_io::read_map(maps_dir.join(format!("{a}_{b}.map")))?;
                    let (ma, mb) = (mesh(a)?, mesh(b)?);
                    let d = metric_distortion(&t, ma, mb, args.samples)?;
                    let q = map_quality(&t, ma, mb, None)?;
                    Ok(Scored {
                        source: a.to_string(),
                        target: b.to_string(),
                        error: 100.0 * p["mean_error"].as_f64().unwrap_or(f64::NAN),
                        init_error: p["init_mean_error"].as_f64().map(|e| 100.0 * e),
                        distortion: d.mean,
                        long_range: d.long_range,
                        area: q.area_distortion,
                        conformal: q.conformal_distortion,
                    })
                })
                .collect::<anyhow::Result<_>>()?;
            let is_bad = |s: &Scored| is_bad_error(s.error, args.bad);
            let roc = |f: &dyn Fn(&Scored) -> f64| {
                auc(&scored.iter().map(|s| (f(s), is_bad(s))).collect::<Vec<_>>())
            };
            let warned = scored
                .iter()
                .filter(|s| s.distortion > args.warn_above || s.area > args.warn_area_above);
            let (n_warned, n_hit) =
                warned.fold((0, 0), |(w, h), s| (w + 1, h + usize::from(is_bad(s))));
            let n_bad = scored.iter().filter(|s| is_bad(s)).count();
            let mean = scored.iter().map(|s| s.error).sum::<f64>() / scored.len().max(1) as f64;
            let fmt = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.3}"));
            let precision = (n_warned > 0).then(|| n_hit as f64 / n_warned as f64);
            let recall = (n_bad > 0).then(|| n_hit as f64 / n_bad as f64);
            let (a_dist, a_long) = (roc(&|s| s.distortion), roc(&|s| s.long_range));
            let (a_area, a_conf) = (roc(&|s| s.area), roc(&|s| s.conformal));
            println!(
                "{:<40} {:>5} {:>9.2} {:>4}  {:>8} {:>8} {:>8} {:>8}  {:>9} {:>7}",
                method,
                scored.len(),
                mean,
                n_bad,
                fmt(a_dist),
                fmt(a_long),
                fmt(a_area),
                fmt(a_conf),
                fmt(precision),
                fmt(recall)
            );
            // Which stage went wrong: the initial (descriptor) map already,
            // or the refinement (alignment screen, then deformation or
            // spectral refinement) from a good start.
            let (mut from_init, mut in_refinement, mut rescued) = (0, 0, 0);
            for s in &scored {
                match (s.init_error.map(|e| e > args.bad), is_bad(s)) {
                    (Some(true), true) => from_init += 1,
                    (Some(false), true) => in_refinement += 1,
                    (Some(true), false) => rescued += 1,
                    _ => {}
                }
            }
            println!(
                "{:<40} bad maps: {from_init} from a bad initial map, {in_refinement} lost by the refinement from a good one; {rescued} bad initial maps repaired",
                ""
            );
            if args.per_pair {
                for s in &scored {
                    println!(
                        "  {:<16} {:<16} error {:7.2} init {:>7} distortion {:.3} long {:.3} area {:.3} conformal {:.3}{}",
                        s.source,
                        s.target,
                        s.error,
                        s.init_error.map_or("-".into(), |e| format!("{e:.2}")),
                        s.distortion,
                        s.long_range,
                        s.area,
                        s.conformal,
                        if is_bad(s) { "  BAD" } else { "" }
                    );
                }
            }
            report.push(json!({
                "method": method, "bad_from_init": from_init, "bad_in_refinement": in_refinement,
                "repaired": rescued, "pairs": scored.len(), "mean_error": mean, "bad": n_bad,
                "auc_distortion": a_dist, "auc_long_range": a_long, "auc_area": a_area,
                "auc_conformal": a_conf, "warned": n_warned, "precision": precision, "recall": recall,
                "per_pair": scored.iter().map(|s| json!({
                    "source": s.source, "target": s.target, "error": s.error, "init_error": s.init_error,
                    "distortion": s.distortion, "long_range": s.long_range,
                    "area": s.area, "conformal": s.conformal,
                })).collect::<Vec<_>>(),
            }));
            by_method.push(scored);
        }
        if by_method.len() > 1 {
            let n = by_method[0].len();
            if by_method.iter().any(|m| m.len() != n) {
                bail!("{cname}: the methods were evaluated on different pairs");
            }
            // Agreement of the first two methods: the mean distance on B
            // between their images of samples spread over A (Dijkstra, at
            // unit area). Maps that disagree cannot both be right.
            let dirs: Vec<PathBuf> = args.methods[..2]
                .iter()
                .map(|m| out_dir.join("maps").join(format!("{cname}-{m}")))
                .collect();
            let disagreement: Vec<f64> = (0..n)
                .into_par_iter()
                .map(|i| -> anyhow::Result<f64> {
                    let (a, b) = (&by_method[0][i].source, &by_method[0][i].target);
                    let read =
                        |d: &PathBuf| fmaps::mesh_io::read_map(d.join(format!("{a}_{b}.map")));
                    let (t0, t1) = (read(&dirs[0])?, read(&dirs[1])?);
                    let (ma, mb) = (mesh(a)?, mesh(b)?);
                    let solver = fmaps::geodesic::DijkstraSolver::new(mb);
                    let samples =
                        fmaps::refine::farthest_point_sampling(ma.vertices(), args.samples, 0);
                    let mut sum = 0.0;
                    for &v in &samples {
                        use fmaps::geodesic::DistanceSolver;
                        let d = solver.distances_to(&[t0[v]], &[t1[v]])?;
                        sum += d[0];
                    }
                    Ok(sum / samples.len().max(1) as f64 / mb.area().sqrt())
                })
                .collect::<anyhow::Result<_>>()?;
            let first_bad: Vec<(f64, bool)> = (0..n)
                .map(|i| {
                    (
                        disagreement[i],
                        is_bad_error(by_method[0][i].error, args.bad),
                    )
                })
                .collect();
            let fmt = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.3}"));
            println!(
                "disagreement of {} and {}: AUC {} as a detector of the first's bad maps",
                args.methods[0],
                args.methods[1],
                fmt(auc(&first_bad))
            );
            if args.per_pair {
                for (i, d) in disagreement.iter().enumerate() {
                    println!(
                        "  {:<16} {:<16} errors {:7.2} {:7.2} disagreement {d:.3}",
                        by_method[0][i].source,
                        by_method[0][i].target,
                        by_method[0][i].error,
                        by_method[1][i].error
                    );
                }
            }
            let oracle = (0..n)
                .map(|i| {
                    by_method
                        .iter()
                        .map(|m| m[i].error)
                        .fold(f64::INFINITY, f64::min)
                })
                .sum::<f64>()
                / n as f64;
            let rules: [(&str, &ScoreOf); 4] = [
                ("metric distortion", &|s| s.distortion),
                ("long-range distortion", &|s| s.long_range),
                ("area distortion", &|s| s.area),
                ("metric + area distortion", &|s| s.distortion + s.area),
            ];
            let mut selection = serde_json::Map::new();
            for (name, score) in rules {
                let chosen = (0..n)
                    .map(|i| {
                        by_method
                            .iter()
                            .min_by(|x, y| score(&x[i]).total_cmp(&score(&y[i])))
                            .map_or(f64::NAN, |m| m[i].error)
                    })
                    .sum::<f64>()
                    / n as f64;
                println!("keeping per pair the lowest {name}: {chosen:.2} x100");
                selection.insert(name.to_string(), json!(chosen));
            }
            println!("best per pair (oracle): {oracle:.2} x100");
            report.push(json!({"selection": selection, "oracle": oracle}));
        }
        let path = out_dir.join(format!("confidence-{cname}.json"));
        std::fs::write(&path, serde_json::to_string_pretty(&report)?)?;
    }
    Ok(())
}
