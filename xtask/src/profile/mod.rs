//! Profiling harnesses: one stage run repeatedly on real inputs, for
//! `perf` and for A/B timings of two builds (`cargo xtask profile KIND --
//! ARGS...`). They print times and checksums; the benchmarks with peers,
//! warm-ups and medians are `cargo xtask bench*`.

mod eigen;
mod geodesic;
mod nearest;
mod refine;
mod strategies;

/// Which harness.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum Kind {
    /// The native eigensolver on one mesh: `MESH.off [K] [RUNS] [SUBSPACE] [BLOCK] [THREADS]`.
    Eigen,
    /// ZoomOut 50:150:5, ICP or the fit on one pair: `A.off B.off [zoomout|zoomout1|icp|fit] [REPEATS]`.
    Refine,
    /// The exact geodesic solver, one source at a time: `[--sources N] [--window-ordered] [--save DIR | --check DIR] MESH.off...`.
    Geodesic,
    /// One nearest-neighbour strategy on saved embeddings: `DATA.npy QUERIES.npy STRATEGY RUNS [hint | GUESSES.npy]`.
    Nearest,
    /// Every nearest-neighbour strategy on spectral embeddings: `[FILE:N:K ...]`.
    Strategies,
}

/// `cargo xtask profile`.
#[derive(clap::Args)]
pub struct Args {
    /// The harness.
    kind: Kind,
    /// Its arguments (after `--`).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    args: Vec<String>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let argv: Vec<String> = std::iter::once(format!("profile {:?}", args.kind))
        .chain(args.args)
        .collect();
    let result = match args.kind {
        Kind::Eigen => eigen::run(argv),
        Kind::Refine => refine::run(argv),
        Kind::Geodesic => geodesic::run(argv),
        Kind::Nearest => nearest::run(argv),
        Kind::Strategies => strategies::run(argv),
    };
    result.map_err(|e| anyhow::anyhow!("{e}"))
}
