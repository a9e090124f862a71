//! Writing NumPy `.npy` files (format version 1.0, little-endian `f64`), so
//! Python users can `np.load` what fmaps computes.

use std::io::{self, Write};
use std::path::Path;

/// Writes an `f64` array of the given shape. `data` is in column-major
/// (Fortran) order, as nalgebra stores matrices; the header says so, and
/// `np.load` returns the array with the right shape and values.
///
/// # Panics
/// If `data.len()` is not the product of `shape`.
#[track_caller]
pub fn write_f64<W: Write>(w: &mut W, shape: &[usize], data: &[f64]) -> io::Result<()> {
    assert_eq!(
        shape.iter().product::<usize>(),
        data.len(),
        "npy: shape does not match data"
    );
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
