//! Times the exact solver on real meshes, one source at a time on one
//! thread, and optionally checks the fields against saved references.
//!
//! ```text
//! cargo xtask profile geodesic -- \
//!     [--sources N] [--window-ordered] [--save DIR | --check DIR] MESH.off...
//! ```
use std::time::Instant;

use fmaps::geodesic::{ExactAlgorithm, ExactSolver};

pub fn run(argv: Vec<String>) -> Result<(), Box<dyn std::error::Error>> {
    let mut args = argv.into_iter().skip(1);
    let (mut n_src, mut save, mut check, mut meshes) = (10usize, None, None, Vec::new());
    let mut algorithm = ExactAlgorithm::Vtp;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--sources" => n_src = args.next().ok_or("--sources N")?.parse()?,
            "--save" => save = Some(args.next().ok_or("--save DIR")?),
            "--check" => check = Some(args.next().ok_or("--check DIR")?),
            "--window-ordered" => algorithm = ExactAlgorithm::WindowOrdered,
            _ => meshes.push(a),
        }
    }
    println!(
        "{:<14} {:>6} {:>4} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "mesh", "n", "src", "ms/src", "windows", "propag", "stored", "max rel"
    );
    for path in &meshes {
        let mesh = fmaps::mesh_io::read_mesh(path)?;
        let solver = ExactSolver::new(&mesh)?.with_algorithm(algorithm);
        let n = mesh.vertices().len();
        let stem = std::path::Path::new(path)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let (mut secs, mut windows, mut propagated, mut worst) = (0.0, 0u64, 0u64, 0.0f64);
        let mut stored = 0;
        for i in 0..n_src {
            let s = i * n / n_src;
            let t = Instant::now();
            let (d, st) = solver.distances_with_stats(&[s])?;
            secs += t.elapsed().as_secs_f64();
            windows += st.windows;
            propagated += st.propagated;
            stored = stored.max(st.peak_stored);
            let file = |dir: &str| format!("{dir}/{stem}-{s}.txt");
            if let Some(dir) = &save {
                std::fs::create_dir_all(dir)?;
                let text: Vec<String> = d.iter().map(|x| format!("{x:e}")).collect();
                std::fs::write(file(dir), text.join("\n"))?;
            }
            if let Some(dir) = &check {
                let text = std::fs::read_to_string(file(dir))?;
                let (mut bad, mut inf) = (0, 0);
                for (x, r) in d.iter().zip(text.lines()) {
                    let r: f64 = r.parse()?;
                    let rel = (x - r).abs() / r.max(1e-300);
                    let rel = if x == &r { 0.0 } else { rel };
                    worst = worst.max(rel);
                    bad += usize::from(rel > 1e-9);
                    inf += usize::from(x.is_infinite());
                }
                if bad > 0 && std::env::var_os("VERBOSE").is_some() {
                    eprintln!("{stem} source {s}: {bad} vertices off by > 1e-9, {inf} unreached");
                }
            }
        }
        println!(
            "{:<14} {:>6} {:>4} {:>10.2} {:>10} {:>10} {:>10} {:>10.2e}",
            stem,
            n,
            n_src,
            1e3 * secs / n_src as f64,
            windows / n_src as u64,
            propagated / n_src as u64,
            stored,
            worst
        );
    }
    Ok(())
}
