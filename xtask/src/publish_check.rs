//! `cargo xtask publish-check`: everything crates.io needs, for every
//! publishable crate of the workspace: manifest metadata, licence files,
//! crate docs with a runnable example and `#![deny(missing_docs)]`,
//! `cargo doc` without warnings, and `cargo publish --dry-run` of the
//! whole workspace in dependency order (cargo packages each crate, and
//! builds it against the packaged versions of the crates before it).

use std::path::Path;
use std::process::Command;

use anyhow::{Context, bail};

use crate::util::root;

/// Options of `cargo xtask publish-check`.
#[derive(clap::Args)]
pub struct Args {
    /// Allow uncommitted changes (passed to `cargo publish`).
    #[arg(long)]
    allow_dirty: bool,
    /// Only the metadata and documentation checks (no packaging build).
    #[arg(long)]
    no_dry_run: bool,
}

/// crates.io category slugs the workspace may use (all valid on
/// crates.io; extend from <https://crates.io/category_slugs>).
const CATEGORIES: &[&str] = &[
    "algorithms",
    "command-line-utilities",
    "data-structures",
    "graphics",
    "hardware-support",
    "mathematics",
    "parser-implementations",
    "rendering",
    "science",
    "visualization",
];

/// The problems of one package's metadata and sources.
fn check_package(p: &serde_json::Value) -> Vec<String> {
    let mut problems = Vec::new();
    let name = p["name"].as_str().unwrap_or("?");
    let manifest = Path::new(p["manifest_path"].as_str().unwrap_or(""));
    let dir = manifest.parent().unwrap_or(Path::new("."));
    let mut bad = |s: String| problems.push(format!("{name}: {s}"));
    match p["description"].as_str() {
        Some(d) if d.len() >= 20 => {}
        _ => bad("description missing or too short".into()),
    }
    if p["license"].as_str() != Some("MIT OR Apache-2.0") {
        bad(format!(
            "license is {}, expected MIT OR Apache-2.0",
            p["license"]
        ));
    }
    for f in ["LICENSE-MIT", "LICENSE-APACHE"] {
        if !dir.join(f).is_file() {
            bad(format!("{f} missing in {}", dir.display()));
        }
    }
    match p["readme"].as_str() {
        Some(r) if dir.join(r).is_file() => {}
        _ => bad("readme missing".into()),
    }
    for key in ["repository", "homepage"] {
        if p[key].as_str().is_none() {
            bad(format!("{key} missing"));
        }
    }
    let keywords: Vec<&str> = p["keywords"]
        .as_array()
        .map(|a| a.iter().filter_map(|k| k.as_str()).collect())
        .unwrap_or_default();
    if keywords.is_empty() || keywords.len() > 5 {
        bad(format!(
            "{} keywords (crates.io takes 1 to 5)",
            keywords.len()
        ));
    }
    for k in &keywords {
        let ok = k.len() <= 20
            && k.starts_with(|c: char| c.is_ascii_alphabetic())
            && k.chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '+'));
        if !ok {
            bad(format!("keyword `{k}` is not valid on crates.io"));
        }
    }
    let categories: Vec<&str> = p["categories"]
        .as_array()
        .map(|a| a.iter().filter_map(|k| k.as_str()).collect())
        .unwrap_or_default();
    if categories.is_empty() || categories.len() > 5 {
        bad(format!("{} categories (1 to 5)", categories.len()));
    }
    for c in &categories {
        if !CATEGORIES.contains(c) {
            bad(format!("category `{c}` is not a known crates.io slug"));
        }
    }
    let lib = dir.join("src/lib.rs");
    let main = dir.join("src/main.rs");
    if !lib.exists() && main.exists() {
        // A binary-only package (fmaps-cli): crate docs, no doctest.
        match std::fs::read_to_string(&main) {
            Ok(src) if src.starts_with("//!") => {}
            Ok(_) => bad("src/main.rs has no crate docs (//! at the top)".into()),
            Err(e) => bad(format!("{}: {e}", main.display())),
        }
        return problems;
    }
    match std::fs::read_to_string(&lib) {
        Ok(src) => {
            if !src.contains("#![deny(missing_docs)]") {
                bad("src/lib.rs lacks #![deny(missing_docs)]".into());
            }
            let crate_docs: String = src
                .lines()
                .take_while(|l| l.starts_with("//!") || l.trim().is_empty())
                .collect::<Vec<_>>()
                .join("\n");
            if !crate_docs.contains("//! ```") {
                bad("crate docs (//! at the top of src/lib.rs) have no example".into());
            }
        }
        Err(e) => bad(format!("{}: {e}", lib.display())),
    }
    problems
}

pub fn publish_check(args: &Args) -> anyhow::Result<()> {
    let root = root();
    let out = Command::new(env!("CARGO"))
        .args(["metadata", "--format-version", "1", "--no-deps"])
        .current_dir(&root)
        .output()
        .context("running cargo metadata")?;
    if !out.status.success() {
        bail!("cargo metadata: {}", String::from_utf8_lossy(&out.stderr));
    }
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout)?;
    let packages: Vec<&serde_json::Value> = meta["packages"]
        .as_array()
        .context("cargo metadata: no packages")?
        .iter()
        // `publish = false` shows as an empty registry list.
        .filter(|p| p["publish"].as_array().is_none_or(|a| !a.is_empty()))
        .collect();
    let mut problems = Vec::new();
    for p in &packages {
        problems.extend(check_package(p));
    }
    println!(
        "metadata: {} publishable crates checked ({})",
        packages.len(),
        packages
            .iter()
            .filter_map(|p| p["name"].as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    if !problems.is_empty() {
        bail!("{} problems:\n  {}", problems.len(), problems.join("\n  "));
    }

    println!("cargo doc --no-deps (warnings are errors)");
    let mut doc = Command::new(env!("CARGO"));
    doc.args(["doc", "--no-deps", "--workspace", "--exclude", "xtask"])
        .env("RUSTDOCFLAGS", "-D warnings")
        .current_dir(&root);
    if !doc.status()?.success() {
        bail!("cargo doc reported warnings or errors (above)");
    }

    if !args.no_dry_run {
        println!("cargo publish --workspace --dry-run");
        let mut publish = Command::new(env!("CARGO"));
        publish
            .args(["publish", "--workspace", "--dry-run"])
            .current_dir(&root);
        if args.allow_dirty {
            publish.arg("--allow-dirty");
        }
        let out = publish.output()?;
        let stderr = String::from_utf8_lossy(&out.stderr);
        let warnings: Vec<&str> = stderr
            .lines()
            .filter(|l| l.starts_with("warning") && !l.contains("aborting upload due to dry run"))
            .collect();
        if !out.status.success() {
            bail!("cargo publish --dry-run failed:\n{stderr}");
        }
        if !warnings.is_empty() {
            bail!("cargo publish --dry-run warned:\n{}", warnings.join("\n"));
        }
        let uploaded: Vec<&str> = stderr
            .lines()
            .filter_map(|l| l.trim().strip_prefix("Uploading "))
            .collect();
        println!("packaged and verified, in this order:");
        for u in &uploaded {
            println!("  {u}");
        }
        if uploaded.len() != packages.len() {
            bail!(
                "{} crates packaged, {} publishable",
                uploaded.len(),
                packages.len()
            );
        }
    }
    println!("publish-check passed");
    Ok(())
}
