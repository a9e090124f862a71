//! The layout of the remeshed FAUST/TOSCA benchmark (`bcicp/`):
//! `COLLECTION/test_pairs.txt`, `COLLECTION/vtx_5k/NAME.off`,
//! `COLLECTION/vtx_5k/corres/NAME.vts` and `NAME.sym.vts`, and published
//! maps in `COLLECTION/vtx_5k/maps/METHOD.zip` (entries `METHOD/A_B.map`).

use std::path::{Path, PathBuf};

use fmaps_mesh_io::TriMesh;

use crate::{Error, GroundTruth, Result};

/// One collection of the benchmark (e.g. `FAUST`, `TOSCA_Isometric`).
#[derive(Debug, Clone)]
pub struct Collection {
    name: String,
    dir: PathBuf,
}

impl Collection {
    /// Opens `root/name` (root is the `bcicp` directory).
    pub fn open(root: &Path, name: &str) -> Result<Self> {
        let dir = root.join(name);
        if !dir.join("vtx_5k").is_dir() {
            return Err(Error::Dataset(format!(
                "{}: not a collection directory (no vtx_5k/ inside)",
                dir.display()
            )));
        }
        Ok(Self {
            name: name.to_string(),
            dir,
        })
    }

    /// The collection's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The pairs of `test_pairs.txt` (tab or space separated; blank lines
    /// skipped).
    pub fn test_pairs(&self) -> Result<Vec<(String, String)>> {
        let path = self.dir.join("test_pairs.txt");
        let text = std::fs::read_to_string(&path)
            .map_err(|e| Error::Dataset(format!("{}: {e}", path.display())))?;
        let mut pairs = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let mut t = line.split_whitespace();
            match (t.next(), t.next(), t.next()) {
                (None, _, _) => {}
                (Some(a), Some(b), None) => pairs.push((a.to_string(), b.to_string())),
                _ => {
                    return Err(Error::Dataset(format!(
                        "{} line {}: expected 'SOURCE<TAB>TARGET', found '{line}'",
                        path.display(),
                        i + 1
                    )));
                }
            }
        }
        Ok(pairs)
    }

    /// Path of a shape's mesh.
    pub fn mesh_path(&self, shape: &str) -> PathBuf {
        self.dir.join("vtx_5k").join(format!("{shape}.off"))
    }

    /// Reads a shape's mesh.
    pub fn read_mesh(&self, shape: &str) -> Result<TriMesh> {
        Ok(fmaps_mesh_io::read_mesh(self.mesh_path(shape))?)
    }

    /// Path of a shape's ground-truth `.vts` (or `.sym.vts`).
    pub fn vts_path(&self, shape: &str, sym: bool) -> PathBuf {
        let ext = if sym { "sym.vts" } else { "vts" };
        self.dir
            .join("vtx_5k/corres")
            .join(format!("{shape}.{ext}"))
    }

    /// The ground truth of pair (a, b): A's `.vts`, B's `.vts` and, when
    /// present, B's `.sym.vts`, checked against the vertex counts.
    pub fn ground_truth(&self, a: &str, b: &str, n_a: usize, n_b: usize) -> Result<GroundTruth> {
        let read = |shape: &str, sym: bool, n: usize| -> Result<Vec<usize>> {
            let p = self.vts_path(shape, sym);
            let v = fmaps_mesh_io::read_vts(&p)?;
            fmaps_mesh_io::check_indices(&v, n, Some(&p))?;
            Ok(v)
        };
        let sym = if self.vts_path(b, true).exists() {
            Some(read(b, true, n_b)?)
        } else {
            None
        };
        GroundTruth::new(read(a, false, n_a)?, read(b, false, n_b)?, sym)
    }

    /// Names of the published methods (`maps/*.zip`), sorted.
    pub fn published_methods(&self) -> Result<Vec<String>> {
        let dir = self.dir.join("vtx_5k/maps");
        let Ok(entries) = std::fs::read_dir(&dir) else {
            return Ok(Vec::new());
        };
        let mut out: Vec<String> = entries
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let p = e.path();
                (p.extension().and_then(|x| x.to_str()) == Some("zip"))
                    .then(|| p.file_stem().map(|s| s.to_string_lossy().into_owned()))
                    .flatten()
            })
            .collect();
        out.sort();
        Ok(out)
    }

    /// Opens the archive of a published method (feature `published-maps`).
    #[cfg(feature = "published-maps")]
    pub fn published_maps(&self, method: &str) -> Result<crate::PublishedMaps> {
        crate::PublishedMaps::open(&self.dir.join("vtx_5k/maps").join(format!("{method}.zip")))
    }
}
