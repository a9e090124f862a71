//! A trained feature extractor and its file.
//!
//! A [`Model`] is a [`DiffusionNet`] with what it takes to apply it to a
//! new mesh: its input (the WKS of the first eigenpairs, normalised) and
//! its operators (the cotangent Laplacian with lumped masses of the mesh
//! scaled to unit area, k eigenpairs, the gradients' regularisation).
//! [`Model::features`] computes the per-vertex features of a mesh.
//!
//! # The model file (`fmaps-model`, version 1)
//!
//! An uncompressed NumPy `.npz` archive, readable with `numpy.load`:
//!
//! - `meta.npy`: a `uint8` array, the UTF-8 text of a JSON object
//!   ([`ModelMeta`]): `format` (`"fmaps-model"`), `version` (1), the
//!   architecture, the input and operator parameters and the training
//!   provenance (free text, key by key);
//! - one `float64` array per parameter (stored in Fortran order, which
//!   the header says), named and shaped as the reference
//!   PyTorch implementation's `state_dict` names them
//!   (`first_lin.weight` is C x C_in, `block_0.diffusion.diffusion_time`
//!   has C values, ...), so that
//!   `net.load_state_dict({k: torch.tensor(v) for k, v in z.items() if k != "meta"})`
//!   loads them into it.
//!
//! A file of another format or version, a missing or misshapen tensor or
//! a non-finite value is refused with an error naming the file.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;
#[cfg(feature = "shipped-model")]
use std::path::PathBuf;

use fmaps_descriptors::{WksParams, normalize_columns, wks};
use fmaps_mesh_io::{TriMesh, npy, npz};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::network::DiffusionNet;
use crate::operators::GRAD_REGULARIZATION;
use crate::{Error, Result, ShapeOperators};

/// The model file's format name.
pub const FORMAT: &str = "fmaps-model";
/// The model file's version this crate reads and writes.
pub const VERSION: u32 = 1;
/// The largest model file read (bytes): far above any DiffusionNet.
const MAX_FILE: u64 = 1 << 30;

/// The network's shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Architecture {
    /// Input channels (the WKS energies).
    pub inputs: usize,
    /// Width of the blocks.
    pub width: usize,
    /// Number of blocks.
    pub blocks: usize,
    /// Output channels.
    pub outputs: usize,
}

impl Default for Architecture {
    /// The reference's for matching (ULRSSM): 128 inputs, width 128, 4
    /// blocks, 256 outputs.
    fn default() -> Self {
        Architecture {
            inputs: 128,
            width: 128,
            blocks: 4,
            outputs: 256,
        }
    }
}

/// The network's input features.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Input {
    /// The WKS of the first eigenpairs with the automatic energies (as
    /// many as the network's inputs), each column M-normalised: intrinsic,
    /// the same in any pose, orientation and scale.
    #[default]
    Wks,
    /// The vertex coordinates of the mesh scaled to unit area, its
    /// area-weighted centroid at the origin (3 inputs); training augments
    /// them by random rotations and scales ([`crate::train::Augment`]).
    Xyz,
}

/// How a mesh becomes the network's input and operators.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Preprocessing {
    /// The input features (WKS when the file does not say).
    #[serde(default)]
    pub input: Input,
    /// Eigenpairs of the spectral diffusion (and of the WKS input).
    pub eigenpairs: usize,
    /// The gradient operators' ridge regularisation (recorded in the
    /// file; this crate computes the operators with
    /// [`GRAD_REGULARIZATION`] and refuses a model made with another).
    pub gradient_regularization: f64,
}

impl Default for Preprocessing {
    /// DiffusionNet's: 128 eigenpairs, regularisation 1e-5.
    fn default() -> Self {
        Preprocessing {
            input: Input::Wks,
            eigenpairs: 128,
            gradient_regularization: GRAD_REGULARIZATION,
        }
    }
}

/// The model file's `meta` entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelMeta {
    /// [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// The network's shape.
    pub architecture: Architecture,
    /// Input and operators' parameters.
    pub preprocessing: Preprocessing,
    /// How the model was made (command, recipe, data, commit, steps, wall
    /// time, CPU, final losses): free text by key.
    pub provenance: BTreeMap<String, String>,
}

/// A trained feature extractor (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    /// The network.
    pub net: DiffusionNet,
    /// How meshes are prepared for it.
    pub preprocessing: Preprocessing,
    /// How it was made.
    pub provenance: BTreeMap<String, String>,
}

/// A mesh prepared for a model: its operators and its input features.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The operators of the mesh scaled to unit area.
    pub operators: ShapeOperators,
    /// The input features (n x inputs).
    pub input: DMatrix<f64>,
}

/// The shipped model's file name, as errors name it.
#[cfg(feature = "shipped-model")]
pub const SHIPPED_NAME: &str = "fmaps-learn/models/faust-unsupervised.npz";

#[cfg(feature = "shipped-model")]
static SHIPPED: &[u8] = include_bytes!("../models/faust-unsupervised.npz");

impl Model {
    /// An untrained model of `architecture`, initialised from `seed`.
    pub fn new(architecture: Architecture, preprocessing: Preprocessing, seed: u64) -> Model {
        let a = architecture;
        Model {
            net: DiffusionNet::new(a.inputs, a.width, a.blocks, a.outputs, seed),
            preprocessing,
            provenance: BTreeMap::new(),
        }
    }

    /// The network's shape.
    pub fn architecture(&self) -> Architecture {
        Architecture {
            inputs: self.net.inputs(),
            width: self.net.width(),
            blocks: self.net.blocks.len(),
            outputs: self.net.outputs(),
        }
    }

    /// The operators (with `eigenpairs` eigenpairs, at least the model's)
    /// and the input of `mesh`.
    pub fn prepare(&self, mesh: &TriMesh, eigenpairs: usize) -> Result<Prepared> {
        self.check_preprocessing()?;
        let (unit, _) = mesh.to_unit_area()?;
        let k = eigenpairs.max(self.preprocessing.eigenpairs);
        let operators = ShapeOperators::compute(&unit, k)?;
        let input = self.input(&unit, &operators)?;
        Ok(Prepared { operators, input })
    }

    /// [`prepare`](Self::prepare) with the operators cached in the folder
    /// `cache` (one file per mesh and eigenpair count, named by a hash of
    /// the mesh; see [`ShapeOperators::cached`]).
    pub fn prepare_cached(
        &self,
        mesh: &TriMesh,
        eigenpairs: usize,
        cache: &Path,
    ) -> Result<Prepared> {
        self.check_preprocessing()?;
        let (unit, _) = mesh.to_unit_area()?;
        let k = eigenpairs.max(self.preprocessing.eigenpairs);
        let key = ShapeOperators::key(&unit, k);
        let hash = key.rsplit("hash=").next().unwrap_or("mesh").to_string();
        std::fs::create_dir_all(cache).map_err(|e| Error::Write {
            path: cache.to_path_buf(),
            source: e,
        })?;
        let file = cache.join(format!("operators-{}-k{k}-{hash}.npz", unit.n_vertices()));
        let (operators, _) = ShapeOperators::cached(&unit, k, &file)?;
        let input = self.input(&unit, &operators)?;
        Ok(Prepared { operators, input })
    }

    fn check_preprocessing(&self) -> Result<()> {
        let r = self.preprocessing.gradient_regularization;
        if r != GRAD_REGULARIZATION {
            return Err(Error::Parameter(format!(
                "gradient regularisation {r}: this fmaps computes the operators with {GRAD_REGULARIZATION}"
            )));
        }
        Ok(())
    }

    /// The input features ([`Input`]) of a mesh scaled to unit area,
    /// from its operators.
    pub fn input(&self, unit: &TriMesh, ops: &ShapeOperators) -> Result<DMatrix<f64>> {
        if self.preprocessing.input == Input::Xyz {
            if self.net.inputs() != 3 {
                return Err(Error::Parameter(format!(
                    "{} inputs for vertex coordinates",
                    self.net.inputs()
                )));
            }
            let v = unit.vertices();
            let total = ops.mass.sum();
            let centre: [f64; 3] = std::array::from_fn(|c| {
                v.iter()
                    .zip(ops.mass.iter())
                    .map(|(p, m)| p[c] * m)
                    .sum::<f64>()
                    / total
            });
            return Ok(DMatrix::from_fn(v.len(), 3, |i, c| v[i][c] - centre[c]));
        }
        let k = self.preprocessing.eigenpairs;
        if ops.eigenvalues.len() < k {
            return Err(Error::Parameter(format!(
                "operators with {} eigenpairs for a model of {k}",
                ops.eigenvalues.len()
            )));
        }
        let evals = ops.eigenvalues.rows(0, k).into_owned();
        let evecs = ops.eigenvectors.columns(0, k).into_owned();
        let mut params = WksParams::default();
        params.n_energies = self.net.inputs();
        let mut x = wks(&evals, &evecs, &params)?;
        normalize_columns(&mut x, &ops.mass);
        Ok(x)
    }

    /// The per-vertex features of `mesh` (n x outputs).
    ///
    /// ```
    /// use fmaps_learn::model::{Architecture, Model, Preprocessing};
    ///
    /// let arch = Architecture { inputs: 8, width: 8, blocks: 1, outputs: 4 };
    /// let pre = Preprocessing { eigenpairs: 12, ..Preprocessing::default() };
    /// let model = Model::new(arch, pre, 1);
    /// let mesh = fmaps_shapes::icosphere(1.0, 2);
    /// let f = model.features(&mesh)?;
    /// assert_eq!(f.shape(), (mesh.n_vertices(), 4));
    /// # Ok::<(), fmaps_learn::Error>(())
    /// ```
    pub fn features(&self, mesh: &TriMesh) -> Result<DMatrix<f64>> {
        let p = self.prepare(mesh, self.preprocessing.eigenpairs)?;
        Ok(self.features_of(&p.operators, &p.input))
    }

    /// The features of a prepared shape (no dropout).
    pub fn features_of(&self, ops: &ShapeOperators, input: &DMatrix<f64>) -> DMatrix<f64> {
        let net = NetBasis::new(ops, self.preprocessing.eigenpairs);
        self.net.forward(net.input(ops), input, None)
    }

    /// The `meta` entry of this model's file.
    pub fn meta(&self) -> ModelMeta {
        ModelMeta {
            format: FORMAT.into(),
            version: VERSION,
            architecture: self.architecture(),
            preprocessing: self.preprocessing,
            provenance: self.provenance.clone(),
        }
    }

    /// The archive's entries: `meta` and the parameters (row-major, in
    /// the reference's shapes), then `extra` entries.
    pub(crate) fn entries(&self, extra: Vec<(String, Vec<u8>)>) -> Result<Vec<(String, Vec<u8>)>> {
        let meta = serde_json::to_string_pretty(&self.meta())
            .map_err(|e| Error::Parameter(format!("model metadata: {e}")))?;
        let mut out = Vec::new();
        let mut buf = Vec::new();
        npy::write_u8(&mut buf, meta.as_bytes()).map_err(io)?;
        out.push(("meta.npy".to_string(), buf));
        for p in self.net.params() {
            out.push((format!("{}.npy", p.name), tensor_npy(&p.shape, p.values)?));
        }
        out.extend(extra);
        Ok(out)
    }

    /// Writes the model file `path` (atomically; a device or pipe is
    /// written through).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        write_entries(path.as_ref(), &self.entries(Vec::new())?)
    }

    /// Reads a model file.
    ///
    /// Errors: not a model archive, another format or version, a missing,
    /// misshapen or non-finite tensor (each naming the file).
    pub fn load(path: impl AsRef<Path>) -> Result<Model> {
        let path = path.as_ref();
        let data = fmaps_mesh_io::read_bounded(path, MAX_FILE)?;
        Model::parse(&data).map_err(|m| Error::ModelFile {
            path: path.to_path_buf(),
            problem: m,
        })
    }

    /// The model shipped with this crate (`models/faust-unsupervised.npz`,
    /// provenance in `models/README.md`): DiffusionNet trained without
    /// labels on the 80 training shapes of the remeshed FAUST by
    /// `cargo xtask train`. Its [`provenance`](Self::provenance) says how.
    ///
    /// Errors: none for the file this crate ships (a test reads it); the
    /// file's own checks otherwise.
    ///
    /// ```
    /// let model = fmaps_learn::model::Model::shipped()?;
    /// assert_eq!(model.architecture().outputs, 256);
    /// # Ok::<(), fmaps_learn::Error>(())
    /// ```
    #[cfg(feature = "shipped-model")]
    pub fn shipped() -> Result<Model> {
        Model::parse(SHIPPED).map_err(|m| Error::ModelFile {
            path: PathBuf::from(SHIPPED_NAME),
            problem: m,
        })
    }

    /// A model from the bytes of a model file.
    pub(crate) fn parse(data: &[u8]) -> std::result::Result<Model, String> {
        let entries = npz::read_archive(data).map_err(|(at, m)| format!("byte {at}: {m}"))?;
        let meta_bytes = entry(&entries, "meta")?;
        let meta_text = npy::parse_u8(meta_bytes).map_err(|(_, m)| format!("`meta`: {m}"))?;
        let meta: ModelMeta = serde_json::from_slice(&meta_text)
            .map_err(|e| format!("`meta` is not a model's metadata: {e}"))?;
        if meta.format != FORMAT {
            return Err(format!("format `{}`, expected `{FORMAT}`", meta.format));
        }
        if meta.version != VERSION {
            return Err(format!(
                "version {} of the model format; this fmaps reads version {VERSION}",
                meta.version
            ));
        }
        let a = meta.architecture;
        let p = meta.preprocessing;
        if a.inputs == 0 || a.width == 0 || a.outputs == 0 || a.inputs > 4096 || a.width > 4096 {
            return Err(format!("architecture {a:?} out of range"));
        }
        if a.blocks > 64 || a.outputs > 4096 || p.eigenpairs == 0 || p.eigenpairs > 4096 {
            return Err(format!("architecture {a:?} / {p:?} out of range"));
        }
        if p.gradient_regularization != GRAD_REGULARIZATION {
            return Err(format!(
                "gradient operators regularised by {}; this fmaps computes them with {GRAD_REGULARIZATION}",
                p.gradient_regularization
            ));
        }
        if p.input == Input::Xyz && a.inputs != 3 {
            return Err(format!("{} inputs for vertex coordinates", a.inputs));
        }
        let mut model = Model::new(a, p, 0);
        model.provenance = meta.provenance;
        let shapes: Vec<(String, Vec<usize>)> = model
            .net
            .params()
            .into_iter()
            .map(|p| (p.name, p.shape))
            .collect();
        for ((name, shape), values) in shapes.into_iter().zip(model.net.params_mut()) {
            let arr = npy::parse_f64(entry(&entries, &name)?)
                .map_err(|(_, m)| format!("`{name}`: {m}"))?;
            if arr.shape != shape {
                return Err(format!(
                    "`{name}` has shape {:?}, expected {shape:?}",
                    arr.shape
                ));
            }
            if let Some(i) = arr.data.iter().position(|v| !v.is_finite()) {
                return Err(format!("`{name}` value {i} is not finite"));
            }
            values.copy_from_slice(&arr.data);
        }
        Ok(model)
    }
}

/// The eigenpairs of the network's diffusion (the first k of a shape's).
pub(crate) struct NetBasis {
    evals: DVector<f64>,
    evecs: DMatrix<f64>,
}

impl NetBasis {
    pub(crate) fn new(ops: &ShapeOperators, k: usize) -> NetBasis {
        let k = k.min(ops.eigenvalues.len());
        NetBasis {
            evals: ops.eigenvalues.rows(0, k).into_owned(),
            evecs: ops.eigenvectors.columns(0, k).into_owned(),
        }
    }

    pub(crate) fn input<'a>(&'a self, ops: &'a ShapeOperators) -> crate::network::ShapeInput<'a> {
        crate::network::ShapeInput {
            spectrum: crate::layers::Spectrum {
                eigenvalues: &self.evals,
                eigenvectors: &self.evecs,
                mass: &ops.mass,
            },
            gradients: crate::layers::Gradients {
                x: &ops.grad_x,
                y: &ops.grad_y,
            },
        }
    }
}

fn io(e: std::io::Error) -> Error {
    Error::Write {
        path: "(memory)".into(),
        source: e,
    }
}

/// The `name.npy` entry of an archive.
pub(crate) fn entry<'a>(
    entries: &[npz::Entry<'a>],
    name: &str,
) -> std::result::Result<&'a [u8], String> {
    entries
        .iter()
        .find(|e| e.name == format!("{name}.npy"))
        .map(|e| e.data)
        .ok_or_else(|| format!("no `{name}` entry"))
}

/// A tensor of `shape` (column-major `values`) as an `.npy` (which says
/// its order: NumPy reads the right array).
pub(crate) fn tensor_npy(shape: &[usize], values: &[f64]) -> Result<Vec<u8>> {
    let mut buf = Vec::new();
    npy::write_f64(&mut buf, shape, values).map_err(io)?;
    Ok(buf)
}

/// The archive of named `entries` written to `w`.
pub(crate) fn archive_to(w: &mut dyn Write, entries: &[(String, Vec<u8>)]) -> std::io::Result<()> {
    let refs: Vec<(&str, &[u8])> = entries
        .iter()
        .map(|(n, d)| (n.as_str(), d.as_slice()))
        .collect();
    npz::write_archive(w, &refs)
}

/// Writes an archive of `entries` to `path` by the output policy of
/// [`fmaps_mesh_io::atomic`].
pub(crate) fn write_entries(path: &Path, entries: &[(String, Vec<u8>)]) -> Result<()> {
    fmaps_mesh_io::atomic::write_atomically(path, |w: &mut dyn Write| archive_to(w, entries))
        .map_err(|e| Error::Write {
            path: path.to_path_buf(),
            source: e,
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> Model {
        let arch = Architecture {
            inputs: 6,
            width: 5,
            blocks: 2,
            outputs: 3,
        };
        let pre = Preprocessing {
            eigenpairs: 10,
            ..Preprocessing::default()
        };
        Model::new(arch, pre, 7)
    }

    /// A model survives its file exactly; a weight has the reference's
    /// shape (out x in).
    #[test]
    fn file_round_trip() {
        let mut m = small();
        m.provenance.insert("command".into(), "fmaps train".into());
        let mut bytes = Vec::new();
        archive_to(&mut bytes, &m.entries(Vec::new()).unwrap()).unwrap();
        let back = Model::parse(&bytes).unwrap();
        assert_eq!(back, m);
        let entries = npz::read_archive(&bytes).unwrap();
        let w = npy::parse_f64(entry(&entries, "first_lin.weight").unwrap()).unwrap();
        assert_eq!(w.shape, vec![5, 6]);
        // Column-major, as the header says: element (1, 0), then (0, 1).
        assert_eq!(w.data[1], m.net.first.weight[(1, 0)]);
        assert_eq!(w.data[5], m.net.first.weight[(0, 1)]);
    }

    /// Another version, a missing tensor, a wrong shape, a NaN: refused
    /// with what is wrong.
    #[test]
    fn bad_files() {
        let m = small();
        type Entries = Vec<(String, Vec<u8>)>;
        let archive = |edit: &dyn Fn(&mut Entries)| {
            let mut entries = m.entries(Vec::new()).unwrap();
            edit(&mut entries);
            let mut out = Vec::new();
            archive_to(&mut out, &entries).unwrap();
            Model::parse(&out).unwrap_err()
        };
        let meta_with = |text: String| {
            let mut buf = Vec::new();
            npy::write_u8(&mut buf, text.as_bytes()).unwrap();
            buf
        };
        let json = serde_json::to_string(&m.meta()).unwrap();
        let e = archive(&|e| e[0].1 = meta_with(json.replace("\"version\":1", "\"version\":2")));
        assert!(e.contains("version 2"), "{e}");
        let e = archive(&|e| e[0].1 = meta_with(json.replace("fmaps-model", "other")));
        assert!(e.contains("format `other`"), "{e}");
        let e = archive(&|e| e.retain(|(n, _)| n != "last_lin.bias.npy"));
        assert!(e.contains("no `last_lin.bias` entry"), "{e}");
        let e = archive(&|e| {
            let i = e
                .iter()
                .position(|(n, _)| n == "last_lin.bias.npy")
                .unwrap();
            e[i].1 = tensor_npy(&[2], &[0.0, 1.0]).unwrap();
        });
        assert!(
            e.contains("`last_lin.bias` has shape [2], expected [3]"),
            "{e}"
        );
        let e = archive(&|e| {
            let i = e
                .iter()
                .position(|(n, _)| n == "last_lin.bias.npy")
                .unwrap();
            e[i].1 = tensor_npy(&[3], &[0.0, f64::NAN, 1.0]).unwrap();
        });
        assert!(e.contains("`last_lin.bias` value 1 is not finite"), "{e}");
    }
}
