//! `fmaps spectrum`: the eigenbasis of a mesh, timed per stage.

use super::*;

/// An eigensolver error about the mesh `name`: bad input (exit 2) when the
/// mesh cannot have the asked eigenpairs (too small, zero mass), else a
/// runtime failure.
pub(crate) fn spectrum_failure(e: fmaps::eigensolve::Error, name: &str) -> Failure {
    let code = match e {
        fmaps::eigensolve::Error::InvalidK { .. }
        | fmaps::eigensolve::Error::NonPositiveMass { .. }
        | fmaps::eigensolve::Error::InvalidParameter(_) => 2,
        _ => 1,
    };
    Failure(code, anyhow::Error::new(e).context(name.to_string()))
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn spectrum(
    path: Option<&Path>,
    builtin: Option<Builtin>,
    k: usize,
    backend: Backend,
    mass: Mass,
    block_size: Option<usize>,
    json: bool,
    out: Option<&Path>,
) -> Result<(), Failure> {
    if out.is_some_and(|p| p.as_os_str() == "-") {
        return Err(input(anyhow::anyhow!(
            "--out -: the basis is three files (FILE.npy, FILE_eigenvalues.npy, FILE_mass.npy); name FILE.npy"
        )));
    }
    let files = out.map(basis_files);
    if let Some(f) = &files {
        let outs: Vec<&Path> = f.iter().map(PathBuf::as_path).collect();
        crate::outputs::check_outputs(&path.into_iter().collect::<Vec<_>>(), &outs)?;
    }
    let t = Instant::now();
    let (name, mesh) = match (path, builtin) {
        (Some(p), _) => (p.display().to_string(), load(p)?),
        (None, Some(Builtin::Sphere)) => (
            "builtin unit sphere (icosphere, 5 subdivisions)".to_string(),
            fmaps::shapes::icosphere(1.0, 5),
        ),
        (None, Some(Builtin::Torus)) => (
            "builtin torus R=1, r=0.4".to_string(),
            fmaps::shapes::torus(1.0, 0.4, 160, 64),
        ),
        (None, None) => return Err(input(anyhow::anyhow!("give a mesh file or --builtin"))),
    };
    let load_s = t.elapsed().as_secs_f64();
    let mut params = SpectrumParams::default();
    params.mass = match mass {
        Mass::Lumped => MassKind::Lumped,
        Mass::Voronoi => MassKind::Voronoi,
    };
    params.backend = backend;
    params.threads = rayon::current_num_threads();
    params.block_size = block_size;
    let spinner = Spinner::new(format!("{k} eigenpairs of {} vertices", mesh.n_vertices()));
    let s = fmaps::spectrum(&mesh, k, &params);
    drop(spinner);
    let s = s.map_err(|e| spectrum_failure(e, &name))?;
    let b = &s.basis;
    if let Some(files) = &files {
        write_basis(files, b)?;
    }
    let peak = peak_rss_mb();
    let exact: Option<Vec<f64>> = matches!(builtin, Some(Builtin::Sphere)).then(|| {
        (0..)
            .flat_map(|l: usize| std::iter::repeat_n((l * (l + 1)) as f64, 2 * l + 1))
            .take(k)
            .collect()
    });
    let mut o = String::new();
    if json {
        let v = json!({
            "mesh": name,
            "n_vertices": mesh.n_vertices(),
            "n_faces": mesh.n_faces(),
            "k": k,
            "backend": b.report.backend,
            "shift": b.report.shift,
            "threads": rayon::current_num_threads(),
            "seconds": { "load": load_s, "laplacian": s.times.laplacian, "factorization": s.times.factorization, "eigensolve": s.times.eigensolve },
            "restarts": b.report.restarts,
            "operator_applications": b.report.operator_applications,
            "max_residual": b.report.max_residual(),
            "orthonormality_error": b.report.orthonormality_error,
            "skipped_degenerate_faces": s.skipped_faces.len(),
            "peak_rss_mb": peak,
            "eigenvalues": b.eigenvalues.as_slice(),
            "residuals": b.report.residuals,
        });
        return emit(&format!(
            "{}\n",
            serde_json::to_string(&v).map_err(runtime)?
        ));
    }
    outln!(
        o,
        "{name}: {} vertices, {} faces",
        mesh.n_vertices(),
        mesh.n_faces()
    );
    if !s.skipped_faces.is_empty() {
        outln!(
            o,
            "warning: {} degenerate faces were left out of the Laplacian",
            s.skipped_faces.len()
        );
    }
    outln!(
        o,
        "{} backend, k = {k}, shift {:.4}: {} restarts, {} operator applications",
        b.report.backend,
        b.report.shift,
        b.report.restarts,
        b.report.operator_applications
    );
    outln!(
        o,
        "seconds: load {:.3}  laplacian {:.4}  factorization {:.3}  eigensolve {:.3}  (peak memory {})",
        load_s,
        s.times.laplacian,
        s.times.factorization,
        s.times.eigensolve,
        peak.map_or("n/a".into(), |m| format!("{m:.0} MB"))
    );
    outln!(
        o,
        "max residual ‖Lφ − λMφ‖_M⁻¹ = {:.2e}, max |ΦᵀMΦ − I| = {:.2e}",
        b.report.max_residual(),
        b.report.orthonormality_error
    );
    match &exact {
        Some(ex) => {
            outln!(o, "   i   eigenvalue          exact l(l+1)   rel. error");
            for (i, (l, e)) in b.eigenvalues.iter().zip(ex).enumerate() {
                let rel = if *e > 0.0 {
                    format!("{:.2e}", (l - e).abs() / e)
                } else {
                    "-".into()
                };
                outln!(o, "{i:4}   {l:<18.10} {e:<14} {rel}");
            }
        }
        None => {
            outln!(o, "   i   eigenvalue");
            for (i, l) in b.eigenvalues.iter().enumerate() {
                outln!(o, "{i:4}   {l:.12}");
            }
        }
    }
    if let Some(out) = out {
        if is_npz(out) {
            outln!(
                o,
                "wrote {} (eigenvectors, eigenvalues, mass)",
                out.display()
            );
        } else {
            outln!(o, "wrote {} (+ _eigenvalues.npy, _mass.npy)", out.display());
        }
    }
    emit(&o)
}

/// The files of `--out`: FILE.npz alone (one archive with the arrays
/// `eigenvectors`, `eigenvalues`, `mass`), or for FILE.npy three files:
/// FILE.npy (eigenvectors), FILE_eigenvalues.npy, FILE_mass.npy.
fn basis_files(out: &Path) -> Vec<PathBuf> {
    if is_npz(out) {
        return vec![out.to_path_buf()];
    }
    let stem = out.with_extension("");
    let sibling = |suffix: &str| PathBuf::from(format!("{}_{suffix}.npy", stem.display()));
    vec![out.to_path_buf(), sibling("eigenvalues"), sibling("mass")]
}

fn is_npz(p: &Path) -> bool {
    p.extension().is_some_and(|e| e.eq_ignore_ascii_case("npz"))
}

/// The basis as the files of [`basis_files`], written together.
fn write_basis(files: &[PathBuf], b: &fmaps::eigensolve::SpectralBasis) -> Result<(), Failure> {
    let mut staged = crate::outputs::Staged::default();
    let arrays: [(&str, &[usize], &[f64]); 3] = [
        ("eigenvectors", &[b.n(), b.k()], b.eigenvectors.as_slice()),
        ("eigenvalues", &[b.k()], b.eigenvalues.as_slice()),
        ("mass", &[b.n()], b.mass.as_slice()),
    ];
    if let [one] = files
        && is_npz(one)
    {
        let mut blobs = Vec::new();
        for (name, shape, data) in arrays {
            let mut npy = Vec::new();
            fmaps::mesh_io::npy::write_f64(&mut npy, shape, data).map_err(runtime)?;
            blobs.push((format!("{name}.npy"), npy));
        }
        let entries: Vec<(&str, &[u8])> = blobs
            .iter()
            .map(|(n, d)| (n.as_str(), d.as_slice()))
            .collect();
        staged.stage(one, |tmp| {
            let mut f = std::fs::File::create(tmp)?;
            fmaps::mesh_io::npz::write_archive(&mut f, &entries)?;
            Ok(())
        })?;
        return staged.commit();
    }
    for (path, (_, shape, data)) in files.iter().zip(arrays) {
        staged.stage(path, |tmp| {
            Ok(fmaps::mesh_io::npy::save_f64(tmp, shape, data)?)
        })?;
    }
    staged.commit()
}

/// Peak resident memory of this process (Linux), in MB.
pub(crate) fn peak_rss_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}
