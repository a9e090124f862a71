//! `cargo xtask starts`: how to choose among the starts of a multi-start
//! run without ground truth. For each pair, the pipeline with ZoomOut
//! (50 -> 150 step 5) is run from initial maps of each size; every final
//! map is evaluated (geodesic error against the ground truth) and scored
//! without ground truth (orientation, coverage, collapsed faces, area and
//! conformal distortion). The table shows the mean error of each selection
//! rule next to the best start per pair (the oracle), and the measurement
//! behind `fmaps::pipeline::default_starts` and `StartSelection`.

use std::path::PathBuf;

use anyhow::Context;
use fmaps::eval::{EvalParams, evaluate, map_quality};
use fmaps::geodesic::{DijkstraSolver, DistanceSolver, ExactSolver};
use fmaps::pipeline::{MatchParams, Refinement, match_prepared, prepare};

use crate::util::bcicp_dir;

/// Options of `cargo xtask starts`.
#[derive(clap::Args)]
pub struct Args {
    /// Collection (any of `cargo xtask eval`'s).
    #[arg(long, default_value = "TOSCA_Isometric")]
    collection: String,
    /// The first N pairs (after --stride).
    #[arg(long, default_value_t = 10)]
    pairs: usize,
    /// Take every STRIDE-th pair.
    #[arg(long, default_value_t = 1)]
    stride: usize,
    /// Initial map sizes to run (the first is the pipeline's k).
    #[arg(long, default_value = "50,8,12,20,30", value_delimiter = ',')]
    sizes: Vec<usize>,
    /// Geodesic method: exact or dijkstra.
    #[arg(long, default_value = "exact")]
    geodesic: String,
    /// Dataset directory (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    data: Option<PathBuf>,
}

struct Run {
    k: usize,
    error: f64,
    orientation: f64,
    coverage: f64,
    collapsed: f64,
    area: f64,
    conformal: f64,
}

pub fn starts(args: &Args) -> anyhow::Result<()> {
    let bcicp = bcicp_dir(args.data.as_deref())?;
    let (c, pairs) = crate::eval::collection_pairs(&bcicp, &args.collection)?;
    let mut params = MatchParams::unrefined();
    params.refinement = Refinement::default_zoomout();
    let mut all: Vec<Vec<Run>> = Vec::new();
    for (a, b) in pairs.iter().step_by(args.stride.max(1)).take(args.pairs) {
        let (ma, mb) = (c.read_mesh(a)?, c.read_mesh(b)?);
        let (pa, pb) = (prepare(&ma, &params)?, prepare(&mb, &params)?);
        let gt = c.ground_truth(a, b, ma.n_vertices(), mb.n_vertices())?;
        let solver: Box<dyn DistanceSolver> = match args.geodesic.as_str() {
            "exact" => Box::new(ExactSolver::new(&mb)?),
            _ => Box::new(DijkstraSolver::new(&mb)),
        };
        let mut runs = Vec::new();
        for &k in &args.sizes {
            let mut p = params.clone();
            p.k = k;
            if let Refinement::ZoomOut { zoomout, .. } = &mut p.refinement {
                zoomout.k_start = zoomout.k_start.min(k);
            }
            let r = match_prepared(&pa, &pb, &p).with_context(|| format!("{a} -> {b}, k = {k}"))?;
            let e = evaluate(
                &mb,
                solver.as_ref(),
                &r.t_ab,
                &gt,
                None,
                &EvalParams::default(),
            )?;
            let q = map_quality(&r.t_ab, &ma, &mb, None)?;
            println!(
                "{a} -> {b} k = {k:3}: error {:6.2}  orientation {:+.3}  coverage {:.3}  collapsed {:.3}  area {:.3}  conformal {:.3}",
                100.0 * e.mean_error,
                r.orientation,
                q.coverage,
                q.collapsed_faces,
                q.area_distortion,
                q.conformal_distortion
            );
            runs.push(Run {
                k,
                error: e.mean_error,
                orientation: r.orientation,
                coverage: q.coverage,
                collapsed: q.collapsed_faces,
                area: q.area_distortion,
                conformal: q.conformal_distortion,
            });
        }
        all.push(runs);
    }
    type Rule = (&'static str, fn(&Run) -> f64);
    let rules: [Rule; 6] = [
        ("highest orientation", |r| -r.orientation),
        ("lowest area distortion", |r| r.area),
        ("lowest conformal distortion", |r| r.conformal),
        ("fewest collapsed faces", |r| r.collapsed),
        ("highest coverage", |r| -r.coverage),
        ("oracle (ground truth)", |r| r.error),
    ];
    let n = all.len().max(1) as f64;
    println!(
        "\n{}, first {} pairs, {} geodesics, mean error x100 of the start each rule keeps",
        args.collection,
        all.len(),
        args.geodesic
    );
    println!(
        "  only k = {:<3}                    {:7.3}",
        args.sizes[0],
        100.0 * all.iter().map(|r| r[0].error).sum::<f64>() / n
    );
    for (name, score) in rules {
        let mean = all
            .iter()
            .map(|runs| {
                runs.iter()
                    .min_by(|x, y| score(x).total_cmp(&score(y)))
                    .map_or(f64::NAN, |r| r.error)
            })
            .sum::<f64>()
            / n;
        println!("  {name:<32} {:7.3}", 100.0 * mean);
    }
    let mut picked: Vec<(usize, usize)> = args.sizes.iter().map(|&k| (k, 0)).collect();
    for runs in &all {
        if let Some(best) = runs.iter().min_by(|x, y| x.area.total_cmp(&y.area))
            && let Some(p) = picked.iter_mut().find(|p| p.0 == best.k)
        {
            p.1 += 1;
        }
    }
    println!("  sizes kept by the area rule (k: pairs): {picked:?}");
    Ok(())
}
