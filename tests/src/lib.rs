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

/// The repository README's Rust example, compiled as a doctest (it reads
/// files a user downloads, so it is built, not run).
#[cfg(doctest)]
#[doc = include_str!("../../README.md")]
struct RepositoryReadme;
