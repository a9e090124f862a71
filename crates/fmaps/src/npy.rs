//! Writing NumPy `.npy` files (format version 1.0, little-endian `f64`), so
//! Python users can `np.load` what fmaps computes.

use std::io::{self, Write};
use std::path::Path;

/// Writes an `f64` array of the given shape. `data` is in column-major
/// (Fortran) order, as nalgebra stores matrices; the header says so, and
/// `np.load` returns the array with the right shape and values. An
/// `InvalidInput` error if `data.len()` is not the product of `shape`.
pub fn write_f64<W: Write>(w: &mut W, shape: &[usize], data: &[f64]) -> io::Result<()> {
    let size = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
    if size != Some(data.len()) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("npy: shape {shape:?} does not match {} values", data.len()),
        ));
    }
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
    let mut header = format!("{{'descr': '<f8', 'fortran_order': True, 'shape': {dims}, }}");
    // Magic (6) + version (2) + header length (2) + header + '\n' must be a
    // multiple of 64 bytes.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    w.write_all(b"\x93NUMPY\x01\x00")?;
    w.write_all(&(header.len() as u16).to_le_bytes())?;
    w.write_all(header.as_bytes())?;
    let mut buf = Vec::with_capacity(data.len() * 8);
    for x in data {
        buf.extend_from_slice(&x.to_le_bytes());
    }
    w.write_all(&buf)
}

/// Writes an `f64` array to a file (see [`write_f64`]).
/// Written whole or not at all ([`fmaps_mesh_io::atomic`]).
pub fn save_f64(path: &Path, shape: &[usize], data: &[f64]) -> io::Result<()> {
    fmaps_mesh_io::atomic::write_atomically(path, |mut w| write_f64(&mut w, shape, data))
}

#[cfg(test)]
mod tests {
    /// A reader of what [`super::write_f64`] writes, from the format's
    /// specification: (shape, column-major data).
    fn read(bytes: &[u8]) -> (Vec<usize>, Vec<f64>) {
        assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
        let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        let header = std::str::from_utf8(&bytes[10..10 + hlen]).unwrap();
        assert!(header.contains("'descr': '<f8'") && header.contains("'fortran_order': True"));
        let dims = header.split("'shape': (").nth(1).unwrap();
        let dims = &dims[..dims.find(')').unwrap()];
        let shape: Vec<usize> = dims
            .split(',')
            .map(str::trim)
            .filter(|d| !d.is_empty())
            .map(|d| d.parse().unwrap())
            .collect();
        let data = bytes[10 + hlen..]
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        (shape, data)
    }

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
            super::write_f64(&mut out, &shape, &data).unwrap();
            let (s, d) = read(&out);
            assert_eq!(s, shape);
            assert_eq!(d.len(), data.len());
            assert!(d.iter().zip(&data).all(|(a, b)| a.to_bits() == b.to_bits()));
        }
        let mut out = Vec::new();
        assert!(super::write_f64(&mut out, &[2, 2], &[1.0]).is_err());
        assert!(super::write_f64(&mut out, &[usize::MAX, 3], &[1.0]).is_err());
    }

    #[test]
    fn header_is_padded_and_data_follows() {
        let mut out = Vec::new();
        super::write_f64(&mut out, &[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let hlen = u16::from_le_bytes([out[8], out[9]]) as usize;
        assert_eq!((10 + hlen) % 64, 0);
        let header = std::str::from_utf8(&out[10..10 + hlen]).unwrap();
        assert!(header.contains("'shape': (2, 3)") && header.contains("'fortran_order': True"));
        assert!(header.ends_with('\n'));
        assert_eq!(out.len(), 10 + hlen + 48);
        assert_eq!(
            f64::from_le_bytes(out[10 + hlen..18 + hlen].try_into().unwrap()),
            1.0
        );
        let mut v = Vec::new();
        super::write_f64(&mut v, &[3], &[1.0, 2.0, 3.0]).unwrap();
        let h = u16::from_le_bytes([v[8], v[9]]) as usize;
        assert!(
            std::str::from_utf8(&v[10..10 + h])
                .unwrap()
                .contains("'shape': (3,)")
        );
    }
}
