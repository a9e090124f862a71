//! NumPy `.npy` arrays (format versions 1.0 to 3.0, little-endian), so
//! that Python users can `np.load` what fmaps computes and fmaps can read
//! arrays NumPy wrote.
//!
//! Written: `float64` arrays in column-major (Fortran) order, as nalgebra
//! stores matrices, and `uint8` byte strings. Read: `<f8` and `<i8` in
//! either order (returned column-major) and `|u1`. The reader checks that the
//! data is exactly as long as the header's shape says before it allocates
//! anything, so a header cannot make it allocate more than the input.

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

/// Writes an `f64` array of the given shape. `data` is in column-major
/// (Fortran) order, as nalgebra stores matrices; the header says so, and
/// `np.load` returns the array with the right shape and values. An
/// `InvalidInput` error if `data.len()` is not the product of `shape`.
pub fn write_f64<W: Write>(w: &mut W, shape: &[usize], data: &[f64]) -> io::Result<()> {
    check_len(shape, data.len())?;
    write_header(w, "<f8", shape)?;
    let mut buf = Vec::with_capacity(data.len() * 8);
    for x in data {
        buf.extend_from_slice(&x.to_le_bytes());
    }
    w.write_all(&buf)
}

/// Writes an `int64` array of the given shape (column-major, as
/// [`write_f64`]): NumPy's type for indices.
pub fn write_i64<W: Write>(w: &mut W, shape: &[usize], data: &[i64]) -> io::Result<()> {
    check_len(shape, data.len())?;
    write_header(w, "<i8", shape)?;
    let mut buf = Vec::with_capacity(data.len() * 8);
    for x in data {
        buf.extend_from_slice(&x.to_le_bytes());
    }
    w.write_all(&buf)
}

/// Writes a 1-D `uint8` array (a byte string: `bytes(np.load(...))` in
/// Python).
pub fn write_u8<W: Write>(w: &mut W, data: &[u8]) -> io::Result<()> {
    write_header(w, "|u1", &[data.len()])?;
    w.write_all(data)
}

/// Writes an `f64` array to a file (see [`write_f64`]), whole or not at
/// all ([`crate::atomic`]).
pub fn save_f64(path: &Path, shape: &[usize], data: &[f64]) -> io::Result<()> {
    crate::atomic::write_atomically(path, |mut w| write_f64(&mut w, shape, data))
}

/// Reads a `<f8` array (C or Fortran order; returned column-major). The
/// error says what is wrong and at which byte.
pub fn parse_f64(bytes: &[u8]) -> Result<Array<f64>, (usize, String)> {
    parse_numeric(bytes, "<f8", "float64", |c| {
        f64::from_le_bytes(c.try_into().expect("8 bytes"))
    })
}

/// Reads an `<i8` array (C or Fortran order; returned column-major), as
/// NumPy writes integer indices.
pub fn parse_i64(bytes: &[u8]) -> Result<Array<i64>, (usize, String)> {
    parse_numeric(bytes, "<i8", "int64", |c| {
        i64::from_le_bytes(c.try_into().expect("8 bytes"))
    })
}

/// An array of 8-byte little-endian values of dtype `descr`.
fn parse_numeric<T: Copy + Default>(
    bytes: &[u8],
    descr: &str,
    dtype: &str,
    value: impl Fn(&[u8]) -> T,
) -> Result<Array<T>, (usize, String)> {
    let (header, start) = parse_header(bytes)?;
    if header.descr != descr {
        return Err((
            0,
            format!("dtype {} where {dtype} ('{descr}') is needed", header.descr),
        ));
    }
    let n = values_of(&header.shape).ok_or((0, "the shape overflows".to_string()))?;
    let body = &bytes[start..];
    if Some(body.len()) != n.checked_mul(8) {
        return Err((
            start,
            format!(
                "shape {:?} needs {} bytes of data, the file has {}",
                header.shape,
                n.saturating_mul(8),
                body.len()
            ),
        ));
    }
    let values: Vec<T> = body.chunks_exact(8).map(value).collect();
    let data = if header.fortran_order || header.shape.len() < 2 {
        values
    } else {
        c_to_fortran(&header.shape, &values)
    };
    Ok(Array {
        shape: header.shape,
        data,
    })
}

/// Reads a 1-D `|u1` (or `<u1`) array.
pub fn parse_u8(bytes: &[u8]) -> Result<Vec<u8>, (usize, String)> {
    let (header, start) = parse_header(bytes)?;
    if header.descr != "|u1" && header.descr != "<u1" {
        return Err((
            0,
            format!("dtype {} where uint8 ('|u1') is needed", header.descr),
        ));
    }
    if header.shape.len() != 1 || header.shape[0] != bytes.len() - start {
        return Err((
            start,
            format!(
                "shape {:?} for {} bytes of data (a 1-D array is needed)",
                header.shape,
                bytes.len() - start
            ),
        ));
    }
    Ok(bytes[start..].to_vec())
}

fn check_len(shape: &[usize], len: usize) -> io::Result<()> {
    if values_of(shape) != Some(len) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("npy: shape {shape:?} does not match {len} values"),
        ));
    }
    Ok(())
}

fn values_of(shape: &[usize]) -> Option<usize> {
    shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d))
}

fn write_header<W: Write>(w: &mut W, descr: &str, shape: &[usize]) -> io::Result<()> {
    let dims = match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': True, 'shape': {dims}, }}");
    // Magic (6) + version (2) + header length (2) + header + '\n' must be a
    // multiple of 64 bytes.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let len = u16::try_from(header.len())
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "npy: header too long"))?;
    w.write_all(b"\x93NUMPY\x01\x00")?;
    w.write_all(&len.to_le_bytes())?;
    w.write_all(header.as_bytes())
}

struct Header {
    descr: String,
    fortran_order: bool,
    shape: Vec<usize>,
}

/// The header's three keys and where the data starts.
fn parse_header(bytes: &[u8]) -> Result<(Header, usize), (usize, String)> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err((0, "not a .npy file (no \\x93NUMPY magic)".into()));
    }
    let (len, start): (usize, usize) = match bytes[6] {
        1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err((6, format!("format version {v} (1, 2 or 3 is read)"))),
    };
    let end = start
        .checked_add(len)
        .filter(|&e| e <= bytes.len())
        .ok_or((8, "the file ends inside the header".to_string()))?;
    let text = std::str::from_utf8(&bytes[start..end])
        .map_err(|_| (start, "the header is not text".to_string()))?;
    let value = |key: &str| -> Result<&str, (usize, String)> {
        let at = text
            .find(&format!("'{key}'"))
            .ok_or((start, format!("the header has no '{key}'")))?;
        let rest = text[at + key.len() + 2..].trim_start();
        let rest = rest
            .strip_prefix(':')
            .ok_or((start + at, format!("no ':' after '{key}'")))?;
        Ok(rest.trim_start())
    };
    let descr = value("descr")?;
    let descr = descr
        .strip_prefix('\'')
        .and_then(|d| d.split('\'').next())
        .ok_or((start, "'descr' is not a quoted string".to_string()))?
        .to_string();
    let fortran_order = match value("fortran_order")? {
        v if v.starts_with("True") => true,
        v if v.starts_with("False") => false,
        _ => return Err((start, "'fortran_order' is neither True nor False".into())),
    };
    let shape_text = value("shape")?;
    let inner = shape_text
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .ok_or((start, "'shape' is not a tuple".to_string()))?;
    let shape = inner
        .split(',')
        .map(str::trim)
        .filter(|d| !d.is_empty())
        .map(|d| d.parse::<usize>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|_| (start, format!("shape ({inner}) is not a tuple of sizes")))?;
    Ok((
        Header {
            descr,
            fortran_order,
            shape,
        },
        end,
    ))
}

/// Row-major values of `shape` in column-major order.
fn c_to_fortran<T: Copy + Default>(shape: &[usize], values: &[T]) -> Vec<T> {
    let n = values.len();
    let mut out = vec![T::default(); n];
    // Strides: row-major for the source, column-major for the target.
    let d = shape.len();
    let mut c_stride = vec![1usize; d];
    for i in (0..d.saturating_sub(1)).rev() {
        c_stride[i] = c_stride[i + 1] * shape[i + 1];
    }
    let mut index = vec![0usize; d];
    for o in out.iter_mut() {
        let src: usize = index.iter().zip(&c_stride).map(|(i, s)| i * s).sum();
        *o = values[src];
        // Next index in column-major order: the first dimension fastest.
        for (k, i) in index.iter_mut().enumerate() {
            *i += 1;
            if *i < shape[k] {
                break;
            }
            *i = 0;
        }
    }
    out
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
        assert_eq!((10 + hlen) % 64, 0);
        let header = std::str::from_utf8(&out[10..10 + hlen]).unwrap();
        assert!(header.contains("'shape': (2, 3)") && header.contains("'fortran_order': True"));
        assert!(header.ends_with('\n'));
        assert_eq!(out.len(), 10 + hlen + 48);
        let mut v = Vec::new();
        write_f64(&mut v, &[3], &[1.0, 2.0, 3.0]).unwrap();
        let h = u16::from_le_bytes([v[8], v[9]]) as usize;
        assert!(
            std::str::from_utf8(&v[10..10 + h])
                .unwrap()
                .contains("'shape': (3,)")
        );
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
        let e = parse_f64(&swap("(2, 2)", "(9999, 9)")).unwrap_err();
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
