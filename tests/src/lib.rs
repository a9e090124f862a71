//! Helpers of the workspace's cross-crate tests (`tests/*.rs`): where the
//! repository and the benchmark data are. Run them with `cargo xtask test`
//! (or `cargo test --workspace`, which runs them too).
#![deny(missing_docs)]
#![forbid(unsafe_code)]

use std::path::PathBuf;

/// The workspace root (the folder of the top-level `Cargo.toml`).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace root")
        .to_path_buf()
}

/// The benchmark datasets: `FMAPS_DATA`, else `../shared/datasets` beside
/// the repository; `None` (the caller skips with a message) when `probe`,
/// a path inside it, does not exist.
pub fn data_dir(probe: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("FMAPS_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("../shared/datasets"));
    dir.join(probe).exists().then_some(dir)
}

/// A benchmark dataset a test needs is missing: a note past the test
/// harness's capture (a passing run shows the skip), or a failure when
/// `FMAPS_REQUIRE_DATA` is set (CI, where the data is present).
pub fn missing_data(what: &str) {
    if std::env::var_os("FMAPS_REQUIRE_DATA").is_some_and(|v| !v.is_empty() && v != "0") {
        panic!("{what} not found, and FMAPS_REQUIRE_DATA is set");
    }
    use std::io::Write as _;
    let _ = writeln!(
        std::io::stderr(),
        "note: skipped, {what} not found (set FMAPS_DATA)"
    );
}

/// The repository README's Rust example, compiled as a doctest (it reads
/// files a user downloads, so it is built, not run).
#[cfg(doctest)]
#[doc = include_str!("../../README.md")]
struct RepositoryReadme;
