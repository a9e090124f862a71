//! The error type of `fmaps-mesh-io`.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in an input a parse error was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Location {
    /// A 1-based line number of a text file.
    Line(usize),
    /// A 0-based byte offset into a binary file.
    Byte(usize),
    /// The end of the input (the file is truncated).
    End,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(l) => write!(f, "line {l}"),
            Location::Byte(b) => write!(f, "byte {b}"),
            Location::End => f.write_str("end of file"),
        }
    }
}

/// Everything that can go wrong reading, writing or building a mesh or a
/// correspondence file.
///
/// Parse errors carry the file (when reading from a path), the format, the
/// line or byte offset, and a sentence saying what was wrong.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A scale factor that is not finite and positive.
    #[error("scale factor {0} must be finite and positive")]
    InvalidScale(f64),
    /// The file could not be opened, read or written.
    #[error("{}: input/output error", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The file is larger than this crate reads ([`crate::MAX_INPUT_BYTES`]),
    /// or is a device or pipe that does not end within that many bytes.
    #[error("{}: larger than {} bytes, the most fmaps reads from one input file (is it a device or a wrong file?)", path.display(), limit)]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The limit in bytes.
        limit: u64,
    },
    /// The file extension is not one of the supported formats.
    #[error("{}: unknown mesh format {}; expected .off, .obj or .ply", path.display(), ext.as_deref().map_or("(no extension)".to_string(), |e| format!("'.{e}'")))]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// Its extension, if it has one.
        ext: Option<String>,
    },
    /// The content of the file is malformed.
    #[error("{}{location}: {format}: {message}", path_prefix(path.as_deref()))]
    Parse {
        /// The file, when the input came from a path.
        path: Option<PathBuf>,
        /// The format being parsed ("OFF", "PLY", "OBJ", ".vts", ".map").
        format: &'static str,
        /// Where the problem is.
        location: Location,
        /// What is wrong.
        message: String,
    },
    /// A mesh built from arrays is not a valid triangle mesh.
    #[error("{}invalid mesh: {problem}", path_prefix(path.as_deref()))]
    InvalidMesh {
        /// The file, when the mesh came from a path.
        path: Option<PathBuf>,
        /// What is wrong.
        problem: MeshProblem,
    },
    /// An index of a correspondence file is out of range for the mesh it
    /// refers to.
    #[error("{}line {line}: vertex index {index} (1-based) is out of range: the mesh has {n_vertices} vertices", path_prefix(path.as_deref()))]
    IndexOutOfRange {
        /// The correspondence file, when known.
        path: Option<PathBuf>,
        /// The 1-based line of the offending entry.
        line: usize,
        /// The 1-based index as written in the file.
        index: usize,
        /// The number of vertices of the mesh the file refers to.
        n_vertices: usize,
    },
}

fn path_prefix(path: Option<&Path>) -> String {
    path.map_or_else(String::new, |p| format!("{}: ", p.display()))
}

/// Why arrays of vertices and faces do not form a valid triangle mesh.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MeshProblem {
    /// The mesh has no vertices or no faces.
    #[error("the mesh is empty ({n_vertices} vertices, {n_faces} faces)")]
    Empty {
        /// Number of vertices.
        n_vertices: usize,
        /// Number of faces.
        n_faces: usize,
    },
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {vertex} has a non-finite coordinate {value}")]
    NonFiniteVertex {
        /// 0-based vertex index.
        vertex: usize,
        /// The offending value.
        value: f64,
    },
    /// A face refers to a vertex that does not exist.
    #[error("face {face} refers to vertex {index}, but the mesh has {n_vertices} vertices")]
    FaceIndexOutOfRange {
        /// 0-based face index.
        face: usize,
        /// The offending 0-based vertex index.
        index: usize,
        /// Number of vertices.
        n_vertices: usize,
    },
    /// Every face has zero area (collinear or repeated vertices only), so
    /// the mesh cannot be scaled to unit area.
    #[error("the area is 0: it cannot be normalized (collinear or degenerate faces only?)")]
    ZeroArea,
    /// The coordinates are too large or too small for the area of a
    /// surface to be represented in double precision.
    #[error(
        "coordinates of magnitude {extent:e} are beyond double precision's range for a surface"
    )]
    ExtentOutOfRange {
        /// The largest coordinate magnitude.
        extent: f64,
    },
}

impl Error {
    /// Attaches a file path to an error produced while parsing bytes (as
    /// [`read_mesh`](crate::read_mesh) reports it), for callers that read
    /// the file themselves and parse with [`parse_mesh`](crate::parse_mesh).
    pub fn with_path(self, p: &Path) -> Self {
        match self {
            Error::Parse {
                path: None,
                format,
                location,
                message,
            } => Error::Parse {
                path: Some(p.to_path_buf()),
                format,
                location,
                message,
            },
            Error::InvalidMesh {
                path: None,
                problem,
            } => Error::InvalidMesh {
                path: Some(p.to_path_buf()),
                problem,
            },
            Error::IndexOutOfRange {
                path: None,
                line,
                index,
                n_vertices,
            } => Error::IndexOutOfRange {
                path: Some(p.to_path_buf()),
                line,
                index,
                n_vertices,
            },
            other => other,
        }
    }

    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Builds a parse error without a path (the caller adds it).
pub(crate) fn parse_err(
    format: &'static str,
    location: Location,
    message: impl Into<String>,
) -> Error {
    Error::Parse {
        path: None,
        format,
        location,
        message: message.into(),
    }
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
