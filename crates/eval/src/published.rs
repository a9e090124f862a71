//! The published maps of the benchmark (`maps/METHOD.zip`, entries
//! `METHOD/A_B.map`), read from the zip archive as the dataset ships it.
//! Behind the feature `published-maps` (the `zip` dependency).

use std::collections::HashMap;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::{Error, Result};

/// The `A_B.map` files inside one published method's zip archive.
#[derive(Debug)]
pub struct PublishedMaps {
    path: PathBuf,
    archive: Mutex<zip::ZipArchive<File>>,
    /// `A_B` -> entry index.
    index: HashMap<String, usize>,
}

impl PublishedMaps {
    /// Opens an archive and indexes its `.map` entries by `A_B`.
    pub fn open(path: &Path) -> Result<Self> {
        let zerr = |e: &dyn std::fmt::Display| Error::Zip {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        let file = File::open(path).map_err(|e| zerr(&e))?;
        let mut archive = zip::ZipArchive::new(file).map_err(|e| zerr(&e))?;
        let mut index = HashMap::new();
        for i in 0..archive.len() {
            let entry = archive.by_index(i).map_err(|e| zerr(&e))?;
            let name = entry.name().map_err(|e| zerr(&e))?;
            if let Some(stem) = name.rsplit('/').next().and_then(|f| f.strip_suffix(".map")) {
                index.insert(stem.to_string(), i);
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            archive: Mutex::new(archive),
            index,
        })
    }

    /// Number of maps in the archive.
    pub fn len(&self) -> usize {
        self.index.len()
    }

    /// True when the archive holds no map.
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// The map A → B (0-based, one target per vertex of A), or `None`
    /// when the archive has no `A_B.map`.
    pub fn read(&self, a: &str, b: &str) -> Result<Option<Vec<usize>>> {
        let Some(&i) = self.index.get(&format!("{a}_{b}")) else {
            return Ok(None);
        };
        let mut archive = self.archive.lock().unwrap_or_else(|e| e.into_inner());
        let mut entry = archive.by_index(i).map_err(|e| Error::Zip {
            path: self.path.clone(),
            message: e.to_string(),
        })?;
        let mut bytes = Vec::with_capacity(entry.size() as usize);
        entry.read_to_end(&mut bytes).map_err(|e| Error::Zip {
            path: self.path.clone(),
            message: e.to_string(),
        })?;
        let name = format!("{}!{a}_{b}.map", self.path.display());
        fmaps_mesh_io::parse_index_list(&bytes, ".map")
            .map(Some)
            .map_err(|e| Error::Dataset(format!("{name}: {e}")))
    }
}
