//! `cargo xtask test`: every test of the workspace (unit, integration,
//! doc tests, the cross-crate tests in `tests/` and its tidy tests), then
//! the tests of the ball search and the tiles (nearest, refine, solve)
//! again without matrix tiles
//! (`FMAPS_NO_AMX=1`), so that the paths of CPUs without AMX run on an AMX
//! machine too.

use std::process::Command;

use anyhow::bail;

use crate::util::root;

/// Options of `cargo xtask test`.
#[derive(clap::Args)]
pub struct Args {
    /// Extra features, as for `cargo test --features` (e.g.
    /// `fmaps-cli/arpack,fmaps-tests/arpack`; needs the system ARPACK).
    #[arg(long)]
    features: Option<String>,
    /// Only the tidy tests (seconds, no numerical tests).
    #[arg(long)]
    tidy: bool,
}

/// Runs `cargo` with `args` in the workspace root (with `env` set).
fn cargo(args: &[&str], env: &[(&str, &str)]) -> anyhow::Result<()> {
    let mut cmd = Command::new(env!("CARGO"));
    cmd.args(args).current_dir(root());
    for (k, v) in env {
        cmd.env(k, v);
    }
    eprintln!(
        "$ {}cargo {}",
        env.iter()
            .map(|(k, v)| format!("{k}={v} "))
            .collect::<String>(),
        args.join(" ")
    );
    if !cmd.status()?.success() {
        bail!("cargo {} failed", args.join(" "));
    }
    Ok(())
}

pub fn test(args: &Args) -> anyhow::Result<()> {
    if args.tidy {
        return cargo(&["test", "-p", "fmaps-tests", "--test", "tidy"], &[]);
    }
    let mut all = vec!["test", "--workspace"];
    if let Some(f) = &args.features {
        all.extend(["--features", f]);
    }
    cargo(&all, &[])?;
    cargo(
        &[
            "test",
            "-p",
            "fmaps-nearest",
            "-p",
            "fmaps-refine",
            "-p",
            "fmaps-solve",
        ],
        &[("FMAPS_NO_AMX", "1")],
    )
}

/// Options of `cargo xtask fuzz`.
#[derive(clap::Args)]
pub struct FuzzArgs {
    /// Cases per property.
    #[arg(long, default_value_t = 10_000)]
    cases: u32,
}

/// The fuzz targets: every parser's property tests (arbitrary and mutated
/// bytes, allocation bounds, write-read round trips), the option syntaxes,
/// and the CLI's corpus of nasty inputs through every subcommand.
pub fn fuzz(args: &FuzzArgs) -> anyhow::Result<()> {
    let cases = args.cases.to_string();
    let env = [("FMAPS_FUZZ_CASES", cases.as_str())];
    for (package, test) in [
        ("fmaps-mesh-io", "proptest"),
        ("fmaps-tests", "fuzz"),
        ("fmaps-cli", "corpus"),
    ] {
        cargo(&["test", "--release", "-p", package, "--test", test], &env)?;
    }
    // The multi-start list's grammar, with the command line that parses it.
    cargo(
        &[
            "test",
            "--release",
            "-p",
            "fmaps-cli",
            "--bin",
            "fmaps",
            "starts_",
        ],
        &env,
    )?;
    Ok(())
}
