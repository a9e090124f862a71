//! `cargo xtask`: benchmarks and checks that span the workspace.
//!
//! - `cargo xtask bench [--quick]`: Laplacian assembly and eigensolve on a
//!   FAUST mesh and its subdivisions, side by side with SciPy, table on
//!   stdout and `target/bench/eigensolve.json`.
//! - `cargo xtask eval [--collection C] [--pairs N]`: the benchmark table
//!   (published maps today), JSON per method in `target/eval/`.
//! - `cargo xtask generate`: the generated body collection (exact ground
//!   truth; `generated-iso` and `generated-noniso` pairs).
//! - `cargo xtask starts`: multi-start selection rules against the best
//!   start per pair.
//! - `cargo xtask descriptor-check`: HKS/WKS against pyFM's.
//! - `cargo xtask pictures`: pictures of one FAUST and one TOSCA pair in
//!   `docs/pictures/`.
//! - `cargo xtask publish-check`: crates.io readiness of every crate.
//! - `cargo xtask geodesic-check`: exact geodesics against tvb-gdist (largest
//!   relative difference, time per source).

#![forbid(unsafe_code)]

mod bench;
mod bench_learn;
mod bench_match;
mod bench_refine;
mod collections;
mod confidence;
mod descriptor_check;
mod eval;
mod figures;
mod fit_check;
mod generated;
mod geodesic_check;
mod learn;
mod methods;
mod pictures;
mod profile;
mod publish_check;
mod starts;
mod test;
mod util;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "cargo xtask")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Benchmark the Laplacian and the eigensolvers against SciPy.
    Bench(bench::Args),
    /// The benchmark table over test pairs (published maps, fmaps-default (= smooth-shells, what `fmaps match` runs), fmaps-init, fmaps-icp, fmaps-zoomout[:START:FINAL:STEP], fmaps-smooth-shells[:KEY=VALUE,..] (fmaps-smooth-shells:non-isometric = `fmaps match --non-isometric`), REFINER@PUBLISHED such as zoomout@WKSini_symm, pyfm:<stage>).
    Eval(eval::Args),
    /// Scores without ground truth (metric, area and conformal distortion) as detectors of globally wrong maps, on maps saved by `cargo xtask eval --save-maps`.
    Confidence(confidence::Args),
    /// Write the generated benchmark collection (bodies of different builds and poses, exact ground truth) to target/generated/bcicp/generated.
    Generate(generated::Args),
    /// Multi-start selection rules (orientation, area/conformal distortion, ...) against the best start per pair.
    Starts(starts::Args),
    /// Compare HKS/WKS with pyFM's (needs the Python peers).
    DescriptorCheck(descriptor_check::Args),
    /// Compare exact geodesics with tvb-gdist (needs the Python peers).
    GeodesicCheck(geodesic_check::Args),
    /// Exact functional-map minimum vs pyFM's L-BFGS-B fit, same inputs.
    FitCheck(fit_check::Args),
    /// `fmaps match` stage by stage against pyFM's same pipeline.
    BenchMatch(bench_match::Args),
    /// Nearest neighbours, ICP and ZoomOut against scikit-learn, SciPy and pyFM on one pair.
    BenchRefine(bench_refine::Args),
    /// DiffusionNet's forward and backward passes on one benchmark shape.
    BenchLearn(bench_learn::Args),
    /// `fmaps train` on the FAUST training shapes (tr_reg_000-079); options after `--` go to it.
    Train(learn::TrainArgs),
    /// Learned features on a collection's test pairs: nearest features, exact-geodesic error.
    LearnEval(learn::EvalArgs),
    /// Arrays for the PyTorch parity check of DiffusionNet and the training losses (crates/learn/peers/parity.py).
    LearnParity(learn::ParityArgs),
    /// The seed paper's Figure 8 curve and Figure 1 heat maps, into docs/.
    Figures(figures::Args),
    /// Pictures of one test pair per collection (transfer, errors, C, embedding, curves), into docs/pictures/.
    Pictures(pictures::Args),
    /// Profiling harnesses (eigen, refine, geodesic, nearest, strategies): one stage repeated on real inputs, for perf and A/B timings.
    Profile(profile::Args),
    /// Every test: `cargo test --workspace` (tidy tests included), then the nearest-neighbour tests without AMX tiles.
    Test(test::Args),
    /// The parsers' property tests with 10,000 cases each (release build): mesh formats, correspondence and landmark files, option syntaxes, and the CLI's nasty-input corpus.
    Fuzz(test::FuzzArgs),
    /// crates.io readiness of every crate: metadata, licences, docs, `cargo publish --dry-run` in dependency order.
    PublishCheck(publish_check::Args),
    /// (Internal) runs a program and records its peak memory, for the
    /// benchmarks: `measure-child PEAK_FILE PROGRAM ARGS...`.
    #[command(hide = true)]
    MeasureChild {
        /// PEAK_FILE PROGRAM ARGS...
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<std::ffi::OsString>,
    },
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Bench(a) => bench::bench(&a),
        Command::Eval(a) => eval::eval(&a),
        Command::Generate(a) => generated::generate(&a),
        Command::Confidence(a) => confidence::confidence(&a),
        Command::Starts(a) => starts::starts(&a),
        Command::DescriptorCheck(a) => descriptor_check::descriptor_check(&a),
        Command::GeodesicCheck(a) => geodesic_check::geodesic_check(&a),
        Command::FitCheck(a) => fit_check::fit_check(&a),
        Command::Figures(a) => figures::figures(&a),
        Command::Profile(a) => profile::run(a),
        Command::Pictures(a) => pictures::pictures(&a),
        Command::PublishCheck(a) => publish_check::publish_check(&a),
        Command::Test(a) => test::test(&a),
        Command::Fuzz(a) => test::fuzz(&a),
        Command::MeasureChild { args } => std::process::exit(util::measure_child(&args)?),
        Command::BenchMatch(a) => bench_match::bench_match(&a),
        Command::BenchRefine(a) => bench_refine::bench_refine(&a),
        Command::BenchLearn(a) => bench_learn::bench_learn(&a),
        Command::Train(a) => learn::train(&a),
        Command::LearnEval(a) => learn::learn_eval(&a),
        Command::LearnParity(a) => learn::learn_parity(&a),
    }
}
