//! `cargo xtask figures`: the seed paper's experiments, written to `docs/`.
//!
//! (a) Figure 8: how well a functional map of size k *represents* the
//! ground-truth map. The true point map T_AB is encoded as
//! `C_BA = Φ_Aᵀ M_A Π_AB Φ_B` with k basis functions on each side, decoded
//! back by nearest neighbours in the spectral embedding, and the decoded
//! map's mean geodesic error (exact geodesics, the eval protocol) is
//! averaged over the first pairs of each collection, for k = 5 ... 200.
//! (b) Figure 1: the matrix C of a FAUST pair as a heat map, with the
//! fraction of entries below 0.1, for the ground-truth map (k = 100) and
//! for the fmaps-init pipeline (k = 50).

use std::path::PathBuf;

use anyhow::Context;
use fmaps::eval::{Collection, EvalParams, GroundTruth, evaluate};
use fmaps::geodesic::ExactSolver;
use fmaps::mesh_io::{TriMesh, read_vts};
use fmaps::solve::{fmap_from_point_map, fmap_metrics, point_map_from_fmap};
use fmaps::{SpectrumParams, spectrum};
use serde_json::json;

use crate::util::{data_dir, root};

/// Options of `cargo xtask figures`.
#[derive(clap::Args)]
pub struct Args {
    /// Dataset directory (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Pairs per collection for the Figure 8 curve.
    #[arg(long, default_value_t = 5)]
    pairs: usize,
    /// Output directory (default: docs/).
    #[arg(long)]
    out: Option<PathBuf>,
}

const KS: [usize; 15] = [
    5, 10, 15, 20, 25, 30, 40, 50, 60, 80, 100, 120, 150, 175, 200,
];

/// The ground-truth map A -> B on every vertex of A: the truth where the
/// `.vts` files give it, else the truth of the nearest covered A vertex.
fn full_truth(
    c: &Collection,
    a: &str,
    b: &str,
    ma: &TriMesh,
) -> anyhow::Result<(Vec<usize>, GroundTruth)> {
    let ga = read_vts(c.vts_path(a, false))?;
    let gb = read_vts(c.vts_path(b, false))?;
    let mut t = vec![usize::MAX; ma.n_vertices()];
    for (&x, &y) in ga.iter().zip(&gb) {
        if x < t.len() {
            t[x] = y;
        }
    }
    let covered: Vec<usize> = (0..t.len()).filter(|&x| t[x] != usize::MAX).collect();
    let v = ma.vertices();
    for x in 0..t.len() {
        if t[x] == usize::MAX {
            let near = covered
                .iter()
                .copied()
                .min_by(|&p, &q| {
                    let d = |u: usize| (0..3).map(|i| (v[u][i] - v[x][i]).powi(2)).sum::<f64>();
                    d(p).total_cmp(&d(q))
                })
                .context("no ground-truth vertex")?;
            t[x] = t[near];
        }
    }
    let sym = c.vts_path(b, true);
    let sym = sym.exists().then(|| read_vts(&sym)).transpose()?;
    Ok((t, GroundTruth::new(ga, gb, sym)?))
}

pub fn figures(args: &Args) -> anyhow::Result<()> {
    let bcicp = data_dir(args.data.as_deref()).join("bcicp");
    let out = args.out.clone().unwrap_or_else(|| root().join("docs"));
    std::fs::create_dir_all(&out)?;
    let params = EvalParams::default();
    let mut series = Vec::new();
    let mut record = serde_json::Map::new();
    for cname in ["FAUST", "TOSCA_Isometric"] {
        let c = Collection::open(&bcicp, cname)?;
        let mut pairs = c.test_pairs()?;
        pairs.truncate(args.pairs);
        let mut sums = vec![0.0; KS.len()];
        for (a, b) in &pairs {
            let (ma, mb) = (c.read_mesh(a)?, c.read_mesh(b)?);
            let (t_ab, gt) = full_truth(&c, a, b, &ma)?;
            let ba = spectrum(&ma, 200, &SpectrumParams::default())?.basis;
            let bb = spectrum(&mb, 200, &SpectrumParams::default())?.basis;
            let solver = ExactSolver::new(&mb)?;
            for (s, &k) in sums.iter_mut().zip(&KS) {
                let (ka, kb) = (ba.truncate(k), bb.truncate(k));
                let c_ba = fmap_from_point_map(&t_ab, &kb, &ka)?;
                let decoded = point_map_from_fmap(&c_ba, &kb, &ka)?;
                let r = evaluate(&mb, &solver, &decoded, &gt, None, &params)?;
                *s += r.mean_error;
            }
            eprintln!("{cname} {a}-{b} done");
        }
        let means: Vec<f64> = sums
            .iter()
            .map(|s| 100.0 * s / pairs.len() as f64)
            .collect();
        println!("{cname}: mean geodesic error x100 of the decoded ground-truth map");
        for (k, m) in KS.iter().zip(&means) {
            println!("  k = {k:>3}: {m:.3}");
        }
        record.insert(
            cname.into(),
            json!({"pairs": pairs, "k": KS, "mean_error_x100": means}),
        );
        series.push(fmaps_viz::plot::Series {
            label: format!("{cname} (first {} test pairs)", pairs.len()),
            x: KS.iter().map(|&k| k as f64).collect(),
            y: means,
        });
    }
    let ymax = series
        .iter()
        .flat_map(|s| s.y.iter().copied())
        .fold(0.0f64, f64::max);
    let ytop = (ymax / 5.0).ceil() * 5.0;
    let fig8 = out.join("fig8-representation.png");
    fmaps_viz::plot::line_plot(
        &fmaps_viz::plot::Plot {
            title: "Seed Fig. 8: true map as k x k C",
            x_label: "basis size k",
            y_label: "mean geodesic error x100",
            x_range: (0.0, 200.0),
            y_range: (0.0, ytop),
            x_ticks: vec![0.0, 25.0, 50.0, 75.0, 100.0, 125.0, 150.0, 175.0, 200.0],
            y_ticks: (0..=5).map(|i| ytop * f64::from(i) / 5.0).collect(),
        },
        &series,
    )
    .save_png(&fig8)?;
    println!("{}", fig8.display());

    // Figure 1: C of the first FAUST pair.
    let c = Collection::open(&bcicp, "FAUST")?;
    let (a, b) = c
        .test_pairs()?
        .into_iter()
        .next()
        .context("no FAUST pairs")?;
    let (ma, mb) = (c.read_mesh(&a)?, c.read_mesh(&b)?);
    let (t_ab, _) = full_truth(&c, &a, &b, &ma)?;
    let p = fmaps::MatchParams::unrefined();
    let pa = fmaps::pipeline::prepare(&ma, &p)?;
    let pb = fmaps::pipeline::prepare(&mb, &p)?;
    let k = 100;
    let (ka, kb) = (pa.basis.truncate(k), pb.basis.truncate(k));
    let c_gt = fmap_from_point_map(&t_ab, &kb, &ka)?;
    let m_gt = fmap_metrics(&c_gt, &kb.eigenvalues, &ka.eigenvalues)?;
    let init = fmaps::pipeline::match_prepared(&pa, &pb, &p)?;
    let mut by_k = Vec::new();
    for kk in [20, 50, 100, 200] {
        let (xa, xb) = (pa.basis.truncate(kk), pb.basis.truncate(kk));
        let cg = fmap_from_point_map(&t_ab, &xb, &xa)?;
        let mm = fmap_metrics(&cg, &xb.eigenvalues, &xa.eigenvalues)?;
        println!(
            "C of the true map {a} -> {b}, k = {kk}: {:.1}% of entries below 0.1",
            100.0 * mm.sparsity
        );
        by_k.push(json!({"k": kk, "sparsity": mm.sparsity, "orthonormality": mm.orthonormality}));
    }
    let gt_png = out.join("fmap-ground-truth.png");
    fmaps_viz::plot::heatmap(
        &format!("true map, k={k}: {:.1}% < 0.1", 100.0 * m_gt.sparsity),
        &c_gt,
        1.0,
    )
    .save_png(&gt_png)?;
    let init_png = out.join("fmap-fmaps-init.png");
    fmaps_viz::plot::heatmap(
        &format!(
            "fmaps-init, k=50: {:.1}% < 0.1",
            100.0 * init.metrics.sparsity
        ),
        &init.c_ba,
        1.0,
    )
    .save_png(&init_png)?;
    println!(
        "C of the true map (k = {k}): {:.1}% of entries below 0.1, ||CtC - I|| = {:.3}\n\
         C of fmaps-init (k = 50): {:.1}% below 0.1, ||CtC - I|| = {:.3}\n{}\n{}",
        100.0 * m_gt.sparsity,
        m_gt.orthonormality,
        100.0 * init.metrics.sparsity,
        init.metrics.orthonormality,
        gt_png.display(),
        init_png.display()
    );
    record.insert(
        "heatmap".into(),
        json!({"pair": [a, b], "k_ground_truth": k, "sparsity_ground_truth": m_gt.sparsity,
               "orthonormality_ground_truth": m_gt.orthonormality,
               "sparsity_fmaps_init": init.metrics.sparsity, "ground_truth_by_k": by_k}),
    );
    std::fs::write(
        out.join("figures.json"),
        serde_json::to_string_pretty(&record)?,
    )?;
    Ok(())
}
