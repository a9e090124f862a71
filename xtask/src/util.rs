//! Paths, the Python peer, and running a child process with its peak memory.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{Context, bail};

/// The workspace root (the parent of this crate's directory).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// `--data`, else `FMAPS_DATA`, else `../shared/datasets` next to the root.
pub fn data_dir(arg: Option<&Path>) -> PathBuf {
    arg.map(Path::to_path_buf)
        .or_else(|| std::env::var_os("FMAPS_DATA").map(PathBuf::from))
        .unwrap_or_else(|| root().join("../shared/datasets"))
}

/// The peers directory (`../shared/peers`).
pub fn peers_dir() -> PathBuf {
    root().join("../shared/peers")
}

/// The Python of the peers' venv, if it is set up.
pub fn peer_python(arg: Option<&Path>) -> Option<PathBuf> {
    let p = arg.map(Path::to_path_buf).unwrap_or_else(|| {
        std::env::var_os("FMAPS_PEERS_VENV")
            .map(PathBuf::from)
            .unwrap_or_else(|| {
                PathBuf::from(std::env::var_os("HOME").unwrap_or_default())
                    .join(".cache/fmaps-peers")
            })
            .join("bin/python")
    });
    p.exists().then_some(p)
}

/// What a finished child printed, and its peak resident memory.
pub struct Run {
    pub stdout: String,
    pub peak_mb: f64,
}

/// Runs a command to completion, capturing stdout; fails with its stderr
/// when it exits non-zero. Peak memory comes from `wait4`'s rusage, so it
/// is the child's own, whatever ran before.
pub fn run(cmd: &mut Command) -> anyhow::Result<Run> {
    let desc = format!("{cmd:?}");
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("starting {desc}"))?;
    let mut stdout = String::new();
    let mut stderr = String::new();
    child.stdout.take().unwrap().read_to_string(&mut stdout)?;
    child.stderr.take().unwrap().read_to_string(&mut stderr)?;
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: plain FFI call with valid out-pointers; the child is ours and
    // has not been waited for.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let r = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    if r != pid {
        bail!("wait4 failed for {desc}");
    }
    if !(libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0) {
        bail!("{desc} failed:\n{stderr}");
    }
    Ok(Run {
        stdout,
        peak_mb: usage.ru_maxrss as f64 / 1024.0,
    })
}
