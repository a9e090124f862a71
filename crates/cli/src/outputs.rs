//! Output files of a command: never an input, never named twice, and
//! written together — each to a temporary sibling first, all renamed into
//! place only once every one is complete, so a failure leaves every
//! previous file as it was.

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

/// Refuses outputs that would overwrite an input or each other (exit 2).
pub(crate) fn check_outputs(inputs: &[&Path], outputs: &[&Path]) -> Result<(), Failure> {
    let ins: Vec<PathBuf> = inputs.iter().map(|p| resolved(p)).collect();
    let mut seen: Vec<(PathBuf, &Path)> = Vec::new();
    for out in outputs {
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
/// [`commit`](Self::commit)); dropped without a commit, the temporaries
/// are removed and the targets untouched.
#[derive(Default)]
pub(crate) struct Staged {
    files: Vec<(PathBuf, PathBuf)>,
}

impl Staged {
    /// Writes `path`'s content to a temporary sibling through `write`
    /// (given the temporary's path).
    pub(crate) fn stage(
        &mut self,
        path: &Path,
        write: impl FnOnce(&Path) -> anyhow::Result<()>,
    ) -> Result<(), Failure> {
        let tmp = mesh_io::atomic::temporary_path(path);
        // Registered first, so that a partial temporary is removed too.
        self.files.push((tmp.clone(), path.to_path_buf()));
        write(&tmp)
            .with_context(|| format!("writing {}", path.display()))
            .map_err(runtime)
    }

    /// Renames every staged file into place.
    pub(crate) fn commit(mut self) -> Result<(), Failure> {
        for (tmp, path) in std::mem::take(&mut self.files) {
            std::fs::rename(&tmp, &path)
                .with_context(|| format!("writing {}", path.display()))
                .map_err(runtime)?;
        }
        Ok(())
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        for (tmp, _) in &self.files {
            let _ = std::fs::remove_file(tmp);
        }
    }
}

/// The outputs of `match` and `refine`, written together: the point map
/// (`.map`, 1-based) and C as text (one row per line, 17 significant
/// digits).
pub(crate) fn write_map_outputs(
    out: Option<&Path>,
    save_fmap: Option<&Path>,
    t_ab: &[usize],
    c: &nalgebra::DMatrix<f64>,
) -> Result<(), Failure> {
    let mut staged = Staged::default();
    if let Some(out) = out {
        staged.stage(out, |tmp| Ok(mesh_io::write_map(tmp, t_ab)?))?;
    }
    if let Some(path) = save_fmap {
        let mut text = String::new();
        for row in c.row_iter() {
            let cells: Vec<String> = row.iter().map(|v| format!("{v:.17e}")).collect();
            outln!(text, "{}", cells.join(" "));
        }
        staged.stage(path, |tmp| Ok(std::fs::write(tmp, text)?))?;
    }
    staged.commit()
}
