//! Eigenbasis cache files (`fmaps batch`): one shape's eigenvalues,
//! eigenvectors and mass, with the key they were computed under (a hash
//! of the mesh file and the parameters), so that a collection computes
//! each shape's basis once across all its pairs and across runs.
//!
//! A cache file is a NumPy `.npz` archive ([`crate::npz`]), readable with
//! NumPy alone:
//!
//! ```python
//! z = np.load("tr_reg_000-....npz")
//! phi, evals, mass = z["eigenvectors"], z["eigenvalues"], z["mass"]   # n x k, (k,), (n,)
//! key = bytes(z["key"]).decode()
//! ```
//!
//! Entries: `format` (the bytes `fmaps-basis-2`), `key` (UTF-8 bytes, at
//! most [`MAX_KEY`]), `eigenvalues` (k), `mass` (n) and `eigenvectors`
//! (n x k, float64). A file is accepted only if every entry is present,
//! its CRC-32 and sizes agree, the shapes fit together and every value is
//! finite: a truncated file, a damaged one or one of another format is an
//! error (the caller recomputes), never a basis.

use std::io::Write;
use std::path::Path;

use crate::{Error, Result, npy, npz};

/// The `format` entry of the files this version writes and reads.
const FORMAT: &[u8] = b"fmaps-basis-2";

/// Longest key stored.
pub const MAX_KEY: usize = 4096;

/// Largest cache file read (2 GiB: 1.3M vertices x 200 eigenpairs).
pub const MAX_BASIS_BYTES: u64 = 1 << 31;

/// One shape's eigenbasis as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct BasisFile {
    /// What it was computed from (checked by the caller).
    pub key: String,
    /// Eigenvalues (length k).
    pub eigenvalues: Vec<f64>,
    /// Mass diagonal (length n).
    pub mass: Vec<f64>,
    /// Eigenvectors, column-major n x k.
    pub vectors: Vec<f64>,
}

impl BasisFile {
    /// Vertices.
    pub fn n(&self) -> usize {
        self.mass.len()
    }

    /// Eigenpairs.
    pub fn k(&self) -> usize {
        self.eigenvalues.len()
    }
}

/// The `.npz` archive holding `b`, written to `w`.
pub fn write_basis_to(w: &mut dyn Write, b: &BasisFile) -> std::io::Result<()> {
    let bad = |m: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, m);
    if b.key.len() > MAX_KEY {
        return Err(bad(format!(
            "key of {} bytes (at most {MAX_KEY})",
            b.key.len()
        )));
    }
    if b.vectors.len() != b.n() * b.k() {
        return Err(bad(format!(
            "{} eigenvector entries for n = {} and k = {}",
            b.vectors.len(),
            b.n(),
            b.k()
        )));
    }
    let (mut format, mut key, mut evals, mut mass, mut vectors) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    npy::write_u8(&mut format, FORMAT)?;
    npy::write_u8(&mut key, b.key.as_bytes())?;
    npy::write_f64(&mut evals, &[b.k()], &b.eigenvalues)?;
    npy::write_f64(&mut mass, &[b.n()], &b.mass)?;
    npy::write_f64(&mut vectors, &[b.n(), b.k()], &b.vectors)?;
    npz::write_archive(
        w,
        &[
            ("format.npy", &format),
            ("key.npy", &key),
            ("eigenvalues.npy", &evals),
            ("mass.npy", &mass),
            ("eigenvectors.npy", &vectors),
        ],
    )
}

/// Writes `b` to `path` atomically (whole or not at all).
pub fn write_basis(path: impl AsRef<Path>, b: &BasisFile) -> Result<()> {
    let path = path.as_ref();
    crate::atomic::write_atomically(path, |w: &mut dyn Write| write_basis_to(w, b))
        .map_err(|e| Error::io(path, e))
}

/// Reads a cache file written by [`write_basis`]; any other content is a
/// parse error naming the byte (or the entry) where it went wrong.
pub fn read_basis(path: impl AsRef<Path>) -> Result<BasisFile> {
    npz::read_file(
        path.as_ref(),
        MAX_BASIS_BYTES,
        "basis cache (.npz)",
        parse_basis,
    )
}

/// [`read_basis`] on bytes: the error's byte offset (`None`: the whole
/// archive or an entry's content).
pub fn parse_basis(data: &[u8]) -> std::result::Result<BasisFile, (Option<usize>, String)> {
    let entries = npz::read_archive(data).map_err(|(at, m)| (Some(at), m))?;
    let entry = |name: &str| npz::entry(&entries, name, "basis cache");
    let in_entry = |name: &'static str| {
        move |(at, m): (usize, String)| (None, format!("{name}, byte {at}: {m}"))
    };
    let format = npy::parse_u8(entry("format")?).map_err(in_entry("format"))?;
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
    let key = npy::parse_u8(entry("key")?).map_err(in_entry("key"))?;
    if key.len() > MAX_KEY {
        return Err((
            None,
            format!("key of {} bytes (at most {MAX_KEY})", key.len()),
        ));
    }
    let key = String::from_utf8(key).map_err(|_| (None, "the key is not UTF-8".to_string()))?;
    let evals = npy::parse_f64(entry("eigenvalues")?).map_err(in_entry("eigenvalues"))?;
    let mass = npy::parse_f64(entry("mass")?).map_err(in_entry("mass"))?;
    let vectors = npy::parse_f64(entry("eigenvectors")?).map_err(in_entry("eigenvectors"))?;
    let (n, k) = (mass.data.len(), evals.data.len());
    if evals.shape.len() != 1 || mass.shape.len() != 1 || vectors.shape != [n, k] {
        return Err((
            None,
            format!(
                "shapes do not fit: eigenvalues {:?}, mass {:?}, eigenvectors {:?}",
                evals.shape, mass.shape, vectors.shape
            ),
        ));
    }
    for (name, a) in [
        ("eigenvalues", &evals),
        ("mass", &mass),
        ("eigenvectors", &vectors),
    ] {
        if let Some((i, v)) = a.data.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err((None, format!("{name}[{i}] = {v} is not finite")));
        }
    }
    Ok(BasisFile {
        key,
        eigenvalues: evals.data,
        mass: mass.data,
        vectors: vectors.data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> BasisFile {
        BasisFile {
            key: "mesh 0123 k=3".into(),
            eigenvalues: vec![0.0, 1.5, 2.25],
            mass: vec![0.5, 0.25],
            vectors: vec![1.0, 2.0, 3.0, 4.0, 5.0, -6.0],
        }
    }

    #[test]
    fn a_basis_round_trips() {
        let dir = std::env::temp_dir().join(format!("fmaps-basis-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("b.npz");
        write_basis(&p, &sample()).unwrap();
        assert_eq!(read_basis(&p).unwrap(), sample());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn damaged_files_are_errors() {
        let mut bytes = Vec::new();
        write_basis_to(&mut bytes, &sample()).unwrap();
        assert_eq!(parse_basis(&bytes).unwrap(), sample());
        // Truncated anywhere: an error, never a panic.
        for cut in 0..bytes.len() {
            assert!(parse_basis(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        // Any flipped byte: an error or the same basis (a byte no check
        // covers, such as a record's time), never another basis.
        for i in 0..bytes.len() {
            let mut d = bytes.clone();
            d[i] ^= 0x11;
            if let Ok(b) = parse_basis(&d) {
                assert_eq!(b, sample(), "byte {i}");
            }
        }
        // A NaN, with a valid CRC: named by its entry and index.
        let mut nan = sample();
        nan.vectors[4] = f64::NAN;
        let mut nan_bytes = Vec::new();
        write_basis_to(&mut nan_bytes, &nan).unwrap();
        let e = parse_basis(&nan_bytes).unwrap_err();
        assert!(e.1.contains("eigenvectors[4]"), "{e:?}");
        // Shapes that do not fit together, and another format.
        let archive = |format: &[u8], shape: [usize; 2]| {
            let b = sample();
            let (mut f, mut k, mut l, mut m, mut v) =
                (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
            npy::write_u8(&mut f, format).unwrap();
            npy::write_u8(&mut k, b.key.as_bytes()).unwrap();
            npy::write_f64(&mut l, &[3], &b.eigenvalues).unwrap();
            npy::write_f64(&mut m, &[2], &b.mass).unwrap();
            npy::write_f64(&mut v, &shape, &b.vectors).unwrap();
            let mut out = Vec::new();
            let entries: [(&str, &[u8]); 5] = [
                ("format.npy", &f),
                ("key.npy", &k),
                ("eigenvalues.npy", &l),
                ("mass.npy", &m),
                ("eigenvectors.npy", &v),
            ];
            npz::write_archive(&mut out, &entries).unwrap();
            out
        };
        assert_eq!(parse_basis(&archive(FORMAT, [2, 3])).unwrap(), sample());
        let e = parse_basis(&archive(FORMAT, [3, 2])).unwrap_err();
        assert!(e.1.contains("shapes do not fit"), "{e:?}");
        let e = parse_basis(&archive(b"fmaps-basis-1", [2, 3])).unwrap_err();
        assert!(e.1.contains("this version reads"), "{e:?}");
        // Files that are not archives at all.
        assert!(parse_basis(b"FMAPS-BASIS-1\n").is_err());
        assert!(parse_basis(b"OFF\n").is_err());
    }
}
