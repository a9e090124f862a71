//! Output files of a command: never an input, never named twice, and
//! written together ([`mesh_io::atomic::Outputs`]) — every content produced
//! first, then devices and pipes written through and regular files renamed
//! into place, so a failure while producing any output leaves every output
//! as it was.

use std::path::{Path, PathBuf};

use super::*;

/// A path as the file system resolves it (the folder canonicalized, for a
/// file that does not exist yet).
fn resolved(p: &Path) -> PathBuf {
    if let Ok(c) = p.canonicalize() {
        return c;
    }
    let parent = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    match (parent.canonicalize(), p.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => p.to_path_buf(),
    }
}

/// Whether `out` is the file, pipe or terminal this process's standard
/// output writes to (`--out /dev/stdout`): the report then goes to
/// standard error.
fn is_our_stdout(out: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::fd::AsFd;
        use std::os::unix::fs::MetadataExt;
        let ours = std::io::stdout()
            .as_fd()
            .try_clone_to_owned()
            .map(std::fs::File::from)
            .and_then(|f| f.metadata());
        match (ours, std::fs::metadata(out)) {
            (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = out;
        false
    }
}

/// Refuses (exit 2) a path that cannot take an output: a directory, a
/// loop of links, a file in a folder that does not exist.
fn writable(out: &Path) -> Result<(), Failure> {
    use mesh_io::atomic::OutputTarget;
    let bad = |why: String| {
        Err(input(anyhow::anyhow!(
            "{}: cannot be written as an output: {why}",
            out.display()
        )))
    };
    match mesh_io::atomic::output_target(out) {
        Err(e) => bad(e.to_string()),
        Ok(OutputTarget::File(p)) => {
            let dir = match p.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            if dir.is_dir() {
                Ok(())
            } else {
                bad(format!("the folder {} does not exist", dir.display()))
            }
        }
        Ok(_) => Ok(()),
    }
}

/// Refuses outputs that would overwrite an input or each other, or that
/// no file can be written to (exit 2).
pub(crate) fn check_outputs(inputs: &[&Path], outputs: &[&Path]) -> Result<(), Failure> {
    let ins: Vec<PathBuf> = inputs.iter().map(|p| resolved(p)).collect();
    let mut seen: Vec<(PathBuf, &Path)> = Vec::new();
    for out in outputs {
        if out.as_os_str() == "-" {
            if seen.iter().any(|(_, o)| o.as_os_str() == "-") {
                return Err(input(anyhow::anyhow!(
                    "-: standard output named for two outputs"
                )));
            }
            crate::STDOUT_IS_AN_OUTPUT.store(true, std::sync::atomic::Ordering::Relaxed);
            seen.push((PathBuf::from("-"), out));
            continue;
        }
        writable(out)?;
        if is_our_stdout(out) {
            crate::STDOUT_IS_AN_OUTPUT.store(true, std::sync::atomic::Ordering::Relaxed);
        }
        let r = resolved(out);
        if let Some(i) = ins.iter().position(|x| *x == r) {
            return Err(input(anyhow::anyhow!(
                "{}: this output would overwrite the input {}",
                out.display(),
                inputs[i].display()
            )));
        }
        if let Some((_, first)) = seen.iter().find(|(x, _)| *x == r) {
            return Err(input(anyhow::anyhow!(
                "{}: named for two outputs (also {})",
                out.display(),
                first.display()
            )));
        }
        seen.push((r, out));
    }
    Ok(())
}

/// Outputs written together ([`stage`](Self::stage), then
/// [`commit`](Self::commit)), by the policy of
/// [`mesh_io::atomic`]: regular files atomically, devices, FIFOs and
/// sockets written through, links followed, `-` to standard output;
/// dropped without a commit, the temporaries are removed and every output
/// is as it was.
#[derive(Default)]
pub(crate) struct Staged {
    outputs: mesh_io::atomic::Outputs,
}

impl Staged {
    /// Writes `path`'s content to a temporary file through `write` (given
    /// the temporary's path). A path that cannot be an output (a
    /// directory) is bad input (exit 2); a failure to write is exit 1.
    pub(crate) fn stage(
        &mut self,
        path: &Path,
        write: impl FnOnce(&Path) -> anyhow::Result<()>,
    ) -> Result<(), Failure> {
        if let Err(e) = mesh_io::atomic::output_target(path) {
            return Err(input(anyhow::anyhow!(
                "{}: cannot be written as an output: {e}",
                path.display()
            )));
        }
        self.outputs
            .stage(path, |tmp| -> anyhow::Result<()> { write(tmp) })
            .with_context(|| format!("writing {}", path.display()))
            .map_err(runtime)
    }

    /// Writes every staged output into place.
    pub(crate) fn commit(self) -> Result<(), Failure> {
        self.outputs
            .commit()
            .context("writing the outputs")
            .map_err(runtime)
    }
}

/// The outputs of `match` and `refine`, written together: the point map
/// (`.map`, 1-based; `.npy`/`.npz`: int64, 0-based) and C as text (one row
/// per line, 17 significant digits; `.npy`/`.npz`: float64).
pub(crate) fn write_map_outputs(
    out: Option<&Path>,
    save_fmap: Option<&Path>,
    t_ab: &[usize],
    c: &nalgebra::DMatrix<f64>,
) -> Result<(), Failure> {
    use mesh_io::arrays::{Container, write_indices, write_matrix};
    let mut staged = Staged::default();
    if let Some(out) = out {
        if let Some(container) = Container::of(out) {
            staged.stage(out, |tmp| Ok(write_indices(tmp, t_ab, container)?))?;
        } else {
            staged.stage(out, |tmp| Ok(mesh_io::write_map(tmp, t_ab)?))?;
        }
    }
    if let Some((path, container)) = save_fmap.and_then(|p| Some((p, Container::of(p)?))) {
        staged.stage(path, |tmp| {
            Ok(write_matrix(
                tmp,
                c.nrows(),
                c.ncols(),
                c.as_slice(),
                container,
            )?)
        })?;
    } else if let Some(path) = save_fmap {
        let mut text = String::new();
        for row in c.row_iter() {
            let cells: Vec<String> = row.iter().map(|v| format!("{v:.17e}")).collect();
            outln!(text, "{}", cells.join(" "));
        }
        staged.stage(path, |tmp| Ok(std::fs::write(tmp, text)?))?;
    }
    staged.commit()
}
