//! `cargo xtask fit-check`: fmaps' exact minimizer against pyFM's
//! L-BFGS-B fit on the same inputs. pyFM's bases, descriptors and result
//! are dumped by `xtask/py/pyfm_fit.py`; fmaps builds its energy from them
//! (its own operators, masks and weight normalization), checks that the
//! energy at pyFM's solution equals the value pyFM reports (two
//! implementations of one energy), then minimizes it exactly and compares.

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use anyhow::bail;
use fmaps::pipeline::MatchParams;
use fmaps::solve::normalize_weights;
use fmaps::solve::{ShapeData, build_energy};
use nalgebra::{DMatrix, DVector};
use serde_json::json;

use crate::util::{data_dir, peer_python, read_npy_f64_2d, root, run};

/// Options of `cargo xtask fit-check`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    peers: crate::util::PeerArgs,
    /// Collection of the pairs.
    #[arg(long, default_value = "FAUST")]
    collection: String,
    /// How many test pairs (from the first).
    #[arg(long, default_value_t = 3)]
    pairs: usize,
    /// Size of the functional map.
    #[arg(long, default_value_t = 50)]
    k: usize,
    /// Relative weight of the orientation term.
    #[arg(long, default_value_t = 1.0)]
    w_orient: f64,
}

/// Eigenvectors, eigenvalues, mass and descriptors of one dumped shape.
type Dumped = (DMatrix<f64>, DVector<f64>, DVector<f64>, DMatrix<f64>);

fn matrix(path: &std::path::Path) -> anyhow::Result<DMatrix<f64>> {
    let rows = read_npy_f64_2d(path)?;
    let (r, c) = (rows.len(), rows.first().map_or(0, Vec::len));
    Ok(DMatrix::from_fn(r, c, |i, j| rows[i][j]))
}

fn vector(path: &std::path::Path) -> anyhow::Result<DVector<f64>> {
    let bytes = std::fs::read(path)?;
    let (_, data) = crate::util::parse_npy_f64(&bytes, &path.display().to_string())?;
    Ok(DVector::from_vec(data))
}

pub fn fit_check(args: &Args) -> anyhow::Result<()> {
    let Some(py) = peer_python(args.peers.python.as_deref()) else {
        bail!("the Python peers are not set up: run ../shared/peers/setup.sh");
    };
    let bcicp = data_dir(args.peers.data.as_deref()).join("bcicp");
    let c = fmaps::eval::Collection::open(&bcicp, &args.collection)?;
    let mut pairs = c.test_pairs()?;
    pairs.truncate(args.pairs);
    let tmp = std::env::temp_dir().join(format!("fmaps-fit-{}", std::process::id()));
    println!(
        "{:<24} {:>14} {:>14} {:>10} {:>14} {:>10} {:>9} {:>9}",
        "pair",
        "E(pyFM C)",
        "pyFM reports",
        "rel diff",
        "E(fmaps C)",
        "E ratio",
        "pyFM s",
        "fmaps s"
    );
    let mut rows = Vec::new();
    for (a, b) in &pairs {
        let out = tmp.join(format!("{a}_{b}"));
        let r = run(Command::new(&py)
            .arg(root().join("xtask/py/pyfm_fit.py"))
            .arg(c.mesh_path(a))
            .arg(c.mesh_path(b))
            .arg("--out")
            .arg(&out)
            .args(["--k", &args.k.to_string()])
            .args(["--w-orient", &args.w_orient.to_string()])
            .env("OMP_NUM_THREADS", "1")
            .env("OPENBLAS_NUM_THREADS", "1"))?;
        let info: serde_json::Value = serde_json::from_str(r.stdout.trim())?;
        // mesh1 = B (source of C), mesh2 = A.
        let (mb, ma) = (c.read_mesh(b)?, c.read_mesh(a)?);
        let load = |i: u8| -> anyhow::Result<Dumped> {
            Ok((
                matrix(&out.join(format!("evecs{i}.npy")))?,
                vector(&out.join(format!("evals{i}.npy")))?,
                vector(&out.join(format!("mass{i}.npy")))?,
                matrix(&out.join(format!("descr{i}.npy")))?,
            ))
        };
        let (phi1, ev1, m1, d1) = load(1)?;
        let (phi2, ev2, m2, d2) = load(2)?;
        let c_pyfm = matrix(&out.join("fm.npy"))?;
        let mut params = MatchParams::unrefined();
        params.k = args.k;
        params.energy.weights.orient = args.w_orient;
        let src = ShapeData {
            faces: mb.faces(),
            phi: &phi1,
            evals: &ev1,
            mass: &m1,
            area: m1.sum(),
        };
        let tgt = ShapeData {
            faces: ma.faces(),
            phi: &phi2,
            evals: &ev2,
            mass: &m2,
            area: m2.sum(),
        };
        let t = Instant::now();
        let mut energy = build_energy(&src, &tgt, &d1, &d2, &params.energy)?;
        normalize_weights(&mut energy, params.energy.weights);
        let c_ours = energy.minimize()?;
        let secs = t.elapsed().as_secs_f64();
        // pyFM's energy is ½ Σ w_i term_i; ours Σ w_i term_i.
        let e_py = energy.value(&c_pyfm);
        let reported = 2.0 * info["energy"].as_f64().unwrap_or(f64::NAN);
        let e_ours = energy.value(&c_ours);
        let row = json!({
            "pair": [a, b], "energy_at_pyfm_c": e_py, "pyfm_reported": reported,
            "energy_rel_diff": (e_py - reported).abs() / reported,
            "energy_at_fmaps_c": e_ours, "ratio": e_ours / e_py,
            "pyfm_fit_seconds": info["fit_seconds"], "fmaps_seconds": secs,
            "pyfm_nit": info["nit"], "c_max_abs_diff": (&c_ours - &c_pyfm).amax(),
        });
        println!(
            "{:<24} {:>14.8e} {:>14.8e} {:>10.2e} {:>14.8e} {:>10.6} {:>9.3} {:>9.3}",
            format!("{a}-{b}"),
            e_py,
            reported,
            row["energy_rel_diff"].as_f64().unwrap_or(f64::NAN),
            e_ours,
            e_ours / e_py,
            info["fit_seconds"].as_f64().unwrap_or(f64::NAN),
            secs
        );
        rows.push(row);
    }
    let _ = std::fs::remove_dir_all(&tmp);
    let path: PathBuf = root().join("target/eval/fit-check.json");
    std::fs::create_dir_all(path.parent().unwrap_or(&root()))?;
    std::fs::write(&path, serde_json::to_string_pretty(&rows)?)?;
    println!(
        "(energies in fmaps' scaling, Σ w_i term_i = 2x pyFM's; E ratio < 1: the exact minimum is lower;\n \
         pyFM s: its fit() with the operators, one thread; fmaps s: operators + exact solve, same inputs)\n{}",
        path.display()
    );
    Ok(())
}
