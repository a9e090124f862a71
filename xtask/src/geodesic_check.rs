//! `cargo xtask geodesic-check`: fmaps' exact geodesics against tvb-gdist
//! (Kirsanov's exact MMP, through `../shared/peers/geodesics.py`) on FAUST
//! and TOSCA meshes: largest relative difference and time per source.

use std::process::Command;
use std::time::Instant;

use anyhow::{Context, bail};
use fmaps::geodesic::{DistanceSolver, ExactSolver, HeatParams, HeatSolver};
use serde_json::Value;

use crate::util::{data_dir, peer_python, peers_dir, read_npy_f64_2d, run};

/// Options of `cargo xtask geodesic-check`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    peers: crate::util::PeerArgs,
    /// Number of source vertices per mesh (spread over the index range).
    #[arg(long, default_value_t = 5)]
    sources: usize,
}

pub fn geodesic_check(args: &Args) -> anyhow::Result<()> {
    let data = data_dir(args.peers.data.as_deref()).join("bcicp");
    let Some(py) = peer_python(args.peers.python.as_deref()) else {
        bail!("the Python peers are not set up: run ../shared/peers/setup.sh");
    };
    let meshes = [
        data.join("FAUST/vtx_5k/tr_reg_000.off"),
        data.join("FAUST/vtx_5k/tr_reg_057.off"),
        data.join("TOSCA_Isometric/vtx_5k/cat0.off"),
        data.join("TOSCA_Isometric/vtx_5k/michael0.off"),
    ];
    let tmp = std::env::temp_dir().join(format!("fmaps-geodesic-check-{}.npy", std::process::id()));
    let par = rayon::current_num_threads();
    println!("{}", crate::util::machine_header(par));
    println!(
        "{:<16} {:>6} {:>5} {:>12} | {:>11} {:>11} {:>7} {:>11} {:>7} | {:>11} {:>11} {:>7} {:>9}",
        "mesh",
        "n",
        "src",
        "max rel diff",
        "exact s/src",
        "gdist s/src",
        "ratio",
        format!("exact || {par}"),
        "ratio",
        "heat s/src",
        "pp3d s/src",
        "ratio",
        "heat dev"
    );
    let fmaps_bin = crate::util::fmaps_binary()?;
    let mut worst = 0.0f64;
    let mut memory = Vec::new();
    for mesh_path in meshes.iter().filter(|p| p.exists()) {
        let mesh = fmaps::mesh_io::read_mesh(mesh_path)?;
        let n = mesh.n_vertices();
        let sources: Vec<usize> = (0..args.sources)
            .map(|i| i * (n - 1) / args.sources.max(1))
            .collect();
        let src_args: Vec<String> = sources.iter().map(|s| s.to_string()).collect();
        let r = run(Command::new(&py)
            .arg(peers_dir().join("geodesics.py"))
            .arg(mesh_path)
            .arg("--sources")
            .args(&src_args)
            .args(["--method", "exact", "--out"])
            .arg(&tmp))?;
        let peer: Value = serde_json::from_str(&r.stdout)?;
        let peer_mb = r.peak_mb;
        let reference = read_npy_f64_2d(&tmp)?;
        // Peak memory of a whole process computing one exact field, ours
        // (the CLI) and the peer's (Python with tvb-gdist) above.
        let ours_mb = run(Command::new(&fmaps_bin)
            .arg("geodesic")
            .arg(mesh_path)
            .args(["--source", &src_args[0], "--json", "--threads", "1"]))?
        .peak_mb;
        memory.push((
            mesh_path
                .file_stem()
                .unwrap()
                .to_string_lossy()
                .into_owned(),
            ours_mb,
            peer_mb,
        ));
        let t = Instant::now();
        let solver = ExactSolver::new(&mesh)?;
        let ours: Vec<Vec<f64>> = sources
            .iter()
            .map(|&s| solver.distances(&[s]))
            .collect::<Result<_, _>>()?;
        let ours_s = t.elapsed().as_secs_f64() / sources.len() as f64;
        let mut diff = 0.0f64;
        for (o, g) in ours.iter().zip(&reference) {
            for (a, b) in o.iter().zip(g) {
                if *b > 0.0 {
                    diff = diff.max((a - b).abs() / b);
                }
            }
        }
        worst = worst.max(diff);
        let gdist_s = peer["seconds_per_source"]
            .as_f64()
            .context("geodesics.py printed no timing")?;
        // Exact fields from the same sources on all the pool's threads.
        let t = Instant::now();
        let _ = solver.fields(&sources)?;
        let par_s = t.elapsed().as_secs_f64() / sources.len() as f64;
        // Heat method: setup once, then per source; deviation from exact
        // (mean relative, vertices beyond 20% of the largest distance).
        // Timed with its setup (factorizations), as the peer's is.
        let t = Instant::now();
        let heat = HeatSolver::new(&mesh, &HeatParams::default())?;
        let hd: Vec<Vec<f64>> = sources
            .iter()
            .map(|&s| heat.distances(&[s]))
            .collect::<Result<_, _>>()?;
        let heat_s = t.elapsed().as_secs_f64() / sources.len() as f64;
        let mut dev = (0.0, 0usize);
        for (o, h) in ours.iter().zip(&hd) {
            let dmax = o.iter().copied().fold(0.0, f64::max);
            for (a, b) in o.iter().zip(h) {
                if *a > 0.2 * dmax {
                    dev.0 += (b - a).abs() / a;
                    dev.1 += 1;
                }
            }
        }
        let r = run(Command::new(&py)
            .arg(peers_dir().join("geodesics.py"))
            .arg(mesh_path)
            .arg("--sources")
            .args(&src_args)
            .args(["--method", "heat"]))?;
        let pp: Value = serde_json::from_str(&r.stdout)?;
        let pp_s = pp["seconds_per_source"]
            .as_f64()
            .context("geodesics.py printed no timing")?;
        println!(
            "{:<16} {:>6} {:>5} {:>12.2e} | {:>11.4} {:>11.4} {:>6.2}x {:>11.4} {:>6.2}x | {:>11.5} {:>11.5} {:>6.2}x {:>8.2}%",
            mesh_path.file_stem().unwrap().to_string_lossy(),
            n,
            sources.len(),
            diff,
            ours_s,
            gdist_s,
            gdist_s / ours_s,
            par_s,
            gdist_s / par_s,
            heat_s,
            pp_s,
            pp_s / heat_s,
            100.0 * dev.0 / dev.1.max(1) as f64
        );
    }
    let _ = std::fs::remove_file(&tmp);
    println!(
        "peak memory of a whole process computing exact fields (fmaps geodesic CLI, one source; geodesics.py with tvb-gdist, all sources):"
    );
    for (name, ours, peer) in &memory {
        println!("  {name:<16} fmaps {ours:>7.1} MiB   tvb-gdist process {peer:>7.1} MiB");
    }
    println!(
        "largest relative difference: {worst:.2e} (required: 1e-6); exact: fmaps per source without its 4 ms mesh setup (one thread; \"|| {par}\": fields of all sources on {par} threads), tvb-gdist per call (it has no reusable solver, one thread); heat: both include their setup; heat dev = mean relative deviation from exact beyond 20% of the largest distance"
    );
    if worst > 1e-6 {
        bail!("exact geodesics disagree with tvb-gdist beyond 1e-6");
    }
    Ok(())
}
