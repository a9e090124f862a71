//! `--descr-source` / `--descr-target`: a user's own per-vertex
//! descriptors for `fmaps match`, in place of the spectral ones.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::{Failure, input};

/// The descriptors of A and B, as the pipeline takes them.
type Given = Arc<(nalgebra::DMatrix<f64>, nalgebra::DMatrix<f64>)>;

/// The flags.
#[derive(clap::Args, Debug, Clone, Default)]
pub(crate) struct DescriptorFiles {
    /// Your own descriptors of A instead of the spectral ones: one row per
    /// vertex, one column per descriptor (.npy/.npz of any real dtype, or
    /// text: one row per line). Needs --descr-target with the same columns.
    #[arg(long, value_name = "FILE", requires = "descr_target")]
    pub(crate) descr_source: Option<PathBuf>,
    /// Your own descriptors of B (see --descr-source).
    #[arg(long, value_name = "FILE", requires = "descr_source")]
    pub(crate) descr_target: Option<PathBuf>,
}

impl DescriptorFiles {
    /// The two matrices, checked against meshes of `sizes` vertices, or
    /// `None` without the flags.
    pub(crate) fn load(&self, sizes: (usize, usize)) -> Result<Option<Given>, Failure> {
        let (Some(a), Some(b)) = (&self.descr_source, &self.descr_target) else {
            return Ok(None);
        };
        let da = one(a, sizes.0)?;
        let db = one(b, sizes.1)?;
        if da.ncols() != db.ncols() {
            return Err(input(anyhow::anyhow!(
                "{} has {} columns, {} has {}: the descriptors of A and B must correspond column by column",
                a.display(),
                da.ncols(),
                b.display(),
                db.ncols()
            )));
        }
        Ok(Some(Arc::new((da, db))))
    }

    /// The files, as inputs of the command.
    pub(crate) fn paths(&self) -> impl Iterator<Item = &Path> {
        self.descr_source
            .iter()
            .chain(&self.descr_target)
            .map(PathBuf::as_path)
    }
}

/// One descriptor file, `n` rows.
fn one(path: &Path, n: usize) -> Result<nalgebra::DMatrix<f64>, Failure> {
    let m = crate::value_files::read_matrix(path)?;
    if m.nrows() != n {
        return Err(input(anyhow::anyhow!(
            "{}: {} rows, but the mesh has {n} vertices (one row per vertex)",
            path.display(),
            m.nrows()
        )));
    }
    Ok(m)
}
