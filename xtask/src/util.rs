//! Paths, the Python peer, and running a child process with its peak memory.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{Context, bail};

/// Where the data and the Python peers are (shared by the xtask commands).
#[derive(clap::Args)]
pub struct PeerArgs {
    /// Dataset directory (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Python of the peers' venv (default: ~/.cache/fmaps-peers/bin/python).
    #[arg(long)]
    pub python: Option<PathBuf>,
}

/// One test pair timed against a peer (shared by the bench-* commands).
#[derive(clap::Args)]
pub struct PairBench {
    #[command(flatten)]
    pub peers: PeerArgs,
    /// Collection.
    #[arg(long, default_value = "FAUST")]
    pub collection: String,
    /// Index of the test pair.
    #[arg(long, default_value_t = 0)]
    pub pair: usize,
    /// Repetitions of each timing, both sides, after a warm-up run
    /// (medians are reported, so at least 5).
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// Threads for both sides.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
}

/// The median (NaN for no values).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

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

/// The `bcicp` benchmark folder of the dataset directory, checked.
pub fn bcicp_dir(arg: Option<&Path>) -> anyhow::Result<PathBuf> {
    let bcicp = data_dir(arg).join("bcicp");
    if !bcicp.is_dir() {
        bail!(
            "{} not found: pass --data or set FMAPS_DATA",
            bcicp.display()
        );
    }
    Ok(bcicp)
}

/// The collections asked for, FAUST and TOSCA_Isometric when none.
pub fn collections_or_default(asked: &[String]) -> Vec<String> {
    if asked.is_empty() {
        vec!["FAUST".to_string(), "TOSCA_Isometric".to_string()]
    } else {
        asked.to_vec()
    }
}

/// The release `fmaps` binary next to this xtask binary, built first (a
/// no-op when up to date).
pub fn fmaps_binary() -> anyhow::Result<PathBuf> {
    let status = Command::new(env!("CARGO"))
        .args([
            "build",
            "--release",
            "-q",
            "-p",
            "fmaps-cli",
            "--bin",
            "fmaps",
        ])
        .current_dir(root())
        .status()
        .context("building the fmaps binary")?;
    if !status.success() {
        bail!("cargo build -p fmaps-cli failed");
    }
    let exe = std::env::current_exe()?;
    let bin = exe
        .parent()
        .context("xtask binary without a folder")?
        .join("fmaps");
    if !bin.is_file() {
        bail!("{} not found after building", bin.display());
    }
    Ok(bin)
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
/// when it exits non-zero. The command runs under this xtask's hidden
/// `measure-child` subcommand, whose only child it is, so the peak memory
/// that `getrusage(RUSAGE_CHILDREN)` reports there is the command's own,
/// whatever ran before (no `unsafe` here: see [`measure_child`]).
pub fn run(cmd: &mut Command) -> anyhow::Result<Run> {
    let desc = format!("{cmd:?}");
    let peak_file = std::env::temp_dir().join(format!(
        "fmaps-xtask-peak-{}-{}",
        std::process::id(),
        RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    ));
    let mut wrapped = Command::new(std::env::current_exe()?);
    wrapped
        .arg("measure-child")
        .arg(&peak_file)
        .arg(cmd.get_program())
        .args(cmd.get_args());
    if let Some(dir) = cmd.get_current_dir() {
        wrapped.current_dir(dir);
    }
    for (k, v) in cmd.get_envs() {
        match v {
            Some(v) => wrapped.env(k, v),
            None => wrapped.env_remove(k),
        };
    }
    let out = wrapped
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .output()
        .with_context(|| format!("starting {desc}"))?;
    let peak = std::fs::read_to_string(&peak_file).ok();
    std::fs::remove_file(&peak_file).ok();
    if !out.status.success() {
        bail!("{desc} failed:\n{}", String::from_utf8_lossy(&out.stderr));
    }
    let peak_kb: f64 = peak
        .as_deref()
        .and_then(|p| p.trim().parse().ok())
        .with_context(|| format!("no peak memory recorded for {desc}"))?;
    Ok(Run {
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        peak_mb: peak_kb / 1024.0,
    })
}

/// Distinguishes the peak-memory files of the runs of one xtask.
static RUNS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// `xtask measure-child PEAK_FILE PROGRAM ARGS...`: runs the program with
/// this process's standard streams, writes its peak resident memory (KB,
/// `getrusage(RUSAGE_CHILDREN)`: this process has no other child) to
/// PEAK_FILE, and exits with its status.
pub fn measure_child(args: &[std::ffi::OsString]) -> anyhow::Result<i32> {
    let [peak_file, program, rest @ ..] = args else {
        bail!("measure-child: expected PEAK_FILE PROGRAM [ARGS...]");
    };
    let status = Command::new(program)
        .args(rest)
        .status()
        .with_context(|| format!("starting {}", program.to_string_lossy()))?;
    let usage = nix::sys::resource::getrusage(nix::sys::resource::UsageWho::RUSAGE_CHILDREN)?;
    std::fs::write(peak_file, usage.max_rss().to_string())?;
    Ok(status.code().unwrap_or(1))
}

/// Parses a little-endian float64 `.npy` (C or Fortran order): shape and
/// data in C (row-major) order.
pub fn parse_npy_f64(b: &[u8], what: &str) -> anyhow::Result<(Vec<usize>, Vec<f64>)> {
    if b.len() < 10 || &b[..6] != b"\x93NUMPY" {
        bail!("{what} is not a .npy file");
    }
    let (hlen, start) = if b[6] == 1 {
        (u16::from_le_bytes([b[8], b[9]]) as usize, 10)
    } else {
        (u32::from_le_bytes([b[8], b[9], b[10], b[11]]) as usize, 12)
    };
    let header = std::str::from_utf8(&b[start..start + hlen])?;
    if !header.contains("'<f8'") {
        bail!("{what}: expected float64 data, header {header}");
    }
    let fortran = header.contains("'fortran_order': True");
    let shape = header
        .split("'shape': (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .context("no shape")?;
    let dims: Vec<usize> = shape
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse())
        .collect::<Result<_, _>>()?;
    let count: usize = dims.iter().product();
    let data = &b[start + hlen..];
    if data.len() != count * 8 {
        bail!("{what}: truncated data");
    }
    let raw: Vec<f64> = data
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    if fortran && dims.len() == 2 {
        let (r, c) = (dims[0], dims[1]);
        let mut out = vec![0.0; count];
        for i in 0..r {
            for j in 0..c {
                out[i * c + j] = raw[j * r + i];
            }
        }
        return Ok((dims, out));
    }
    Ok((dims, raw))
}

/// Reads a float64 2D `.npy` file as rows.
pub fn read_npy_f64_2d(path: &Path) -> anyhow::Result<Vec<Vec<f64>>> {
    let b = std::fs::read(path)?;
    let (dims, data) = parse_npy_f64(&b, &path.display().to_string())?;
    let [_, cols] = dims[..] else {
        bail!("{}: expected a 2D array", path.display())
    };
    Ok(data.chunks(cols.max(1)).map(<[f64]>::to_vec).collect())
}

/// The CPU model (from /proc/cpuinfo on Linux).
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into())
}

/// The header line of every benchmark table: CPU model, the instruction
/// set fmaps' kernels run at here (AVX-512 / AVX2 / baseline, AMX yes or
/// no) and the threads the fmaps side actually used.
pub fn machine_header(threads_used: usize) -> String {
    format!(
        "machine: {} ({} cores); fmaps kernels: {}; fmaps threads used: {threads_used}",
        cpu_model(),
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        fmaps::nearest::cpu_features()
    )
}
