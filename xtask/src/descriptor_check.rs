//! `cargo xtask descriptor-check`: fmaps' HKS/WKS against pyFM's on a FAUST
//! mesh, from pyFM's own basis (same numbers in, so any difference is the
//! descriptor code) and from fmaps' basis (the whole pipeline).

use std::io::Read;
use std::process::Command;

use anyhow::{Context, bail};
use fmaps::{SpectrumParams, spectrum};
use fmaps_descriptors::{HksParams, WksParams, hks, wks};
use nalgebra::{DMatrix, DVector};

use crate::util::{data_dir, parse_npy_f64, peer_python, peers_dir, read_npy_f64_2d, run};

/// Options of `cargo xtask descriptor-check`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    peers: crate::util::PeerArgs,
    /// Eigenpairs.
    #[arg(long, default_value_t = 100)]
    k: usize,
    /// Descriptors per kind.
    #[arg(long, default_value_t = 100)]
    n_descr: usize,
}

pub fn descriptor_check(args: &Args) -> anyhow::Result<()> {
    let mesh_path = data_dir(args.peers.data.as_deref()).join("bcicp/FAUST/vtx_5k/tr_reg_000.off");
    let Some(py) = peer_python(args.peers.python.as_deref()) else {
        bail!("the Python peers are not set up: run ../shared/peers/setup.sh");
    };
    let tmp = std::env::temp_dir().join(format!("fmaps-descr-{}", std::process::id()));
    std::fs::create_dir_all(&tmp)?;
    let mesh = fmaps::mesh_io::read_mesh(&mesh_path)?;
    let ours_basis = spectrum(&mesh, args.k, &SpectrumParams::default())?.basis;
    println!(
        "{:<5} {:>24} {:>24}",
        "kind", "max rel diff (pyFM basis)", "max rel diff (own basis)"
    );
    for kind in ["hks", "wks"] {
        let out = tmp.join(format!("{kind}.npy"));
        let basis = tmp.join("basis.npz");
        run(Command::new(&py)
            .arg(peers_dir().join("descriptors.py"))
            .arg(&mesh_path)
            .args([
                "--k",
                &args.k.to_string(),
                "--kind",
                kind,
                "--n-descr",
                &args.n_descr.to_string(),
                "--out",
            ])
            .arg(&out)
            .arg("--basis-out")
            .arg(&basis))?;
        let reference = read_npy_f64_2d(&out)?;
        let (evals, evecs) = read_basis(&basis)?;
        let compute =
            |evals: &DVector<f64>, evecs: &DMatrix<f64>| -> anyhow::Result<DMatrix<f64>> {
                Ok(match kind {
                    "hks" => hks(evals, evecs, &{
                        let mut p = HksParams::default();
                        p.n_times = args.n_descr;
                        p
                    })?,
                    _ => wks(evals, evecs, &{
                        let mut p = WksParams::default();
                        p.n_energies = args.n_descr;
                        p
                    })?,
                })
            };
        let same = compute(&evals, &evecs)?;
        let own = compute(&ours_basis.eigenvalues, &ours_basis.eigenvectors)?;
        println!(
            "{kind:<5} {:>24.2e} {:>24.2e}",
            max_rel(&same, &reference),
            max_rel(&own, &reference)
        );
    }
    let _ = std::fs::remove_dir_all(&tmp);
    Ok(())
}

/// Largest |a − b| relative to the largest |b| of the same column.
fn max_rel(a: &DMatrix<f64>, b: &[Vec<f64>]) -> f64 {
    let mut worst = 0.0f64;
    for j in 0..a.ncols() {
        let scale = b.iter().map(|r| r[j].abs()).fold(0.0, f64::max);
        for (i, row) in b.iter().enumerate() {
            worst = worst.max((a[(i, j)] - row[j]).abs() / scale);
        }
    }
    worst
}

fn read_basis(path: &std::path::Path) -> anyhow::Result<(DVector<f64>, DMatrix<f64>)> {
    let mut z = zip::ZipArchive::new(std::fs::File::open(path)?)?;
    let mut get = |name: &str| -> anyhow::Result<(Vec<usize>, Vec<f64>)> {
        let mut e = z
            .by_name(name)
            .with_context(|| format!("{} has no {name}", path.display()))?;
        let mut b = Vec::new();
        e.read_to_end(&mut b)?;
        parse_npy_f64(&b, name)
    };
    let (_, evals) = get("evals.npy")?;
    let (dims, evecs) = get("evecs.npy")?;
    let [n, k] = dims[..] else {
        bail!("evecs is not 2D")
    };
    Ok((
        DVector::from_vec(evals),
        DMatrix::from_row_slice(n, k, &evecs),
    ))
}
