//! Times one nearest-neighbour strategy on saved embeddings (as written
//! by `cargo xtask bench-refine`, float64 `.npy`), for profiling:
//! `cargo xtask profile nearest --
//! target/bench/refine/data150.npy target/bench/refine/query150.npy tiles 20
//! [hint | GUESSES.npy]` (strategies: brute, tree, prefix, balls, tiles,
//! auto).
use std::time::Instant;

use fmaps::nearest::{NnParams, NnStrategy, cpu_features, nearest_rows, view};
use nalgebra::DMatrix;

/// A float64 `.npy` matrix (either order).
fn load(path: &str) -> Result<DMatrix<f64>, Box<dyn std::error::Error>> {
    let bytes = std::fs::read(path)?;
    let a = fmaps::mesh_io::npy::parse_f64(&bytes)
        .map_err(|(at, m)| format!("{path}, byte {at}: {m}"))?;
    let (r, c) = (a.shape[0], a.shape.get(1).copied().unwrap_or(1));
    Ok(DMatrix::from_column_slice(r, c, &a.data))
}

pub fn run(argv: Vec<String>) -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = argv.into_iter().collect();
    let (data, queries) = (load(&args[1])?, load(&args[2])?);
    let strategy = match args.get(3).map_or("auto", |s| s.as_str()) {
        "brute" => NnStrategy::Brute,
        "tree" => NnStrategy::Tree,
        "prefix" => NnStrategy::Prefix,
        "tiles" => NnStrategy::Tiles,
        "balls" => NnStrategy::Balls,
        _ => NnStrategy::Auto,
    };
    let reps: usize = args.get(4).map_or(10, |s| s.parse().expect("a count"));
    // The balls' clusters (strategy `balls`, or `auto` with guesses and
    // no tiles), computed once, as ZoomOut does per shape.
    let partition = fmaps::nearest::Partition::kmeans(
        view(&data),
        fmaps::nearest::PartitionParams::default().ball_size,
        fmaps::nearest::PartitionParams::default().kmeans_steps,
    );
    let search = |hint: Option<&[usize]>, strategy| {
        nearest_rows(
            view(&data),
            view(&queries),
            hint,
            &NnParams::with_strategy(strategy).with_partition(partition.clone()),
        )
        .expect("rows of equal length")
    };
    // `hint` as a fifth argument: the answer itself as guesses (as late in
    // ZoomOut and ICP); a path to a float64 .npy of indices: those.
    let hint = match args.get(5).map(|s| s.as_str()) {
        Some("hint") => Some(search(None, NnStrategy::Brute)),
        Some(path) => Some(load(path)?.iter().map(|&v| v as usize).collect()),
        None => None,
    };
    let t = Instant::now();
    let mut sum = 0usize;
    for _ in 0..reps {
        let found = search(hint.as_deref(), strategy);
        sum += found.iter().sum::<usize>();
    }
    println!(
        "{strategy:?}: {:.4} s per search ({} x {} among {}, checksum {sum}; {}, {} threads)",
        t.elapsed().as_secs_f64() / reps as f64,
        queries.nrows(),
        queries.ncols(),
        data.nrows(),
        cpu_features(),
        rayon::current_num_threads()
    );
    Ok(())
}
