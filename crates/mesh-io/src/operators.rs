//! Cache files of a shape's learned-feature operators (`fmaps-learn`'s
//! DiffusionNet operators): mass, eigenbasis, tangent frames and the two
//! sparse gradient operators, with the key they were computed under, so a
//! training run computes each shape's operators once.
//!
//! A file is a NumPy `.npz` archive ([`crate::npz`]), readable with NumPy
//! and SciPy alone:
//!
//! ```python
//! z = np.load("shape.npz")
//! phi, evals, mass = z["eigenvectors"], z["eigenvalues"], z["mass"]   # n x k, (k,), (n,)
//! frames = z["frames"]                                                # n x 3 x 3: rows X, Y, normal
//! gx = scipy.sparse.csr_matrix((z["grad_x_data"], z["grad_x_indices"], z["grad_x_indptr"]), shape=(n, n))
//! ```
//!
//! Entries: `format` (the bytes `fmaps-operators-1`), `key` (UTF-8, at
//! most [`MAX_KEY`] bytes), `mass` (n), `eigenvalues`
//! (k), `eigenvectors` (n x k), `frames` (n x 3 x 3) and, for `grad_x` and
//! `grad_y`, the CSR arrays `_indptr` (n + 1, int64), `_indices` (int64)
//! and `_data` (float64). A file is accepted only if every entry is
//! present with its CRC-32, the shapes fit, every value is finite and the
//! sparse structure is valid (indptr from 0 to nnz, non-decreasing,
//! indices in range): anything else is an error (the caller recomputes).

use std::io::Write;
use std::path::Path;

use crate::basis::MAX_KEY;
use crate::{Error, Result, npy, npz};

/// The `format` entry of the files this version writes and reads.
const FORMAT: &[u8] = b"fmaps-operators-1";

/// Largest operators file read (4 GiB).
pub const MAX_OPERATORS_BYTES: u64 = 1 << 32;

/// An n x n sparse matrix in compressed rows.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SparseRows {
    /// Where each row starts in `indices` and `data` (n + 1 entries, from
    /// 0 to nnz).
    pub indptr: Vec<usize>,
    /// Column of each stored value.
    pub indices: Vec<usize>,
    /// The stored values.
    pub data: Vec<f64>,
}

/// One shape's operators as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct OperatorsFile {
    /// What they were computed from (checked by the caller).
    pub key: String,
    /// Mass diagonal (n).
    pub mass: Vec<f64>,
    /// Eigenvalues (k).
    pub eigenvalues: Vec<f64>,
    /// Eigenvectors, column-major n x k.
    pub eigenvectors: Vec<f64>,
    /// Per vertex, its frame's rows X, Y and normal (9 values per vertex).
    pub frames: Vec<[f64; 9]>,
    /// X components of the gradient.
    pub grad_x: SparseRows,
    /// Y components of the gradient.
    pub grad_y: SparseRows,
}

impl OperatorsFile {
    /// Vertices.
    pub fn n(&self) -> usize {
        self.mass.len()
    }

    /// Eigenpairs.
    pub fn k(&self) -> usize {
        self.eigenvalues.len()
    }

    /// What is inconsistent in it, if anything.
    fn problem(&self) -> Option<String> {
        let (n, k) = (self.n(), self.k());
        if self.key.len() > MAX_KEY {
            return Some(format!(
                "key of {} bytes (at most {MAX_KEY})",
                self.key.len()
            ));
        }
        if self.eigenvectors.len() != n * k || self.frames.len() != n {
            return Some(format!(
                "{} eigenvector entries and {} frames for n = {n}, k = {k}",
                self.eigenvectors.len(),
                self.frames.len()
            ));
        }
        let values = [
            ("mass", &self.mass),
            ("eigenvalues", &self.eigenvalues),
            ("eigenvectors", &self.eigenvectors),
            ("grad_x_data", &self.grad_x.data),
            ("grad_y_data", &self.grad_y.data),
        ];
        for (name, a) in values {
            if let Some((i, v)) = a.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Some(format!("{name}[{i}] = {v} is not finite"));
            }
        }
        if let Some(i) = self
            .frames
            .iter()
            .position(|f| f.iter().any(|v| !v.is_finite()))
        {
            return Some(format!("frame {i} is not finite"));
        }
        for (name, m) in [("grad_x", &self.grad_x), ("grad_y", &self.grad_y)] {
            let p = &m.indptr;
            let nnz = m.indices.len();
            if p.len() != n + 1
                || p[0] != 0
                || p[n] != nnz
                || m.data.len() != nnz
                || p.windows(2).any(|w| w[0] > w[1])
            {
                return Some(format!(
                    "{name}: not a compressed-row matrix of {n} rows ({} row pointers, {nnz} indices, {} values)",
                    p.len(),
                    m.data.len()
                ));
            }
            if let Some((i, c)) = m.indices.iter().enumerate().find(|(_, c)| **c >= n) {
                return Some(format!("{name}: index {i} is column {c}, beyond {n}"));
            }
        }
        None
    }
}

/// Writes `f` as an `.npz` archive to `w`.
///
/// Errors: an inconsistent `f` (sizes, non-finite values, an invalid
/// sparse structure) as `InvalidInput`, and the writer's.
pub fn write_operators_to(w: &mut dyn Write, f: &OperatorsFile) -> std::io::Result<()> {
    if let Some(p) = f.problem() {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, p));
    }
    let (n, k) = (f.n(), f.k());
    let mut entries: Vec<(String, Vec<u8>)> = Vec::new();
    let mut add = |name: &str, bytes: Vec<u8>| entries.push((format!("{name}.npy"), bytes));
    let f64s = |shape: &[usize], data: &[f64]| -> std::io::Result<Vec<u8>> {
        let mut b = Vec::new();
        npy::write_f64(&mut b, shape, data)?;
        Ok(b)
    };
    let i64s = |data: &[usize]| -> std::io::Result<Vec<u8>> {
        let mut b = Vec::new();
        let v: Vec<i64> = data.iter().map(|&x| x as i64).collect();
        npy::write_i64(&mut b, &[v.len()], &v)?;
        Ok(b)
    };
    let mut format = Vec::new();
    npy::write_u8(&mut format, FORMAT)?;
    add("format", format);
    let mut key = Vec::new();
    npy::write_u8(&mut key, f.key.as_bytes())?;
    add("key", key);
    add("mass", f64s(&[n], &f.mass)?);
    add("eigenvalues", f64s(&[k], &f.eigenvalues)?);
    add("eigenvectors", f64s(&[n, k], &f.eigenvectors)?);
    // n x 3 x 3 in column-major order: entry (v, r, c) at v + n (r + 3 c).
    let mut frames = vec![0.0; 9 * n];
    for (v, fr) in f.frames.iter().enumerate() {
        for r in 0..3 {
            for c in 0..3 {
                frames[v + n * (r + 3 * c)] = fr[3 * r + c];
            }
        }
    }
    add("frames", f64s(&[n, 3, 3], &frames)?);
    for (name, m) in [("grad_x", &f.grad_x), ("grad_y", &f.grad_y)] {
        add(&format!("{name}_indptr"), i64s(&m.indptr)?);
        add(&format!("{name}_indices"), i64s(&m.indices)?);
        add(&format!("{name}_data"), f64s(&[m.data.len()], &m.data)?);
    }
    let refs: Vec<(&str, &[u8])> = entries
        .iter()
        .map(|(n, b)| (n.as_str(), b.as_slice()))
        .collect();
    npz::write_archive(w, &refs)
}

/// Writes `f` to `path` atomically (whole or not at all).
pub fn write_operators(path: impl AsRef<Path>, f: &OperatorsFile) -> Result<()> {
    let path = path.as_ref();
    crate::atomic::write_atomically(path, |w: &mut dyn Write| write_operators_to(w, f))
        .map_err(|e| Error::io(path, e))
}

/// Reads an operators file written by [`write_operators`] (or by NumPy
/// with the same entries).
///
/// Errors: the file's I/O, a file over [`MAX_OPERATORS_BYTES`], and
/// anything [`parse_operators`] refuses, naming the file.
pub fn read_operators(path: impl AsRef<Path>) -> Result<OperatorsFile> {
    npz::read_file(
        path.as_ref(),
        MAX_OPERATORS_BYTES,
        "operators (.npz)",
        parse_operators,
    )
}

/// Parses an operators archive (see the module docs); the error gives the
/// byte offset where known and what is wrong.
pub fn parse_operators(data: &[u8]) -> std::result::Result<OperatorsFile, (Option<usize>, String)> {
    let entries = npz::read_archive(data).map_err(|(at, m)| (Some(at), m))?;
    let entry = |name: &str| {
        entries
            .iter()
            .find(|e| e.name == format!("{name}.npy"))
            .map(|e| e.data)
            .ok_or((
                None,
                format!("no `{name}` entry: not an fmaps operators file"),
            ))
    };
    let ctx =
        |name: String| move |(at, m): (usize, String)| (None, format!("{name}, byte {at}: {m}"));
    let format = npy::parse_u8(entry("format")?).map_err(ctx("format".into()))?;
    if format != FORMAT {
        return Err((
            None,
            format!(
                "format {:?}, this version reads {:?}",
                String::from_utf8_lossy(&format),
                String::from_utf8_lossy(FORMAT)
            ),
        ));
    }
    let key = npy::parse_u8(entry("key")?).map_err(ctx("key".into()))?;
    let key = String::from_utf8(key).map_err(|_| (None, "the key is not UTF-8".to_string()))?;
    let f64s = |name: &str| npy::parse_f64(entry(name)?).map_err(ctx(name.to_string()));
    let indices = |name: String| -> std::result::Result<Vec<usize>, (Option<usize>, String)> {
        let a = npy::parse_i64(entry(&name)?).map_err(ctx(name.clone()))?;
        a.data
            .iter()
            .map(|&x| usize::try_from(x).map_err(|_| (None, format!("{name}: negative index {x}"))))
            .collect()
    };
    let (mass, evals, vectors, frames) = (
        f64s("mass")?,
        f64s("eigenvalues")?,
        f64s("eigenvectors")?,
        f64s("frames")?,
    );
    let (n, k) = (mass.data.len(), evals.data.len());
    if vectors.shape != [n, k] || frames.shape != [n, 3, 3] {
        return Err((
            None,
            format!(
                "shapes do not fit: mass {:?}, eigenvalues {:?}, eigenvectors {:?}, frames {:?}",
                mass.shape, evals.shape, vectors.shape, frames.shape
            ),
        ));
    }
    let frames: Vec<[f64; 9]> = (0..n)
        .map(|v| std::array::from_fn(|i| frames.data[v + n * (i / 3 + 3 * (i % 3))]))
        .collect();
    let sparse = |name: &str| -> std::result::Result<SparseRows, (Option<usize>, String)> {
        Ok(SparseRows {
            indptr: indices(format!("{name}_indptr"))?,
            indices: indices(format!("{name}_indices"))?,
            data: f64s(&format!("{name}_data"))?.data,
        })
    };
    let f = OperatorsFile {
        key,
        mass: mass.data,
        eigenvalues: evals.data,
        eigenvectors: vectors.data,
        frames,
        grad_x: sparse("grad_x")?,
        grad_y: sparse("grad_y")?,
    };
    match f.problem() {
        Some(p) => Err((None, p)),
        None => Ok(f),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> OperatorsFile {
        let n = 3;
        let m = SparseRows {
            indptr: vec![0, 2, 3, 5],
            indices: vec![0, 2, 1, 0, 2],
            data: vec![1.0, -1.0, 0.5, 2.0, -2.0],
        };
        OperatorsFile {
            key: "shape 3 vertices".into(),
            mass: vec![0.1, 0.2, 0.3],
            eigenvalues: vec![0.0, 1.5],
            eigenvectors: (0..2 * n).map(|i| i as f64 * 0.25 - 0.5).collect(),
            frames: (0..n)
                .map(|v| std::array::from_fn(|i| (10 * v + i) as f64))
                .collect(),
            grad_x: m.clone(),
            grad_y: SparseRows {
                data: vec![3.0, 4.0, 5.0, 6.0, 7.0],
                ..m
            },
        }
    }

    fn bytes(f: &OperatorsFile) -> Vec<u8> {
        let mut b = Vec::new();
        write_operators_to(&mut b, f).unwrap();
        b
    }

    #[test]
    fn a_written_file_reads_back_the_same() {
        let f = sample();
        assert_eq!(parse_operators(&bytes(&f)).unwrap(), f);
    }

    /// Truncated, damaged or inconsistent files are errors, never
    /// operators.
    #[test]
    fn damaged_or_inconsistent_files_are_errors() {
        let b = bytes(&sample());
        for cut in [0, 10, b.len() / 2, b.len() - 1] {
            assert!(parse_operators(&b[..cut]).is_err(), "cut at {cut}");
        }
        let mut flipped = b.clone();
        let mid = flipped.len() / 3;
        flipped[mid] ^= 0x40;
        assert!(parse_operators(&flipped).is_err());
        let mut bad = sample();
        bad.grad_x.indices[1] = 3;
        let mut out = Vec::new();
        assert!(write_operators_to(&mut out, &bad).is_err());
        let mut bad = sample();
        bad.grad_y.indptr = vec![0, 3, 2, 5];
        assert!(write_operators_to(&mut out, &bad).is_err());
        let mut bad = sample();
        bad.mass[1] = f64::NAN;
        assert!(write_operators_to(&mut out, &bad).is_err());
        // A basis cache is not an operators file.
        let mut basis = Vec::new();
        crate::basis::write_basis_to(
            &mut basis,
            &crate::basis::BasisFile {
                key: "k".into(),
                eigenvalues: vec![0.0],
                mass: vec![1.0],
                vectors: vec![1.0],
            },
        )
        .unwrap();
        let e = parse_operators(&basis).unwrap_err();
        assert!(e.1.contains("fmaps-basis-2"), "{e:?}");
    }
}
