//! Times every strategy of `nearest_rows` on spectral embeddings of a
//! surface (a weighted grid) at several sizes and dimensions, queries
//! perturbed as a noisy functional map moves them; one thread unless
//! RAYON_NUM_THREADS says otherwise. Medians of 5 after a warm-up (one run above 40,000 rows).
//!
//! `cargo xtask profile strategies -- [FILE:N:K ...]`:
//! without arguments the grid's 5,000-vertex basis; each FILE holds an
//! N x K basis as raw little-endian f64, column-major (e.g. numpy's
//! `np.asfortranarray(phi).T.tofile(FILE)`).

use std::time::Instant;

use fmaps::eigensolve::conformance::grid_basis;
use fmaps::nearest::{NnParams, NnStrategy, cpu_features, nearest_rows, view};
use nalgebra::DMatrix;

pub fn run(argv: Vec<String>) -> Result<(), Box<dyn std::error::Error>> {
    println!(
        "kernels: {}; threads: {}",
        cpu_features(),
        rayon::current_num_threads()
    );
    println!(
        "{:>7} {:>4} {:>9} {:>9} {:>9} {:>9}",
        "n", "d", "brute s", "tree s", "prefix s", "auto s"
    );
    let mut bases: Vec<DMatrix<f64>> = argv
        .into_iter()
        .skip(1)
        .map(|a| {
            let parts: Vec<&str> = a.split(':').collect();
            let (n, k): (usize, usize) = (parts[1].parse().unwrap(), parts[2].parse().unwrap());
            let bytes = std::fs::read(parts[0]).unwrap();
            assert_eq!(bytes.len(), n * k * 8, "{a}: size");
            let v: Vec<f64> = bytes
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
                .collect();
            DMatrix::from_vec(n, k, v)
        })
        .collect();
    if bases.is_empty() {
        bases.push(grid_basis(100, 50, 60).eigenvectors);
    }
    for b in &bases {
        for d in [10, 20, 30, 48].into_iter().filter(|&d| d <= b.ncols()) {
            let x = b.columns(0, d).into_owned();
            let q = DMatrix::from_fn(x.nrows(), d, |i, j| {
                x[(i, j)] * (1.0 + 0.3 * (j as f64 / d as f64) * ((i * 13 + j * 7) as f64).sin())
            });
            let mut row = Vec::new();
            let mut answers = Vec::new();
            let reps = if x.nrows() > 40_000 { 1 } else { 5 };
            for s in [
                NnStrategy::Brute,
                NnStrategy::Tree,
                NnStrategy::Prefix,
                NnStrategy::Auto,
            ] {
                let p = NnParams::with_strategy(s);
                let go = || nearest_rows(view(&x), view(&q), None, &p).unwrap();
                answers.push(go());
                let mut t: Vec<f64> = (0..reps)
                    .map(|_| {
                        let t0 = Instant::now();
                        std::hint::black_box(go());
                        t0.elapsed().as_secs_f64()
                    })
                    .collect();
                t.sort_by(f64::total_cmp);
                row.push(t[t.len() / 2]);
            }
            assert!(
                answers.windows(2).all(|w| w[0] == w[1]),
                "strategies disagree"
            );
            println!(
                "{:>7} {:>4} {:>9.4} {:>9.4} {:>9.4} {:>9.4}",
                x.nrows(),
                d,
                row[0],
                row[1],
                row[2],
                row[3]
            );
        }
    }
    Ok(())
}
