//! Pictures of shape correspondences, part of fmaps, with no GPU and no
//! system libraries: a software rasteriser for triangle meshes
//! ([`render`]), colours that show a map ([`position_colors`] carried by
//! [`push_colors`], [`checkerboard`] textures, error heat maps through
//! [`colormap`] with a [`colorbar`]), matrix heat maps and line plots
//! ([`plot`]) and PNG output ([`Image::save_png`]). The colours also go
//! to MeshLab as a coloured PLY through `fmaps_mesh_io::save_colored_ply`.
//!
//! ```
//! use fmaps_viz::{Image, View, position_colors, push_colors, render};
//! let mesh = fmaps_shapes::icosphere(1.0, 2);
//! let (v, f) = (mesh.vertices(), mesh.faces());
//! // Colour transfer through the identity map: both sides look the same.
//! let source = position_colors(v);
//! let target = push_colors(&(0..v.len()).collect::<Vec<_>>(), &source, v.len(), f);
//! assert_eq!(source, target);
//! let view = View { width: 200, height: 200, ..View::default() };
//! let picture = Image::hstack(
//!     &[render(v, f, &source, &view)?, render(v, f, &target, &view)?],
//!     [255, 255, 255],
//! );
//! assert_eq!((picture.width(), picture.height()), (400, 200));
//! let png = picture.to_png()?;
//! assert_eq!(&png[1..4], b"PNG");
//! # Ok::<(), fmaps_viz::Error>(())
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

mod color;
pub mod html;
mod image;
pub mod plot;
mod render;

pub use color::{checkerboard, colorbar, colormap, position_colors, push_colors, scalar_colors};
pub use image::{BLACK, Image, WHITE};
pub use render::{Axis, View, render};

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An input has the wrong length.
    #[error("{what}: got {found}, expected {expected}")]
    Size {
        /// What was measured.
        what: &'static str,
        /// Its size.
        found: usize,
        /// The size needed.
        expected: usize,
    },
    /// A face refers to a vertex that does not exist.
    #[error("face {at} {face:?} refers to a vertex beyond the {n} vertices")]
    Face {
        /// Face index.
        at: usize,
        /// Its vertices.
        face: [usize; 3],
        /// Number of vertices.
        n: usize,
    },
    /// PNG encoding failed.
    #[error("PNG encoding: {0}")]
    Png(String),
    /// A file could not be written.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        message: String,
    },
}

/// Checks one colour per vertex and faces within the vertices.
fn check_colored_mesh(
    vertices: &[[f64; 3]],
    faces: &[[usize; 3]],
    colors: &[[u8; 3]],
) -> Result<()> {
    if colors.len() != vertices.len() {
        return Err(Error::Size {
            what: "vertex colours",
            found: colors.len(),
            expected: vertices.len(),
        });
    }
    if let Some((at, f)) = faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&v| v >= vertices.len()))
    {
        return Err(Error::Face {
            at,
            face: *f,
            n: vertices.len(),
        });
    }
    Ok(())
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
