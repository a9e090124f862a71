//! Wavefront OBJ (geometry only).

use std::io::{self, Write};

use crate::TriMesh;
use crate::error::{Error, Location, MeshProblem, Result, parse_err};
use crate::text::{content_lines, coord, fan};

const FMT: &str = "OBJ";

/// Parses the geometry of a Wavefront OBJ file: `v x y z [w] [r g b]` and
/// `f` lines (`i`, `i/t`, `i//n`, `i/t/n`; negative indices count back from
/// the last vertex read). Polygons are fan-triangulated; groups, objects,
/// materials, normals, texture coordinates and lines are ignored.
///
/// Vertex order is the order of the `v` lines, so `.vts` ground truth that
/// indexes the file stays valid (this is why the crate does not use `tobj`,
/// which renumbers vertices by first use).
pub fn parse_obj(data: &[u8]) -> Result<TriMesh> {
    let mut vertices = Vec::new();
    let mut faces = Vec::new();
    let mut poly = Vec::new();
    for item in content_lines(data, FMT) {
        let (line, text) = item?;
        let mut toks = text.split_ascii_whitespace();
        match toks.next() {
            Some("v") => {
                let v = vertices.len();
                let mut p = [0.0; 3];
                for c in &mut p {
                    let tok = toks.next().ok_or_else(|| {
                        parse_err(
                            FMT,
                            Location::Line(line),
                            format!("vertex {v} has fewer than 3 coordinates"),
                        )
                    })?;
                    *c = coord(tok, FMT, line, v)?;
                }
                vertices.push(p);
            }
            Some("f") => {
                let f = faces.len();
                poly.clear();
                for tok in toks {
                    let idx = tok.split('/').next().unwrap_or("");
                    let i: i64 = idx.parse().map_err(|_| {
                        parse_err(
                            FMT,
                            Location::Line(line),
                            format!("'{tok}' is not a vertex reference"),
                        )
                    })?;
                    let nv = vertices.len() as i64;
                    let resolved = if i > 0 { i - 1 } else { nv + i };
                    if i == 0 || resolved < 0 || resolved >= nv {
                        return Err(parse_err(
                            FMT,
                            Location::Line(line),
                            format!(
                                "face refers to vertex {i}, but only {nv} vertices are defined before this line (OBJ indices are 1-based)"
                            ),
                        ));
                    }
                    poly.push(resolved as usize);
                }
                if poly.len() < 3 {
                    return Err(parse_err(
                        FMT,
                        Location::Line(line),
                        format!(
                            "face {f} has {} vertices; a face needs at least 3",
                            poly.len()
                        ),
                    ));
                }
                fan(&poly, &mut faces);
            }
            _ => {}
        }
    }
    if vertices.is_empty() || faces.is_empty() {
        return Err(Error::InvalidMesh {
            path: None,
            problem: MeshProblem::Empty {
                n_vertices: vertices.len(),
                n_faces: faces.len(),
            },
        });
    }
    TriMesh::new(vertices, faces)
}

/// Writes a mesh as OBJ (`v` and 1-based `f` lines), coordinates in the
/// shortest decimal form that reads back exactly.
pub fn write_obj<W: Write>(w: &mut W, mesh: &TriMesh) -> io::Result<()> {
    writeln!(w, "# written by fmaps-mesh-io")?;
    for p in mesh.vertices() {
        writeln!(w, "v {:?} {:?} {:?}", p[0], p[1], p[2])?;
    }
    for f in mesh.faces() {
        writeln!(w, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1)?;
    }
    Ok(())
}
