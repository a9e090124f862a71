//! `cargo xtask`: benchmarks and checks that span the workspace.
//!
//! - `cargo xtask bench [--quick]`: Laplacian assembly and eigensolve on a
//!   FAUST mesh and its subdivisions, side by side with SciPy, table on
//!   stdout and `target/bench/eigensolve.json`.

mod bench;
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
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Bench(a) => bench::bench(&a),
    }
}
