//! Eigenbasis cache files (`fmaps batch`): one shape's eigenvalues,
//! eigenvectors and mass, with the key they were computed under (a hash
//! of the mesh file and the parameters), so that a collection computes
//! each shape's basis once across all its pairs and across runs.
//!
//! Layout (little-endian): the magic line `FMAPS-BASIS-1\n`, the key's
//! length (u32) and bytes (UTF-8, at most [`MAX_KEY`]), `n` and `k` (u64),
//! then `k` eigenvalues, `n` mass entries and the `n x k` eigenvectors
//! column by column (f64). A file is accepted only if its length is
//! exactly what its header announces and every value is finite.

use std::io::Write;
use std::path::Path;

use crate::{Error, Location, Result};

const MAGIC: &[u8] = b"FMAPS-BASIS-1\n";

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

/// Writes `b` to `path` atomically (whole or not at all).
pub fn write_basis(path: impl AsRef<Path>, b: &BasisFile) -> Result<()> {
    let path = path.as_ref();
    let bad = |m: String| {
        Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, m),
        )
    };
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
    crate::atomic::write_atomically(path, |w: &mut dyn Write| {
        w.write_all(MAGIC)?;
        w.write_all(&(b.key.len() as u32).to_le_bytes())?;
        w.write_all(b.key.as_bytes())?;
        w.write_all(&(b.n() as u64).to_le_bytes())?;
        w.write_all(&(b.k() as u64).to_le_bytes())?;
        for v in b.eigenvalues.iter().chain(&b.mass).chain(&b.vectors) {
            w.write_all(&v.to_le_bytes())?;
        }
        Ok(())
    })
    .map_err(|e| Error::io(path, e))
}

/// Reads a cache file written by [`write_basis`]; any other content is a
/// parse error naming the byte where it went wrong.
pub fn read_basis(path: impl AsRef<Path>) -> Result<BasisFile> {
    let path = path.as_ref();
    let data = crate::read_bounded(path, MAX_BASIS_BYTES)?;
    parse_basis(&data).map_err(|(at, message)| Error::Parse {
        path: Some(path.to_path_buf()),
        format: "basis cache",
        location: at.map_or(Location::End, Location::Byte),
        message,
    })
}

/// [`read_basis`] on bytes: the error's byte offset (`None`: the end).
pub fn parse_basis(data: &[u8]) -> std::result::Result<BasisFile, (Option<usize>, String)> {
    let mut at = 0usize;
    let mut take =
        |len: usize, what: &str| -> std::result::Result<&[u8], (Option<usize>, String)> {
            let end = at
                .checked_add(len)
                .filter(|&e| e <= data.len())
                .ok_or((None, format!("the file ends inside the {what}")))?;
            let s = &data[at..end];
            at = end;
            Ok(s)
        };
    if take(MAGIC.len(), "header")? != MAGIC {
        return Err((
            Some(0),
            "not an fmaps basis cache file (bad magic line)".into(),
        ));
    }
    let key_len = u32::from_le_bytes(take(4, "key length")?.try_into().expect("4")) as usize;
    if key_len > MAX_KEY {
        return Err((
            Some(MAGIC.len()),
            format!("key of {key_len} bytes (at most {MAX_KEY})"),
        ));
    }
    let key = std::str::from_utf8(take(key_len, "key")?)
        .map_err(|_| (Some(MAGIC.len() + 4), "the key is not UTF-8".to_string()))?
        .to_string();
    let sizes_at = MAGIC.len() + 4 + key_len;
    let n = u64::from_le_bytes(take(8, "sizes")?.try_into().expect("8"));
    let k = u64::from_le_bytes(take(8, "sizes")?.try_into().expect("8"));
    // The announced length must be the file's: nothing is allocated for
    // sizes the file does not hold.
    let values = n
        .checked_mul(k)
        .and_then(|nk| nk.checked_add(n))
        .and_then(|v| v.checked_add(k))
        .filter(|v| {
            v.checked_mul(8)
                .is_some_and(|b| b == (data.len() - (sizes_at + 16)) as u64)
        })
        .ok_or((
            Some(sizes_at),
            format!(
                "n = {n}, k = {k} need {} bytes of values, the file has {}",
                n.saturating_mul(k)
                    .saturating_add(n)
                    .saturating_add(k)
                    .saturating_mul(8),
                data.len() - (sizes_at + 16)
            ),
        ))? as usize;
    let start = sizes_at + 16;
    let mut out = Vec::with_capacity(values);
    for (i, c) in data[start..].chunks_exact(8).enumerate() {
        let v = f64::from_le_bytes(c.try_into().expect("8"));
        if !v.is_finite() {
            return Err((Some(start + 8 * i), format!("value {v} is not finite")));
        }
        out.push(v);
    }
    let (n, k) = (n as usize, k as usize);
    let vectors = out.split_off(n + k);
    let mass = out.split_off(k);
    Ok(BasisFile {
        key,
        eigenvalues: out,
        mass,
        vectors,
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
        let p = dir.join("b.basis");
        write_basis(&p, &sample()).unwrap();
        assert_eq!(read_basis(&p).unwrap(), sample());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn damaged_files_are_errors_naming_the_byte() {
        let mut bytes = Vec::new();
        bytes.extend_from_slice(MAGIC);
        let b = sample();
        bytes.extend_from_slice(&(b.key.len() as u32).to_le_bytes());
        bytes.extend_from_slice(b.key.as_bytes());
        bytes.extend_from_slice(&2u64.to_le_bytes());
        bytes.extend_from_slice(&3u64.to_le_bytes());
        for v in b.eigenvalues.iter().chain(&b.mass).chain(&b.vectors) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        assert_eq!(parse_basis(&bytes).unwrap(), b);
        // Truncated anywhere: an error, never a panic.
        for cut in 0..bytes.len() {
            assert!(parse_basis(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        // Sizes that would need more than the file holds (no allocation).
        let mut huge = bytes.clone();
        let sizes = MAGIC.len() + 4 + b.key.len();
        huge[sizes..sizes + 8].copy_from_slice(&u64::MAX.to_le_bytes());
        let (at, msg) = parse_basis(&huge).unwrap_err();
        assert_eq!(at, Some(sizes), "{msg}");
        // A NaN is named by its byte.
        let mut nan = bytes.clone();
        let last = nan.len() - 8;
        nan[last..].copy_from_slice(&f64::NAN.to_le_bytes());
        assert_eq!(parse_basis(&nan).unwrap_err().0, Some(last));
        assert_eq!(parse_basis(b"OFF\n").unwrap_err().0, None);
        let mut other = bytes.clone();
        other[6] = b'X';
        assert_eq!(parse_basis(&other).unwrap_err().0, Some(0));
    }
}
