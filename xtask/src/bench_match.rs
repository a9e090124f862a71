//! `cargo xtask bench-match`: per-stage time of the matching pipeline
//! (no refinement) against pyFM's same pipeline on the same pair, in the
//! same run (`../shared/peers/pyfm_pipeline.py --bench-pair`), and the
//! whole pipeline with ZoomOut 50:150:5 (one start) on both sides.

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use anyhow::bail;
use fmaps::MatchParams;
use fmaps::eval::Collection;
use fmaps::pipeline::{Refinement, match_prepared, prepare};
use fmaps::refine::ZoomOut;
use serde_json::json;

use crate::util::{data_dir, median, peer_python, peers_dir, root, run};

/// Options of `cargo xtask bench-match`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    bench: crate::util::PairBench,
}

pub fn bench_match(args: &Args) -> anyhow::Result<()> {
    let Some(py) = peer_python(args.bench.peers.python.as_deref()) else {
        bail!("the Python peers are not set up: run ../shared/peers/setup.sh");
    };
    let dataset = data_dir(args.bench.peers.data.as_deref())
        .join("bcicp")
        .join(&args.bench.collection);
    let c = Collection::open(dataset.parent().unwrap_or(&dataset), &args.bench.collection)?;
    let pairs = c.test_pairs()?;
    let Some((a, b)) = pairs.get(args.bench.pair).cloned() else {
        bail!("{} has {} test pairs", args.bench.collection, pairs.len());
    };
    // fmaps, in a pool of the requested size.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.bench.threads)
        .build()?;
    let mut stages: Vec<[f64; 6]> = Vec::new();
    for _ in 0..args.bench.repeat {
        let row = pool.install(|| -> anyhow::Result<[f64; 6]> {
            let t = Instant::now();
            let (ma, mb) = (c.read_mesh(&a)?, c.read_mesh(&b)?);
            let load = t.elapsed().as_secs_f64();
            let p = MatchParams::unrefined();
            let t = Instant::now();
            // Side by side, as `fmaps match` does.
            let (pa, pb) = rayon::join(|| prepare(&ma, &p), || prepare(&mb, &p));
            let (pa, pb) = (pa?, pb?);
            let spectra = t.elapsed().as_secs_f64();
            let r = match_prepared(&pa, &pb, &p)?;
            let s = r.times;
            Ok([
                load,
                spectra,
                s.descriptors,
                s.operators + s.solve,
                s.point_map,
                0.0,
            ])
        })?;
        let mut row = row;
        row[5] = row[..5].iter().sum();
        stages.push(row);
    }
    let ours: Vec<f64> = (0..6)
        .map(|i| median(stages.iter().map(|r| r[i]).collect()))
        .collect();
    // The whole pipeline with ZoomOut 50:150:5 from the fitted map, one
    // start (`fmaps match --refine zoomout --starts none` in-process:
    // load, eigenbases, descriptors, fit, point map, ZoomOut).
    // Twice: with pyFM's 200 eigenpairs (like for like), and with the
    // eigenpairs the pipeline reads (`k_process_needed`: 150 here), as
    // `fmaps match` computes them; the two interleaved.
    let (mut whole, mut whole_needed) = (Vec::new(), Vec::new());
    for _ in 0..args.bench.repeat {
        for needed in [false, true] {
            let secs = pool.install(|| -> anyhow::Result<f64> {
                let t = Instant::now();
                let (ma, mb) = (c.read_mesh(&a)?, c.read_mesh(&b)?);
                let mut p = MatchParams::unrefined();
                p.refinement = Refinement::ZoomOut {
                    zoomout: ZoomOut::default(),
                    samples: None,
                };
                if needed {
                    p.k_process = p.k_process_needed();
                    p.descriptors.eigenpairs = p.descriptors.eigenpairs.min(p.k_process);
                }
                let (pa, pb) = rayon::join(|| prepare(&ma, &p), || prepare(&mb, &p));
                let r = match_prepared(&pa?, &pb?, &p)?;
                std::hint::black_box(&r.t_ab);
                Ok(t.elapsed().as_secs_f64())
            })?;
            if needed {
                whole_needed.push(secs);
            } else {
                whole.push(secs);
            }
        }
    }
    let k_needed = {
        let mut p = MatchParams::unrefined();
        p.refinement = Refinement::ZoomOut {
            zoomout: ZoomOut::default(),
            samples: None,
        };
        p.k_process_needed()
    };
    let (whole, whole_needed) = (median(whole), median(whole_needed));

    let out = std::env::temp_dir().join(format!("fmaps-bench-match-{}", std::process::id()));
    run(Command::new(&py)
        .arg(peers_dir().join("pyfm_pipeline.py"))
        .arg(&dataset)
        .args(["--bench-pair", &args.bench.pair.to_string()])
        .args(["--repeat", &args.bench.repeat.to_string()])
        .args(["--threads", &args.bench.threads.to_string()])
        .args(["--orient-weight", "1.0", "--out"])
        .arg(&out))?;
    let file = std::fs::read_dir(&out)?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "json"))
        .ok_or_else(|| anyhow::anyhow!("pyfm_pipeline.py wrote no JSON"))?;
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&file)?)?;
    let m = &v["median"];
    let g = |k: &str| m[k].as_f64().unwrap_or(0.0);
    let peer = [
        g("load"),
        g("laplacian") + g("eig"),
        g("setup") + g("descr"),
        g("fit_orient"),
        g("p2p_orient"),
        0.0,
    ];
    let mut peer = peer;
    peer[5] = peer[..5].iter().sum();
    // pyFM's same pipeline with ZoomOut 50:150:5 from the oriented fit
    // (its stages' medians summed).
    let peer_whole = peer[5] + g("zoomout_orient");
    let _ = std::fs::remove_dir_all(&out);

    println!("{}", crate::util::machine_header(args.bench.threads));
    println!(
        "{} {a} -> {b}, {} thread(s) each side, median of {} (both sides warmed up, imports excluded)",
        args.bench.collection, args.bench.threads, args.bench.repeat
    );
    println!(
        "{:<34} {:>9} {:>9} {:>8}",
        "stage", "fmaps s", "pyFM s", "ratio"
    );
    let names = [
        "load both meshes",
        "Laplacians + eigenbases (k=200)",
        "descriptors (WKS)",
        "fit with orientation term",
        "point map",
        "total (fmaps match, no refinement)",
    ];
    for i in 0..6 {
        println!(
            "{:<34} {:>9.3} {:>9.3} {:>7.1}x",
            names[i],
            ours[i],
            peer[i],
            peer[i] / ours[i]
        );
    }
    println!(
        "{:<34} {:>9.3} {:>9.3} {:>7.1}x",
        "whole, + ZoomOut 50:150:5 (1 start)",
        whole,
        peer_whole,
        peer_whole / whole
    );
    println!(
        "{:<34} {:>9.3} {:>9.3} {:>7.1}x",
        format!("  the same, fmaps with k = {k_needed}"),
        whole_needed,
        peer_whole,
        peer_whole / whole_needed
    );
    println!(
        "(whole: both sides' eigenbases k = 200, pyFM's preprocess default; k = {k_needed}: the eigenpairs \
         the pipeline reads, as `fmaps match --refine zoomout --starts none` computes them)"
    );
    let fit_p2p = (peer[3] + peer[4]) / (ours[3] + ours[4]);
    println!("fit + point map: {fit_p2p:.1}x faster than pyFM");
    let path: PathBuf = root().join(format!(
        "target/bench/match-{}-pair{}-threads{}.json",
        args.bench.collection, args.bench.pair, args.bench.threads
    ));
    std::fs::create_dir_all(path.parent().unwrap_or(&root()))?;
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&json!({
            "pair": [a, b], "threads": args.bench.threads, "repeat": args.bench.repeat,
            "stages": names, "fmaps": ours, "pyfm": peer, "fit_p2p_ratio": fit_p2p,
            "whole_zoomout": {"fmaps": whole, "fmaps_k_needed": whole_needed, "k_needed": k_needed, "pyfm": peer_whole},
        }))?,
    )?;
    println!("{}", path.display());
    Ok(())
}
