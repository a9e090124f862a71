//! Shared helpers of the CLI tests.

// Each test binary uses some of these helpers.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

pub fn fmaps() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fmaps"))
}

/// Runs `cmd`, asserts success (showing stderr otherwise) and parses its
/// stdout as one JSON object.
pub fn json_of(cmd: &mut Command) -> serde_json::Value {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Runs `fmaps ARGS`, asserts that it is refused with exit code 2
/// (showing its output otherwise) and returns its stderr.
pub fn refused<I, S>(args: I) -> String
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let out = fmaps().args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{err}");
    err
}

/// Runs `fmaps BASE EXTRA` in `dir`; returns its exit code and stderr.
pub fn run_in(dir: &std::path::Path, base: &[&str], extra: &[&str]) -> (Option<i32>, String) {
    let out = fmaps()
        .current_dir(dir)
        .args(base)
        .args(extra)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A unit square grid (25 vertices, area 1) in `dir`: g.off, the
/// identity as ground truth g.vts and map id.map, and shift.map, one step
/// (0.25) to the right except on the last column (mean error 0.25 * 20/25).
pub fn grid_fixture(dir: &std::path::Path) -> (fmaps::mesh_io::TriMesh, Vec<usize>) {
    let m = fmaps::shapes::grid(1.0, 1.0, 4, 4);
    fmaps::mesh_io::write_mesh(dir.join("g.off"), &m).unwrap();
    let n = m.n_vertices();
    let all: Vec<usize> = (0..n).collect();
    fmaps::mesh_io::write_vts(dir.join("g.vts"), &all).unwrap();
    fmaps::mesh_io::write_map(dir.join("id.map"), &all).unwrap();
    let shifted: Vec<usize> = (0..n).map(|v| if v % 5 < 4 { v + 1 } else { v }).collect();
    fmaps::mesh_io::write_map(dir.join("shift.map"), &shifted).unwrap();
    (m, all)
}

/// A fresh directory for one test, removed when dropped (also when the
/// test fails: nothing is left in the system's temporary directory).
pub struct TmpDir(PathBuf);

impl std::ops::Deref for TmpDir {
    type Target = std::path::Path;
    fn deref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::path::Path> for TmpDir {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TmpDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TmpDir {
    fn drop(&mut self) {
        // (Already gone where a test removed it itself.)
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

pub fn tmpdir(name: &str) -> TmpDir {
    let d = std::env::temp_dir().join(format!("fmaps-cli-{name}-{}", std::process::id()));
    // A directory left by an earlier run with the same process id.
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    TmpDir(d)
}
