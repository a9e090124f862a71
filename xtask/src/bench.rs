//! `cargo xtask bench`: the eigenbasis stage against SciPy, in one run.
//!
//! Meshes: FAUST `tr_reg_000` (5k vertices) and its 1-to-4 midpoint
//! subdivisions (20k, 80k), written once to `target/bench/meshes` so both
//! sides read the same files. Each eigensolve runs in its own process
//! (`fmaps spectrum --json`, SciPy through `../shared/peers/eigsh.py`), so
//! the peak memory reported is that process's own.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, bail};
use fmaps::laplacian::{LaplacianParams, cotan_laplacian};
use serde_json::{Value, json};

use crate::util::{data_dir, peer_python, peers_dir, root, run};

/// Options of `cargo xtask bench`.
#[derive(clap::Args)]
pub struct Args {
    /// Only the 5k mesh.
    #[arg(long)]
    quick: bool,
    /// Subdivision levels to run (0 = 5k, 1 = 20k, 2 = 80k).
    #[arg(long, value_delimiter = ',', default_value = "0,1,2")]
    levels: Vec<u32>,
    /// Numbers of eigenpairs.
    #[arg(long, value_delimiter = ',', default_value = "100,200")]
    ks: Vec<usize>,
    /// Thread counts (both sides: fmaps --threads, OPENBLAS/OMP for SciPy).
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    threads: Vec<usize>,
    #[command(flatten)]
    peers: crate::util::PeerArgs,
    /// Skip the ARPACK backend even when the system library is present.
    #[arg(long)]
    no_arpack: bool,
    /// Timed runs per side and configuration (after one warm-up run each);
    /// the tables report medians.
    #[arg(long, default_value_t = 5)]
    reps: usize,
    /// Block size of the native solver (default: the solver's own).
    #[arg(long)]
    block_size: Option<usize>,
}

pub fn bench(args: &Args) -> anyhow::Result<()> {
    let root = root();
    let data = data_dir(args.peers.data.as_deref());
    let base = data.join("bcicp/FAUST/vtx_5k/tr_reg_000.off");
    if !base.exists() {
        bail!(
            "{} not found: pass --data or set FMAPS_DATA to the datasets directory",
            base.display()
        );
    }
    let python = peer_python(args.peers.python.as_deref());
    if python.is_none() {
        eprintln!(
            "note: the Python peers are not set up (../shared/peers/setup.sh); SciPy columns stay empty"
        );
    }
    let arpack = !args.no_arpack
        && Command::new("pkg-config")
            .args(["--exists", "arpack"])
            .status()
            .is_ok_and(|s| s.success());
    let mut build = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    build
        .current_dir(&root)
        .args(["build", "--release", "-p", "fmaps-cli"]);
    if arpack {
        build.args(["--features", "arpack"]);
    }
    let st = build.status().context("building fmaps")?;
    if !st.success() {
        bail!("building fmaps failed");
    }
    let fmaps_bin = root.join("target/release/fmaps");

    let out_dir = root.join("target/bench");
    let mesh_dir = out_dir.join("meshes");
    std::fs::create_dir_all(&mesh_dir)?;
    let levels: Vec<u32> = if args.quick {
        vec![0]
    } else {
        args.levels.clone()
    };
    let mut meshes = Vec::new();
    let mut mesh = fmaps::mesh_io::read_mesh(&base)?;
    for level in 0..=levels.iter().copied().max().unwrap_or(0) {
        if level > 0 {
            mesh = fmaps::shapes::subdivide(&mesh);
        }
        if levels.contains(&level) {
            let p = if level == 0 {
                base.clone()
            } else {
                mesh_dir.join(format!("tr_reg_000_sub{level}.off"))
            };
            if level > 0 && !p.exists() {
                fmaps::mesh_io::write_mesh(&p, &mesh)?;
            }
            meshes.push((p, mesh.clone()));
        }
    }

    let mut records = Vec::new();
    // One thread for the assembly, as NumPy's; the eigensolver rows give
    // their own thread count (the thr column).
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    println!(
        "{} (Laplacian; eigensolve: the thr column)",
        crate::util::machine_header(one.current_num_threads())
    );
    println!(
        "\nLaplacian assembly (cotangent stiffness + lumped mass), one thread both sides, median of 7 runs"
    );
    println!(
        "{:<22} {:>7} {:>11} {:>13} {:>7}",
        "mesh", "n", "fmaps ms", "NumPy ms", "ratio"
    );
    for (path, mesh) in &meshes {
        let mut ts: Vec<f64> = (0..7)
            .map(|_| {
                let t = Instant::now();
                let op = one.install(|| cotan_laplacian(mesh, &LaplacianParams::default()));
                std::hint::black_box(&op);
                t.elapsed().as_secs_f64()
            })
            .collect();
        ts.sort_by(f64::total_cmp);
        let ours = ts[3];
        let peer = python
            .as_ref()
            .map(|py| numpy_assembly(py, path))
            .transpose()?;
        println!(
            "{:<22} {:>7} {:>11.2} {:>13} {:>7}",
            name(path),
            mesh.n_vertices(),
            ours * 1e3,
            peer.map_or("-".into(), |p| format!("{:.2}", p * 1e3)),
            peer.map_or("-".into(), |p| format!("{:.1}x", p / ours))
        );
        records.push(json!({"stage": "laplacian", "mesh": name(path), "n": mesh.n_vertices(), "fmaps_seconds": ours, "numpy_seconds": peer}));
    }

    println!(
        "\nEigensolve: k smallest eigenpairs of L φ = λ M φ, factorization + iteration, median of {} runs per side after one warm-up, sides interleaved",
        args.reps.max(1)
    );
    println!(
        "SciPy: eigsh(L, k, M, sigma=-0.01) (../shared/peers/eigsh.py); ratio = SciPy time / ours; Δλ = max relative eigenvalue difference to SciPy (λ_1..λ_k-1)"
    );
    println!(
        "{:<22} {:>6} {:>4} {:>3} | {:>8} | {:>8} {:>6} {:>8} | {:>8} {:>6} {:>8} | {:>13}",
        "mesh",
        "n",
        "k",
        "thr",
        "SciPy s",
        "native s",
        "ratio",
        "Δλ",
        "arpack s",
        "ratio",
        "Δλ",
        "peak MB S/n/a"
    );
    for (path, mesh) in &meshes {
        let n = mesh.n_vertices();
        let reps = args.reps.max(1);
        for &k in &args.ks {
            for &thr in &args.threads {
                // One warm-up run of each side (page cache, CPU frequency),
                // then the sides interleaved run by run so that a slow spell
                // of the machine hits both; each side's median.
                let mut sides: Vec<(&str, Vec<Solve>)> = Vec::new();
                if python.is_some() {
                    sides.push(("scipy", Vec::new()));
                }
                sides.push(("native", Vec::new()));
                if arpack {
                    sides.push(("arpack", Vec::new()));
                }
                for round in 0..=reps {
                    for (side, runs) in &mut sides {
                        let s = match *side {
                            "scipy" => scipy_eigsh(
                                python.as_deref().context("no peer python")?,
                                path,
                                k,
                                thr,
                            )?,
                            b => ours(&fmaps_bin, path, k, thr, b, args.block_size)?,
                        };
                        if round > 0 {
                            runs.push(s);
                        }
                    }
                }
                let mut take = |name: &str| {
                    sides
                        .iter_mut()
                        .find(|(s, _)| *s == name)
                        .map(|(_, runs)| median(std::mem::take(runs)))
                };
                let scipy = take("scipy");
                let native = take("native").context("no native runs")?;
                let arp = take("arpack");
                let ratio = |o: &Solve| {
                    scipy
                        .as_ref()
                        .map_or("-".into(), |s| format!("{:.2}x", s.seconds / o.seconds))
                };
                let diff = |o: &Solve| {
                    scipy.as_ref().map_or("-".into(), |s| {
                        format!("{:.1e}", max_rel_diff(&s.eigenvalues, &o.eigenvalues))
                    })
                };
                println!(
                    "{:<22} {:>6} {:>4} {:>3} | {:>8} | {:>8.3} {:>6} {:>8} | {:>8} {:>6} {:>8} | {:>13}",
                    name(path),
                    n,
                    k,
                    thr,
                    scipy
                        .as_ref()
                        .map_or("-".into(), |s| format!("{:.3}", s.seconds)),
                    native.seconds,
                    ratio(&native),
                    diff(&native),
                    arp.as_ref()
                        .map_or("-".into(), |a| format!("{:.3}", a.seconds)),
                    arp.as_ref().map_or("-".into(), ratio),
                    arp.as_ref().map_or("-".into(), diff),
                    format!(
                        "{}/{:.0}/{}",
                        scipy
                            .as_ref()
                            .map_or("-".into(), |s| format!("{:.0}", s.peak_mb)),
                        native.peak_mb,
                        arp.as_ref()
                            .map_or("-".into(), |a| format!("{:.0}", a.peak_mb))
                    ),
                );
                records.push(json!({
                    "stage": "eigensolve", "mesh": name(path), "n": n, "k": k, "threads": thr,
                    "scipy": scipy.as_ref().map(Solve::to_json),
                    "native": native.to_json(),
                    "arpack": arp.as_ref().map(Solve::to_json),
                    "native_max_rel_diff_to_scipy": scipy.as_ref().map(|s| max_rel_diff(&s.eigenvalues, &native.eigenvalues)),
                    "arpack_max_rel_diff_to_scipy": scipy.as_ref().zip(arp.as_ref()).map(|(s, a)| max_rel_diff(&s.eigenvalues, &a.eigenvalues)),
                }));
            }
        }
    }
    let json_path = out_dir.join("eigensolve.json");
    std::fs::write(
        &json_path,
        serde_json::to_string_pretty(
            &json!({"cpu": crate::util::cpu_model(), "kernels": fmaps::nearest::cpu_features().to_string(), "records": records}),
        )?,
    )?;
    println!("\nwrote {}", json_path.display());
    Ok(())
}

struct Solve {
    seconds: f64,
    peak_mb: f64,
    eigenvalues: Vec<f64>,
}

impl Solve {
    fn to_json(&self) -> Value {
        json!({"seconds": self.seconds, "peak_mb": self.peak_mb})
    }
}

/// The run of median time (upper median for an even count); peak memory
/// is the largest of all runs.
fn median(mut runs: Vec<Solve>) -> Solve {
    let peak = runs.iter().map(|r| r.peak_mb).fold(0.0, f64::max);
    runs.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
    let mid = runs.swap_remove(runs.len() / 2);
    Solve {
        peak_mb: peak,
        ..mid
    }
}

fn ours(
    bin: &Path,
    mesh: &Path,
    k: usize,
    threads: usize,
    backend: &str,
    block_size: Option<usize>,
) -> anyhow::Result<Solve> {
    let mut cmd = Command::new(bin);
    cmd.arg("spectrum").arg(mesh).args([
        "--k",
        &k.to_string(),
        "--threads",
        &threads.to_string(),
        "--backend",
        backend,
        "--json",
    ]);
    if let Some(b) = block_size.filter(|_| backend == "native") {
        cmd.args(["--block-size", &b.to_string()]);
    }
    // ARPACK's BLAS calls go to OpenBLAS: same thread count as the rest.
    let r = run(cmd
        .env("OPENBLAS_NUM_THREADS", threads.to_string())
        .env("OMP_NUM_THREADS", threads.to_string()))?;
    let v: Value = serde_json::from_str(&r.stdout)?;
    let s = &v["seconds"];
    Ok(Solve {
        seconds: s["factorization"].as_f64().unwrap_or(0.0)
            + s["eigensolve"].as_f64().unwrap_or(0.0),
        peak_mb: r.peak_mb,
        eigenvalues: serde_json::from_value(v["eigenvalues"].clone())?,
    })
}

fn scipy_eigsh(py: &Path, mesh: &Path, k: usize, threads: usize) -> anyhow::Result<Solve> {
    let t = threads.to_string();
    let r = run(Command::new(py)
        .arg(peers_dir().join("eigsh.py"))
        .arg(mesh)
        .args(["--k", &k.to_string()])
        .env("OPENBLAS_NUM_THREADS", &t)
        .env("OMP_NUM_THREADS", &t)
        .env("MKL_NUM_THREADS", &t))?;
    let v: Value = serde_json::from_str(&r.stdout)?;
    Ok(Solve {
        seconds: v["seconds"]
            .as_f64()
            .context("eigsh.py printed no seconds")?,
        peak_mb: r.peak_mb,
        eigenvalues: serde_json::from_value(v["eigenvalues"].clone())?,
    })
}

/// The peer's own NumPy/SciPy cotangent assembly (`eigsh.cotan`), median of 7.
fn numpy_assembly(py: &Path, mesh: &Path) -> anyhow::Result<f64> {
    let code = format!(
        "import sys, time, json\nsys.path.insert(0, {peers:?})\nimport eigsh\nv, f = eigsh.read_off({mesh:?})\nts = []\n\
         for _ in range(7):\n    t = time.perf_counter(); eigsh.cotan(v, f); ts.append(time.perf_counter() - t)\n\
         print(json.dumps(sorted(ts)[3]))\n",
        peers = peers_dir().display().to_string(),
        mesh = mesh.display().to_string()
    );
    let r = run(Command::new(py)
        .args(["-c", &code])
        .env("OPENBLAS_NUM_THREADS", "1")
        .env("OMP_NUM_THREADS", "1"))?;
    Ok(r.stdout.trim().parse()?)
}

fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .skip(1)
        .map(|(x, y)| (x - y).abs() / x.abs())
        .fold(0.0, f64::max)
}

fn name(p: &Path) -> String {
    p.file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
}
