//! NumPy `.npy` arrays (format versions 1.0 to 3.0), so that Python users
//! can `np.load` what fmaps computes and fmaps can read arrays NumPy
//! wrote; the format is read and written by the `npyz` crate.
//!
//! Written: `float64` and `int64` arrays (little-endian) in column-major
//! (Fortran) order, as nalgebra stores matrices, and `uint8` byte strings.
//! Read: exactly `<f8`, `<i8` or `|u1` here (fmaps' own files), in either
//! order (returned column-major); [`crate::arrays`] reads every real and
//! integer dtype of users' files. The readers check that the data is
//! exactly as long as the header's shape says before they allocate
//! anything, so a header cannot make them allocate more than the input.

use std::io::{self, Write};
use std::path::Path;

/// An array read from a `.npy` file: its shape and its values in
/// column-major (Fortran) order.
#[derive(Debug, Clone, PartialEq)]
pub struct Array<T> {
    /// The dimensions (empty for a scalar).
    pub shape: Vec<usize>,
    /// The values, column-major: for a matrix, column after column.
    pub data: Vec<T>,
}

/// Writes `data` (column-major) of `shape` with the dtype `descr`.
fn write_with<T: npyz::Serialize + Copy, W: Write>(
    w: &mut W,
    descr: &str,
    shape: &[usize],
    data: &[T],
) -> io::Result<()> {
    use npyz::WriterBuilder;
    check_len(shape, data.len())?;
    let type_str: npyz::TypeStr = descr
        .parse()
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, format!("npy: {e}")))?;
    let dims: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
    let mut out = npyz::WriteOptions::new()
        .dtype(npyz::DType::Plain(type_str))
        .shape(&dims)
        .order(npyz::Order::Fortran)
        .writer(w)
        .begin_nd()?;
    out.extend(data.iter().copied())?;
    out.finish()
}

/// Writes an `f64` array of the given shape. `data` is in column-major
/// (Fortran) order, as nalgebra stores matrices; the header says so, and
/// `np.load` returns the array with the right shape and values. An
/// `InvalidInput` error if `data.len()` is not the product of `shape`.
pub fn write_f64<W: Write>(w: &mut W, shape: &[usize], data: &[f64]) -> io::Result<()> {
    write_with(w, "<f8", shape, data)
}

/// Writes an `int64` array of the given shape (column-major, as
/// [`write_f64`]): NumPy's type for indices.
pub fn write_i64<W: Write>(w: &mut W, shape: &[usize], data: &[i64]) -> io::Result<()> {
    write_with(w, "<i8", shape, data)
}

/// Writes a 1-D `uint8` array (a byte string: `bytes(np.load(...))` in
/// Python).
pub fn write_u8<W: Write>(w: &mut W, data: &[u8]) -> io::Result<()> {
    write_with(w, "|u1", &[data.len()], data)
}

/// Writes an `f64` array to a file (see [`write_f64`]), whole or not at
/// all ([`crate::atomic`]).
pub fn save_f64(path: &Path, shape: &[usize], data: &[f64]) -> io::Result<()> {
    crate::atomic::write_atomically(path, |mut w| write_f64(&mut w, shape, data))
}

/// The values of a numeric array, in column-major (Fortran) order.
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    /// An integer dtype (any width, signed or not) as i64.
    Int(Vec<i64>),
    /// A float dtype (float32, float64) as f64.
    Float(Vec<f64>),
}

/// A numeric array read from a NumPy file.
#[derive(Debug, Clone, PartialEq)]
pub struct Numeric {
    /// The dimensions (empty for a scalar).
    pub shape: Vec<usize>,
    /// The values, column-major.
    pub values: Values,
    /// The file's dtype as NumPy writes it (`<i4`, `>f8`, ...).
    pub dtype: String,
}

const PICKLE: &str = "dtype object: the array holds a pickle, which fmaps does not run; save plain numbers (np.save(..., allow_pickle=False))";

/// Parses one `.npy` array of any real or integer dtype. The error gives
/// the byte offset where known and what is wrong.
pub fn parse_numeric(bytes: &[u8]) -> std::result::Result<Numeric, (Option<usize>, String)> {
    use npyz::{DType, TypeChar};
    let mut rest = bytes;
    let header = npyz::NpyHeader::from_reader(&mut rest).map_err(|e| {
        let head = String::from_utf8_lossy(&bytes[..bytes.len().min(4096)]);
        if head.contains("'descr': '|O'") {
            (Some(0), PICKLE.to_string())
        } else {
            (Some(0), format!("not a NumPy .npy array ({e})"))
        }
    })?;
    let start = bytes.len() - rest.len();
    let file = npyz::NpyFile::with_header(header, rest);
    let dtype = file.dtype();
    let DType::Plain(ts) = &dtype else {
        return Err((
            Some(0),
            format!(
                "dtype {}: a structured array; save plain numbers",
                dtype.descr()
            ),
        ));
    };
    let descr = ts.to_string();
    let shape: Vec<usize> = file
        .shape()
        .iter()
        .map(|&d| usize::try_from(d).unwrap_or(usize::MAX))
        .collect();
    let fortran = matches!(file.order(), npyz::Order::Fortran);
    let size = ts.num_bytes().unwrap_or(0);
    let n = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or((Some(0), format!("shape {shape:?} overflows")))?;
    let needed = n
        .checked_mul(size)
        .ok_or((Some(0), format!("shape {shape:?} overflows")))?;
    if rest.len() != needed {
        return Err((
            Some(start),
            format!(
                "shape {shape:?} of {descr} needs {needed} bytes of data, the file has {}",
                rest.len()
            ),
        ));
    }
    let bad = |what: &str| (Some(0), format!("dtype {descr}: {what}"));
    let io = |e: std::io::Error| (Some(start), format!("the data: {e}"));
    let ints = |v: Vec<i64>| Values::Int(v);
    let values = match (ts.type_char(), size) {
        (TypeChar::Int, 1) => ints(
            file.into_vec::<i8>()
                .map_err(io)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Int, 2) => ints(
            file.into_vec::<i16>()
                .map_err(io)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Int, 4) => ints(
            file.into_vec::<i32>()
                .map_err(io)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Int, 8) => ints(file.into_vec::<i64>().map_err(io)?),
        (TypeChar::Uint, 1) => ints(
            file.into_vec::<u8>()
                .map_err(io)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Uint, 2) => ints(
            file.into_vec::<u16>()
                .map_err(io)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Uint, 4) => ints(
            file.into_vec::<u32>()
                .map_err(io)?
                .into_iter()
                .map(i64::from)
                .collect(),
        ),
        (TypeChar::Uint, 8) => {
            let v = file.into_vec::<u64>().map_err(io)?;
            let mut out = Vec::with_capacity(v.len());
            for (i, x) in v.into_iter().enumerate() {
                out.push(
                    i64::try_from(x)
                        .map_err(|_| bad(&format!("entry {i} is {x}, above 2^63 - 1")))?,
                );
            }
            ints(out)
        }
        (TypeChar::Float, 4) => Values::Float(
            file.into_vec::<f32>()
                .map_err(io)?
                .into_iter()
                .map(f64::from)
                .collect(),
        ),
        (TypeChar::Float, 8) => Values::Float(file.into_vec::<f64>().map_err(io)?),
        (TypeChar::Bool, _) => return Err(bad("booleans, where numbers are needed")),
        (TypeChar::Complex, _) => return Err(bad("complex numbers, where real ones are needed")),
        (TypeChar::Float, _) => return Err(bad("a float width other than 32 or 64 bits")),
        _ => return Err(bad("not a number type")),
    };
    let values = if fortran || shape.len() < 2 {
        values
    } else {
        match values {
            Values::Int(v) => Values::Int(c_to_fortran(&shape, &v)),
            Values::Float(v) => Values::Float(c_to_fortran(&shape, &v)),
        }
    };
    Ok(Numeric {
        shape,
        values,
        dtype: descr,
    })
}

/// C-order (row-major) values of `shape` in column-major order.
fn c_to_fortran<T: Copy>(shape: &[usize], values: &[T]) -> Vec<T> {
    let n = values.len();
    let mut out = Vec::with_capacity(n);
    // Strides of the C layout; iterate column-major multi-indices.
    let d = shape.len();
    let mut strides = vec![1usize; d];
    for k in (0..d.saturating_sub(1)).rev() {
        strides[k] = strides[k + 1] * shape[k + 1];
    }
    let mut idx = vec![0usize; d];
    for _ in 0..n {
        let at: usize = idx.iter().zip(&strides).map(|(i, s)| i * s).sum();
        out.push(values[at]);
        for k in 0..d {
            idx[k] += 1;
            if idx[k] < shape[k] {
                break;
            }
            idx[k] = 0;
        }
    }
    out
}

/// Reads an array of exactly the dtype `descr` (any order; returned
/// column-major).
fn parse_exact(
    bytes: &[u8],
    descr: &str,
    dtype: &str,
) -> Result<(Vec<usize>, Values), (usize, String)> {
    // The dtype first: another dtype is the error, whatever the length.
    if let Ok(file) = npyz::NpyFile::new(bytes)
        && let npyz::DType::Plain(ts) = file.dtype()
    {
        let found = ts.to_string();
        if found != descr && !(descr == "|u1" && found == "<u1") {
            return Err((
                0,
                format!("dtype {found} where {dtype} ('{descr}') is needed"),
            ));
        }
    }
    let a = parse_numeric(bytes).map_err(|(at, m)| (at.unwrap_or(0), m))?;
    Ok((a.shape, a.values))
}

/// Reads a `<f8` array (C or Fortran order; returned column-major). The
/// error says what is wrong and at which byte.
pub fn parse_f64(bytes: &[u8]) -> Result<Array<f64>, (usize, String)> {
    match parse_exact(bytes, "<f8", "float64")? {
        (shape, Values::Float(data)) => Ok(Array { shape, data }),
        _ => Err((0, "float64 ('<f8') is needed".into())),
    }
}

/// Reads an `<i8` array (C or Fortran order; returned column-major), as
/// NumPy writes integer indices.
pub fn parse_i64(bytes: &[u8]) -> Result<Array<i64>, (usize, String)> {
    match parse_exact(bytes, "<i8", "int64")? {
        (shape, Values::Int(data)) => Ok(Array { shape, data }),
        _ => Err((0, "int64 ('<i8') is needed".into())),
    }
}

/// Reads a 1-D `|u1` (or `<u1`) array.
pub fn parse_u8(bytes: &[u8]) -> Result<Vec<u8>, (usize, String)> {
    match parse_exact(bytes, "|u1", "uint8")? {
        (shape, Values::Int(data)) if shape.len() == 1 => {
            // Values of a uint8 array: 0..=255.
            Ok(data.into_iter().map(|x| x as u8).collect())
        }
        (shape, _) => Err((0, format!("shape {shape:?} (a 1-D array is needed)"))),
    }
}

fn check_len(shape: &[usize], len: usize) -> io::Result<()> {
    if shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d)) != Some(len) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("npy: shape {shape:?} does not match {len} values"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_then_read_is_exact() {
        let specials = [
            0.0,
            -0.0,
            1e300,
            -1e-300,
            5e-324,
            f64::MAX,
            f64::NAN,
            1.0 / 3.0,
        ];
        for shape in [
            vec![0],
            vec![1],
            vec![7],
            vec![3, 5],
            vec![2, 0],
            vec![4, 1, 2],
        ] {
            let n: usize = shape.iter().product();
            let data: Vec<f64> = (0..n)
                .map(|i| specials[i % specials.len()] * (i as f64 + 1.0))
                .collect();
            let mut out = Vec::new();
            write_f64(&mut out, &shape, &data).unwrap();
            let a = parse_f64(&out).unwrap();
            assert_eq!(a.shape, shape);
            assert_eq!(a.data.len(), data.len());
            assert!(
                a.data
                    .iter()
                    .zip(&data)
                    .all(|(x, y)| x.to_bits() == y.to_bits())
            );
        }
        let mut out = Vec::new();
        assert!(write_f64(&mut out, &[2, 2], &[1.0]).is_err());
        assert!(write_f64(&mut out, &[usize::MAX, 3], &[1.0]).is_err());
        let mut b = Vec::new();
        write_u8(&mut b, b"key \xff\x00").unwrap();
        assert_eq!(parse_u8(&b).unwrap(), b"key \xff\x00");
    }

    #[test]
    fn header_is_padded_and_data_follows() {
        let mut out = Vec::new();
        write_f64(&mut out, &[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let hlen = u16::from_le_bytes([out[8], out[9]]) as usize;
        // NumPy aligns the data to 16 bytes at least (64 since 1.x).
        assert_eq!((10 + hlen) % 16, 0);
        let header = std::str::from_utf8(&out[10..10 + hlen]).unwrap();
        assert!(
            header.contains("'shape': (2, 3, )") && header.contains("'fortran_order': True"),
            "{header}"
        );
        assert!(
            header.contains("'descr': '<f8'") && header.ends_with('\n'),
            "{header}"
        );
        assert_eq!(out.len(), 10 + hlen + 48);
        // Column-major data: 1, 2 are the first column.
        assert_eq!(&out[10 + hlen..10 + hlen + 8], &1.0f64.to_le_bytes());
    }

    /// What `np.save` writes for `np.arange(6.0).reshape(2, 3)` (C order,
    /// version 1.0), byte for byte: read back column-major.
    #[test]
    fn reads_numpy_c_order() {
        let mut h = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }".to_string();
        h.push_str(&" ".repeat(64 - (10 + h.len() + 1) % 64));
        h.push('\n');
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(h.len() as u16).to_le_bytes());
        b.extend_from_slice(h.as_bytes());
        for x in 0..6 {
            b.extend_from_slice(&f64::from(x).to_le_bytes());
        }
        let a = parse_f64(&b).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        // Row-major [[0, 1, 2], [3, 4, 5]] column by column.
        assert_eq!(a.data, vec![0.0, 3.0, 1.0, 4.0, 2.0, 5.0]);
    }

    #[test]
    fn bad_files_are_errors_that_allocate_nothing_large() {
        let mut good = Vec::new();
        write_f64(&mut good, &[2, 2], &[1.0, 2.0, 3.0, 4.0]).unwrap();
        // Truncated data.
        assert!(parse_f64(&good[..good.len() - 1]).is_err());
        // Truncated header, wrong magic, another dtype.
        assert!(parse_f64(&good[..20]).is_err());
        assert!(parse_f64(b"NUMPY").is_err());
        let swap = |from: &str, to: &str| {
            let at = good
                .windows(from.len())
                .position(|w| w == from.as_bytes())
                .unwrap();
            let mut b = good[..at].to_vec();
            b.extend_from_slice(to.as_bytes());
            b.extend_from_slice(&good[at + from.len()..]);
            b
        };
        let e = parse_f64(&swap("<f8", "<f4")).unwrap_err();
        assert!(e.1.contains("float64"), "{e:?}");
        // A shape promising far more than the file holds (the header's
        // length field is not updated: the shape's text is as long).
        let e = parse_f64(&swap("(2, 2, )", "(99,99,)")).unwrap_err();
        assert!(e.1.contains("needs"), "{e:?}");
        // Every prefix and every single-byte change is an error or a value,
        // never a panic.
        for cut in 0..good.len() {
            let _ = parse_f64(&good[..cut]);
        }
        for i in 0..good.len() {
            let mut b = good.clone();
            b[i] ^= 0xa5;
            let _ = parse_f64(&b);
        }
    }
}
