//! Coloured meshes as ASCII PLY (opens in MeshLab, Blender, Open3D).

use std::fmt::Write as _;
use std::path::Path;

use crate::{Error, Result};

/// The PLY text of a mesh with one RGB colour per vertex.
pub fn colored_ply(
    vertices: &[[f64; 3]],
    faces: &[[usize; 3]],
    colors: &[[u8; 3]],
) -> Result<String> {
    crate::check_colored_mesh(vertices, faces, colors)?;
    let mut s = String::with_capacity(40 * (vertices.len() + faces.len()) + 256);
    let _ = write!(
        s,
        "ply\nformat ascii 1.0\ncomment written by fmaps-viz\nelement vertex {}\n\
         property double x\nproperty double y\nproperty double z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        vertices.len(),
        faces.len()
    );
    for (p, c) in vertices.iter().zip(colors) {
        let _ = writeln!(s, "{} {} {} {} {} {}", p[0], p[1], p[2], c[0], c[1], c[2]);
    }
    for f in faces {
        let _ = writeln!(s, "3 {} {} {}", f[0], f[1], f[2]);
    }
    Ok(s)
}

/// Writes [`colored_ply`] to a file.
pub fn write_colored_ply(
    path: impl AsRef<Path>,
    vertices: &[[f64; 3]],
    faces: &[[usize; 3]],
    colors: &[[u8; 3]],
) -> Result<()> {
    let path = path.as_ref();
    let text = colored_ply(vertices, faces, colors)?;
    fmaps_mesh_io::atomic::write_atomically(path, |w| w.write_all(text.as_bytes())).map_err(|e| {
        Error::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        }
    })
}

#[cfg(test)]
mod tests {
    /// The coloured PLY reads back (with fmaps-mesh-io's reader) to the
    /// same geometry, bit for bit, extreme coordinates included; the
    /// colours are on the vertex lines.
    #[test]
    fn write_then_read_is_exact() {
        let specials = [0.0, -0.0, 1e300, -1e-300, 5e-324, 0.1, -7.25, 1.0 / 3.0];
        let vertices: Vec<[f64; 3]> = (0..24)
            .map(|i| {
                [
                    specials[i % 8],
                    specials[(i * 3 + 1) % 8] * i as f64,
                    -(i as f64) / 7.0,
                ]
            })
            .collect();
        let faces: Vec<[usize; 3]> = (0..22).map(|i| [i, i + 1, i + 2]).collect();
        let colors: Vec<[u8; 3]> = (0..24u8).map(|i| [i, 255 - i, i * 10]).collect();
        let text = super::colored_ply(&vertices, &faces, &colors).unwrap();
        let m = fmaps_mesh_io::parse_ply(text.as_bytes()).unwrap();
        assert_eq!(m.faces(), &faces[..]);
        for (a, b) in m.vertices().iter().zip(&vertices) {
            for c in 0..3 {
                assert_eq!(a[c].to_bits(), b[c].to_bits(), "{a:?} vs {b:?}");
            }
        }
        let body = text.split("end_header\n").nth(1).unwrap();
        for (line, c) in body.lines().zip(&colors) {
            let v: Vec<&str> = line.split(' ').collect();
            assert_eq!(v[3..], [c[0], c[1], c[2]].map(|x| x.to_string()));
        }
    }
}
