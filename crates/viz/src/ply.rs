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
