//! Triangle meshes for shape matching: readers and writers for OFF, OBJ and
//! PLY with errors that name the file and line, the `.vts`/`.map`
//! correspondence files of the shape-matching benchmarks, and a validation
//! report (degenerate and duplicate faces, non-manifold elements, boundary
//! loops, components, genus).
//!
//! Indices are 0-based everywhere in this API. The benchmark files `.vts`
//! and `.map` are 1-based by convention; they are converted here, on the way
//! in and out, and nowhere else.
//!
//! ```
//! use fmaps_mesh_io::{parse_off, write_off, TriMesh};
//!
//! let text = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
//! let mesh = parse_off(text.as_bytes())?;
//! assert_eq!((mesh.n_vertices(), mesh.n_faces()), (4, 4));
//!
//! let report = mesh.validate();
//! assert!(report.is_closed_manifold());
//! assert_eq!(report.euler_characteristic, 2);
//! assert_eq!(report.genus, Some(0));
//!
//! let mut bytes = Vec::new();
//! write_off(&mut bytes, &mesh).expect("writing to a Vec cannot fail");
//! assert_eq!(parse_off(&bytes)?, mesh);
//! # Ok::<(), fmaps_mesh_io::Error>(())
//! ```
//!
//! # Formats
//!
//! | format | read | write |
//! | --- | --- | --- |
//! | OFF | ASCII; `#` comments, blank lines, counts on the header line or the next, `C`/`N`/`ST` variants (extra columns ignored), polygons fan-triangulated | ASCII, shortest round-trip decimal |
//! | PLY | ASCII, binary little and big endian; any scalar type for `x y z`; any list type for `vertex_indices`/`vertex_index`; other properties and elements skipped; polygons fan-triangulated | binary little endian, `double` coordinates |
//! | OBJ | `v` and `f` (with `v/vt/vn`, negative relative indices), polygons fan-triangulated, everything else ignored; **vertex order preserved** | ASCII |
//!
//! OBJ is parsed here rather than with `tobj` because `tobj` renumbers
//! vertices in order of first use and drops unreferenced ones, which breaks
//! `.vts` ground truth that indexes the file's vertex order; it also reports
//! no line numbers. The tests check this reader against `tobj` on geometry.
//!
//! # Features
//!
//! - `serde`: derives `Serialize` for [`MeshReport`].
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod arrays;
pub mod atomic;
pub mod basis;
mod corres;
mod error;
pub mod npy;
pub mod npz;
mod obj;
mod off;
pub mod operators;
mod ply;
mod validate;
pub mod vec3;

use std::fs;
use std::path::Path;

use vec3::{cross, norm, sub};

pub use corres::{
    Landmarks, check_indices, parse_index_list, parse_landmarks, read_landmarks, read_map,
    read_vts, write_index_list, write_map, write_vts,
};
pub use error::{Error, Location, MeshProblem, Result};
pub use obj::{parse_obj, write_obj};
pub use off::{parse_off, write_off};
pub use ply::{parse_ply, write_colored_ply, write_ply};
pub use validate::MeshReport;

/// A triangle mesh: vertex positions and triangles of 0-based vertex indices.
///
/// Invariants (checked by [`TriMesh::new`] and by every reader): at least
/// one vertex and one face, all coordinates finite, every face index smaller
/// than the number of vertices. Faces may still be degenerate or duplicated;
/// [`TriMesh::validate`] reports those.
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    vertices: Vec<[f64; 3]>,
    faces: Vec<[usize; 3]>,
}

impl TriMesh {
    /// Builds a mesh from vertex positions and triangles, checking the
    /// invariants of the type.
    pub fn new(vertices: Vec<[f64; 3]>, faces: Vec<[usize; 3]>) -> Result<Self> {
        if vertices.is_empty() || faces.is_empty() {
            return Err(Error::InvalidMesh {
                path: None,
                problem: MeshProblem::Empty {
                    n_vertices: vertices.len(),
                    n_faces: faces.len(),
                },
            });
        }
        for (vertex, p) in vertices.iter().enumerate() {
            if let Some(&value) = p.iter().find(|c| !c.is_finite()) {
                return Err(Error::InvalidMesh {
                    path: None,
                    problem: MeshProblem::NonFiniteVertex { vertex, value },
                });
            }
        }
        let n_vertices = vertices.len();
        for (face, f) in faces.iter().enumerate() {
            if let Some(&index) = f.iter().find(|&&i| i >= n_vertices) {
                return Err(Error::InvalidMesh {
                    path: None,
                    problem: MeshProblem::FaceIndexOutOfRange {
                        face,
                        index,
                        n_vertices,
                    },
                });
            }
        }
        Ok(Self { vertices, faces })
    }

    /// Vertex positions (n x 3).
    pub fn vertices(&self) -> &[[f64; 3]] {
        &self.vertices
    }

    /// Triangles as 0-based vertex indices, counter-clockwise seen from
    /// outside for a consistently oriented mesh.
    pub fn faces(&self) -> &[[usize; 3]] {
        &self.faces
    }

    /// Number of vertices.
    pub fn n_vertices(&self) -> usize {
        self.vertices.len()
    }

    /// Number of triangles.
    pub fn n_faces(&self) -> usize {
        self.faces.len()
    }

    /// Gives back the vertex and face arrays.
    pub fn into_parts(self) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
        (self.vertices, self.faces)
    }

    /// Area of every triangle (half the norm of the edge cross product).
    pub fn face_areas(&self) -> Vec<f64> {
        self.faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| self.vertices[i]);
                0.5 * norm(cross(sub(b, a), sub(c, a)))
            })
            .collect()
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        self.face_areas().iter().sum()
    }

    /// The mesh with every coordinate multiplied by `factor` (same faces).
    /// Errors when `factor` is not finite and positive or a coordinate
    /// leaves the finite range.
    pub fn scaled(&self, factor: f64) -> Result<TriMesh> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(Error::InvalidScale(factor));
        }
        let v = self
            .vertices
            .iter()
            .map(|p| p.map(|c| c * factor))
            .collect();
        TriMesh::new(v, self.faces.clone())
    }

    /// The mesh scaled to unit area, and the factor every coordinate was
    /// multiplied by (`1/√area`). The coordinates are first scaled by a
    /// power of two (exact) to a largest magnitude in [1, 2), so the area
    /// neither overflows nor underflows for any finite coordinates:
    /// meshes in units of 1e300 or 1e-300 come out as in metres.
    ///
    /// Errors: a mesh of zero area ([`MeshProblem::ZeroArea`]).
    ///
    /// ```
    /// use fmaps_mesh_io::TriMesh;
    /// // A right triangle of area 2e6 (in millimetres, say).
    /// let t = TriMesh::new(vec![[0.0; 3], [2000.0, 0.0, 0.0], [0.0, 2000.0, 0.0]], vec![[0, 1, 2]])?;
    /// let (unit, factor) = t.to_unit_area()?;
    /// assert!((unit.area() - 1.0).abs() < 1e-15);
    /// assert!((factor - 1.0 / 2e6f64.sqrt()).abs() < 1e-18);
    /// # Ok::<(), fmaps_mesh_io::Error>(())
    /// ```
    pub fn to_unit_area(&self) -> Result<(TriMesh, f64)> {
        let invalid = |problem| Error::InvalidMesh {
            path: None,
            problem,
        };
        let extent = self
            .vertices
            .iter()
            .flatten()
            .fold(0.0f64, |m, c| m.max(c.abs()));
        if extent == 0.0 {
            return Err(invalid(MeshProblem::ZeroArea));
        }
        let pre = 2f64.powi(-(extent.log2().floor() as i32));
        if !pre.is_finite() || pre == 0.0 {
            return Err(invalid(MeshProblem::ExtentOutOfRange { extent }));
        }
        let pre_mesh = self.scaled(pre)?;
        let area = pre_mesh.area();
        if !(area.is_finite() && area > 0.0) {
            return Err(invalid(MeshProblem::ZeroArea));
        }
        let s = 1.0 / area.sqrt();
        Ok((pre_mesh.scaled(s)?, pre * s))
    }

    /// Checks the mesh and returns a report of its combinatorics and defects.
    pub fn validate(&self) -> MeshReport {
        validate::report(self)
    }

    /// The face on the other side of every edge (see [`FaceAdjacency`]).
    pub fn face_adjacency(&self) -> FaceAdjacency {
        let faces = &self.faces;
        // Pair half-edges through a sort of (min, max, face, k).
        let mut half: Vec<(usize, usize, usize, usize)> = Vec::with_capacity(3 * faces.len());
        for (fi, f) in faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (f[(k + 1) % 3], f[(k + 2) % 3]);
                half.push((a.min(b), a.max(b), fi, k));
            }
        }
        half.sort_unstable();
        let mut across = vec![[None; 3]; faces.len()];
        let mut non_manifold_edges = Vec::new();
        let mut i = 0;
        while i < half.len() {
            let mut j = i + 1;
            while j < half.len() && half[j].0 == half[i].0 && half[j].1 == half[i].1 {
                j += 1;
            }
            match j - i {
                1 => {}
                2 => {
                    let (x, y) = (half[i], half[i + 1]);
                    across[x.2][x.3] = Some((y.2, y.3));
                    across[y.2][y.3] = Some((x.2, x.3));
                }
                _ => non_manifold_edges.push([half[i].0, half[i].1]),
            }
            i = j;
        }
        FaceAdjacency {
            across,
            non_manifold_edges,
        }
    }
}

/// Faces across edges. Edge `k` of face `f` is the edge opposite corner
/// `k`, from corner `k+1` to corner `k+2`.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct FaceAdjacency {
    /// `across[f][k]`: the other face of edge k of face f and the index of
    /// that edge there; `None` on boundary and non-manifold edges.
    pub across: Vec<[Option<(usize, usize)>; 3]>,
    /// Edges with more than two faces, as `[min, max]` vertex pairs.
    pub non_manifold_edges: Vec<[usize; 2]>,
}

/// The mesh formats this crate reads and writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Format {
    /// Object File Format (ASCII).
    Off,
    /// Wavefront OBJ.
    Obj,
    /// Stanford PLY.
    Ply,
}

impl Format {
    /// The format a path's extension names (case-insensitive).
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("off") => Ok(Format::Off),
            Some("obj") => Ok(Format::Obj),
            Some("ply") => Ok(Format::Ply),
            _ => Err(Error::UnknownFormat {
                path: path.to_path_buf(),
                ext,
            }),
        }
    }
}

/// Parses mesh bytes in the given format.
pub fn parse_mesh(data: &[u8], format: Format) -> Result<TriMesh> {
    match format {
        Format::Off => parse_off(data),
        Format::Obj => parse_obj(data),
        Format::Ply => parse_ply(data),
    }
}

/// The most bytes read from one input file: 256 MiB, about 5 million
/// vertices of ASCII OFF or 10 million of binary PLY, beyond what the
/// pipeline matches on one machine, and small enough that the parsed mesh
/// (a few times the file at most) stays well within memory. Larger files,
/// and devices or pipes that do not end (such as `/dev/zero`), are refused
/// with [`Error::TooLarge`] after reading at most this much.
pub const MAX_INPUT_BYTES: u64 = (1 << 28) - 1;

/// Reads a whole input file, at most `limit` bytes ([`MAX_INPUT_BYTES`] for
/// every reader of this crate): a regular file larger than that is refused
/// before reading, anything else (a pipe, a device) after reading `limit`
/// bytes. Never allocates more than `limit` + 1 bytes.
pub fn read_bounded(path: impl AsRef<Path>, limit: u64) -> Result<Vec<u8>> {
    use std::io::Read;
    let path = path.as_ref();
    let file = fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    let too_large = || Error::TooLarge {
        path: path.to_path_buf(),
        limit,
    };
    if meta.is_file() && meta.len() > limit {
        return Err(too_large());
    }
    let hint = if meta.is_file() { meta.len() } else { 0 };
    let mut data = Vec::with_capacity(usize::try_from(hint.min(limit)).unwrap_or(0) + 1);
    file.take(limit.saturating_add(1))
        .read_to_end(&mut data)
        .map_err(|e| Error::io(path, e))?;
    if data.len() as u64 > limit {
        return Err(too_large());
    }
    Ok(data)
}

/// Reads a mesh file, choosing the format from its extension
/// (`.off`, `.obj`, `.ply`). Errors name the file.
pub fn read_mesh(path: impl AsRef<Path>) -> Result<TriMesh> {
    let path = path.as_ref();
    let format = Format::from_path(path)?;
    let data = read_bounded(path, MAX_INPUT_BYTES)?;
    parse_mesh(&data, format).map_err(|e| e.with_path(path))
}

/// Writes a mesh, choosing the format from the extension of `path`
/// (OFF as ASCII, PLY as binary little endian, OBJ as ASCII).
pub fn write_mesh(path: impl AsRef<Path>, mesh: &TriMesh) -> Result<()> {
    let path = path.as_ref();
    let format = Format::from_path(path)?;
    atomic::write_atomically(path, |mut w| match format {
        Format::Off => write_off(&mut w, mesh),
        Format::Obj => write_obj(&mut w, mesh),
        Format::Ply => write_ply(&mut w, mesh),
    })
    .map_err(|e| Error::io(path, e))
}

/// Writes a mesh with one colour per vertex to a PLY file
/// ([`write_colored_ply`]), whole or not at all.
pub fn save_colored_ply(path: impl AsRef<Path>, mesh: &TriMesh, colors: &[[u8; 3]]) -> Result<()> {
    let path = path.as_ref();
    atomic::write_atomically(path, |mut w| write_colored_ply(&mut w, mesh, colors))
        .map_err(|e| Error::io(path, e))
}

/// Shared helpers of the text parsers.
pub(crate) mod text {
    use crate::error::{Error, Location, parse_err};

    /// Iterates over the lines of `data` as `(1-based line number, content)`
    /// with `#` comments and surrounding whitespace removed, skipping lines
    /// that are then empty. Non-UTF-8 lines are an error.
    pub(crate) fn content_lines<'a>(
        data: &'a [u8],
        format: &'static str,
    ) -> impl Iterator<Item = Result<(usize, &'a str), Error>> + 'a {
        // A UTF-8 byte-order mark is not content; a file with carriage
        // returns but no line feed uses them as line breaks (old Mac).
        let data = strip_bom(data);
        let eol = if data.contains(&b'\n') { b'\n' } else { b'\r' };
        data.split(move |&b| b == eol)
            .enumerate()
            .filter_map(move |(i, raw)| {
                let line = i + 1;
                let text = match std::str::from_utf8(raw) {
                    Ok(t) => t,
                    Err(_) => {
                        return Some(Err(parse_err(
                            format,
                            Location::Line(line),
                            "not valid UTF-8 text (binary data in a text format?)",
                        )));
                    }
                };
                let text = text.split('#').next().unwrap_or("").trim();
                (!text.is_empty()).then_some(Ok((line, text)))
            })
    }

    /// `data` without a leading UTF-8 byte-order mark.
    pub(crate) fn strip_bom(data: &[u8]) -> &[u8] {
        data.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(data)
    }

    /// Parses a finite coordinate.
    pub(crate) fn coord(
        tok: &str,
        format: &'static str,
        line: usize,
        vertex: usize,
    ) -> Result<f64, Error> {
        let v: f64 = tok.parse().map_err(|_| {
            parse_err(
                format,
                Location::Line(line),
                format!("vertex {vertex}: '{tok}' is not a number"),
            )
        })?;
        if !v.is_finite() {
            return Err(parse_err(
                format,
                Location::Line(line),
                format!("vertex {vertex} has a non-finite coordinate '{tok}'"),
            ));
        }
        Ok(v)
    }

    /// Fan-triangulates a polygon into `out`.
    pub(crate) fn fan(poly: &[usize], out: &mut Vec<[usize; 3]>) {
        for j in 1..poly.len() - 1 {
            out.push([poly[0], poly[j], poly[j + 1]]);
        }
    }
}
