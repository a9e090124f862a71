//! Maps, matrices and per-vertex values in NumPy files, as people save
//! them: `.npy` (and `.npz` archives holding one array) of any real or
//! integer dtype, either byte order, C or Fortran order, parsed by the
//! `npyz` crate. Indices in NumPy files are 0-based (as NumPy indexes);
//! the datasets' text formats (`.map`, `.vts`) stay 1-based.
//!
//! What converts: integers of any width to indices (uint64 above 2^63 − 1
//! refused), floats that are whole numbers to indices, integers float64
//! holds exactly and float32/float64 to values. Never: booleans, complex
//! numbers, strings, objects (a pickle inside: `np.save(...,
//! allow_pickle=False)` writes plain numbers), structured arrays. Every
//! error names the file; the data's length is checked against the header
//! before anything is allocated.
//!
//! ```
//! use fmaps_mesh_io::arrays;
//! let dir = std::env::temp_dir().join(format!("fmaps-arrays-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let path = dir.join("map.npy");
//! arrays::write_indices(&path, &[2, 0, 1], arrays::Container::Npy)?;
//! assert_eq!(arrays::read_indices(&path)?, vec![2, 0, 1]);
//! # std::fs::remove_dir_all(&dir).ok();
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::path::Path;

pub use crate::npy::{Numeric, Values, parse_numeric};
use crate::{Error, Location, Result};

/// Whether `path` names a NumPy file (`.npy` or `.npz`).
pub fn is_numpy(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy") || e.eq_ignore_ascii_case("npz"))
}

/// Reads the array of a `.npy` file, or the one array of an `.npz`
/// archive (an archive with several is refused, naming them).
pub fn read_numeric(path: &Path) -> Result<Numeric> {
    let npz = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    let format = if npz { ".npz" } else { ".npy" };
    crate::npz::read_file(path, crate::MAX_INPUT_BYTES, format, |bytes| {
        if !npz {
            return parse_numeric(bytes);
        }
        let entries = crate::npz::read_archive(bytes).map_err(|(at, m)| (Some(at), m))?;
        match entries.as_slice() {
            [one] => parse_numeric(one.data).map_err(|(_, m)| (None, format!("{}: {m}", one.name))),
            _ => Err((
                None,
                format!(
                    "{} arrays ({}): save the one array to read (np.save, or np.savez with one)",
                    entries.len(),
                    entries
                        .iter()
                        .map(|e| e.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )),
        }
    })
}

/// The error of a NumPy file's content.
fn content(path: &Path, message: String) -> Error {
    Error::Parse {
        path: Some(path.to_path_buf()),
        format: "NumPy",
        location: Location::End,
        message,
    }
}

/// 0-based vertex indices from a NumPy file: shape (n,) or (n, 1), any
/// integer dtype, or floats that are whole numbers. Negative entries are
/// refused; the caller checks them against its mesh.
pub fn read_indices(path: &Path) -> Result<Vec<usize>> {
    let a = read_numeric(path)?;
    let n = match a.shape.as_slice() {
        [n] | [n, 1] => *n,
        s => {
            return Err(content(
                path,
                format!("shape {s:?}: indices are a vector (n,) or a column (n, 1)"),
            ));
        }
    };
    let as_index = |i: usize, x: i64| {
        usize::try_from(x).map_err(|_| content(path, format!("entry {i} is {x}, a negative index")))
    };
    let out: Result<Vec<usize>> = match &a.values {
        Values::Int(v) => v.iter().enumerate().map(|(i, &x)| as_index(i, x)).collect(),
        Values::Float(v) => v
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                if x.is_finite() && x.fract() == 0.0 && x.abs() < 9.2e18 {
                    as_index(i, x as i64)
                } else {
                    Err(content(
                        path,
                        format!("entry {i} is {x}, not an integer index"),
                    ))
                }
            })
            .collect(),
    };
    let out = out?;
    debug_assert_eq!(out.len(), n);
    Ok(out)
}

/// A matrix (rows x cols, column-major values) from a NumPy file: a 2-D
/// array, or a vector as one column; integer dtypes whose values float64
/// holds exactly.
pub fn read_matrix(path: &Path) -> Result<(usize, usize, Vec<f64>)> {
    let a = read_numeric(path)?;
    let (rows, cols) = match a.shape.as_slice() {
        [n] => (*n, 1),
        [r, c] => (*r, *c),
        s => {
            return Err(content(
                path,
                format!("shape {s:?}: a matrix (2-D) or a vector is needed"),
            ));
        }
    };
    let values = match a.values {
        Values::Float(v) => v,
        Values::Int(v) => {
            const EXACT: i64 = 1 << 53;
            if let Some((i, x)) = v.iter().enumerate().find(|(_, x)| x.abs() > EXACT) {
                return Err(content(
                    path,
                    format!("entry {i} is {x}, an integer float64 cannot hold exactly"),
                ));
            }
            v.into_iter().map(|x| x as f64).collect()
        }
    };
    if let Some(i) = values.iter().position(|x| !x.is_finite()) {
        return Err(content(
            path,
            format!(
                "entry ({}, {}) is {}: values must be finite",
                i % rows.max(1),
                i / rows.max(1),
                values[i]
            ),
        ));
    }
    Ok((rows, cols, values))
}

/// How an array is stored: a `.npy` file, or an `.npz` archive holding
/// it as `arr_0` (as `np.savez` names a positional array).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Container {
    /// A `.npy` file.
    Npy,
    /// An `.npz` archive with one array.
    Npz,
}

impl Container {
    /// The container `path`'s extension names (`.npy`, `.npz`), if any.
    pub fn of(path: &Path) -> Option<Container> {
        let e = path.extension()?;
        if e.eq_ignore_ascii_case("npy") {
            Some(Container::Npy)
        } else if e.eq_ignore_ascii_case("npz") {
            Some(Container::Npz)
        } else {
            None
        }
    }
}

/// Writes 0-based indices as a 1-D int64 array to `path`, atomically.
pub fn write_indices(path: &Path, indices: &[usize], container: Container) -> Result<()> {
    let data: Vec<i64> = indices.iter().map(|&i| i as i64).collect();
    let mut npy = Vec::new();
    crate::npy::write_i64(&mut npy, &[data.len()], &data).map_err(|e| Error::io(path, e))?;
    write_array(path, &npy, container)
}

/// Writes a matrix (column-major values) as a float64 array to `path`,
/// atomically.
pub fn write_matrix(
    path: &Path,
    rows: usize,
    cols: usize,
    values: &[f64],
    container: Container,
) -> Result<()> {
    let mut npy = Vec::new();
    crate::npy::write_f64(&mut npy, &[rows, cols], values).map_err(|e| Error::io(path, e))?;
    write_array(path, &npy, container)
}

/// One `.npy` array to `path`, or inside an `.npz` archive.
fn write_array(path: &Path, npy: &[u8], container: Container) -> Result<()> {
    crate::atomic::write_atomically(path, |w| match container {
        Container::Npz => crate::npz::write_archive(w, &[("arr_0.npy", npy)]),
        Container::Npy => w.write_all(npy),
    })
    .map_err(|e| Error::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An .npy file as NumPy writes it (format 1.0), by hand: `descr`,
    /// C order unless `fortran`, `shape`, then the raw bytes.
    fn npy(descr: &str, fortran: bool, shape: &str, data: &[u8]) -> Vec<u8> {
        let mut h = format!(
            "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}",
            if fortran { "True" } else { "False" }
        );
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(' ');
        }
        h.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(h.len() as u16).to_le_bytes());
        out.extend_from_slice(h.as_bytes());
        out.extend_from_slice(data);
        out
    }

    #[test]
    fn every_integer_width_and_both_byte_orders_read_the_same_values() {
        let want = Values::Int(vec![3, 0, 7]);
        let cases: Vec<Vec<u8>> = vec![
            npy("<i4", false, "(3,)", &[3, 0, 0, 0, 0, 0, 0, 0, 7, 0, 0, 0]),
            npy(">i4", false, "(3,)", &[0, 0, 0, 3, 0, 0, 0, 0, 0, 0, 0, 7]),
            npy("<u4", false, "(3,)", &[3, 0, 0, 0, 0, 0, 0, 0, 7, 0, 0, 0]),
            npy("|u1", false, "(3,)", &[3, 0, 7]),
            npy("<i2", false, "(3,)", &[3, 0, 0, 0, 7, 0]),
            npy(
                "<i8",
                false,
                "(3,)",
                &[
                    3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 7, 0, 0, 0, 0, 0, 0, 0,
                ],
            ),
        ];
        for bytes in cases {
            assert_eq!(parse_numeric(&bytes).unwrap().values, want);
        }
    }

    #[test]
    fn c_order_matrices_come_out_column_major() {
        // [[1, 2, 3], [4, 5, 6]] in C order, float32.
        let data: Vec<u8> = [1f32, 2., 3., 4., 5., 6.]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let a = parse_numeric(&npy("<f4", false, "(2, 3)", &data)).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert_eq!(a.values, Values::Float(vec![1., 4., 2., 5., 3., 6.]));
        let f = parse_numeric(&npy("<f4", true, "(2, 3)", &data)).unwrap();
        assert_eq!(f.values, Values::Float(vec![1., 2., 3., 4., 5., 6.]));
    }

    #[test]
    fn bad_files_say_what_is_wrong() {
        let says = |bytes: &[u8], what: &str| {
            let (_, m) = parse_numeric(bytes).unwrap_err();
            assert!(m.contains(what), "{m}");
        };
        says(
            &npy("<i4", false, "(3,)", &[0; 8]),
            "needs 12 bytes of data, the file has 8",
        );
        says(
            &npy("<i4", false, "(1000000000000,)", &[0; 8]),
            "needs 4000000000000 bytes",
        );
        says(&npy("|b1", false, "(2,)", &[0, 1]), "booleans");
        says(&npy("<c16", false, "(1,)", &[0; 16]), "complex");
        says(&npy("|O", false, "(1,)", &[0; 8]), "pickle");
        says(b"PK\x03\x04 not an npy", "not a NumPy .npy array");
        says(
            &npy("<u8", false, "(1,)", &u64::MAX.to_le_bytes()),
            "above 2^63 - 1",
        );
    }
}
