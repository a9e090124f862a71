//! ASCII OFF (Object File Format).

use std::io::{self, Write};

use crate::TriMesh;
use crate::error::{Error, Location, MeshProblem, Result, parse_err};
use crate::text::{content_lines, coord, fan};

const FMT: &str = "OFF";

/// Parses an ASCII OFF file.
///
/// Accepts `#` comments and blank lines anywhere, the vertex and face counts
/// on the header line (`OFF 8 12 0`) or on the next line, the `C`, `N` and
/// `ST` header variants (extra per-vertex columns such as colours, normals
/// or texture coordinates are ignored, as are per-face colours after the
/// indices), and polygons, which are fan-triangulated. Each vertex and each
/// face is on its own line; data after the declared faces is an error (a
/// wrong face count), as is a file written on one line.
///
/// Errors give the 1-based line: a missing or unsupported header, counts
/// that are not numbers, a vertex with fewer than 3 coordinates or a
/// non-finite one, a face with fewer than 3 vertices or an index that is
/// negative or out of range, and a file that ends before the declared
/// counts.
pub fn parse_off(data: &[u8]) -> Result<TriMesh> {
    let mut lines = content_lines(data, FMT);

    let (hline, header) = next(&mut lines, || "the OFF header".into())?;
    let mut toks = header.split_ascii_whitespace();
    let keyword = toks.next().unwrap_or("");
    check_keyword(keyword, hline)?;
    let rest: Vec<&str> = toks.collect();
    let (cline, counts) = if rest.is_empty() {
        let (l, t) = next(&mut lines, || "the vertex and face counts".into())?;
        (l, t.split_ascii_whitespace().collect())
    } else {
        (hline, rest)
    };
    if counts.len() > 3 {
        return Err(parse_err(
            FMT,
            Location::Line(cline),
            format!(
                "{} values where the vertex, face and edge counts belong: OFF puts the counts, each vertex and each face on a line of its own",
                counts.len()
            ),
        ));
    }
    if counts.len() < 2 {
        return Err(parse_err(
            FMT,
            Location::Line(cline),
            "expected the vertex, face and edge counts",
        ));
    }
    let count = |tok: &str, what: &str| -> Result<usize> {
        tok.parse::<usize>().map_err(|_| {
            parse_err(
                FMT,
                Location::Line(cline),
                format!("the {what} count '{tok}' is not a non-negative integer"),
            )
        })
    };
    let nv = count(counts[0], "vertex")?;
    let nf = count(counts[1], "face")?;
    if nv == 0 || nf == 0 {
        return Err(Error::InvalidMesh {
            path: None,
            problem: MeshProblem::Empty {
                n_vertices: nv,
                n_faces: nf,
            },
        });
    }

    // Never trust the declared counts for allocation: a corrupt header must
    // not make us reserve gigabytes. Each vertex needs at least 6 bytes.
    let mut vertices = Vec::with_capacity(nv.min(data.len() / 6 + 1));
    for v in 0..nv {
        let (line, text) = next(&mut lines, || format!("vertex {v} of {nv}"))?;
        let mut toks = text.split_ascii_whitespace();
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

    let mut faces = Vec::with_capacity(nf.min(data.len() / 8 + 1));
    let mut poly = Vec::new();
    for f in 0..nf {
        let (line, text) = next(&mut lines, || format!("face {f} of {nf}"))?;
        let mut toks = text.split_ascii_whitespace();
        let c_tok = toks.next().unwrap_or("");
        let c: usize = c_tok.parse().map_err(|_| {
            parse_err(
                FMT,
                Location::Line(line),
                format!("face {f}: the vertex count '{c_tok}' is not a non-negative integer"),
            )
        })?;
        if c < 3 {
            return Err(parse_err(
                FMT,
                Location::Line(line),
                format!("face {f} has {c} vertices; a face needs at least 3"),
            ));
        }
        poly.clear();
        for j in 0..c {
            let tok = toks.next().ok_or_else(|| {
                parse_err(
                    FMT,
                    Location::Line(line),
                    format!("face {f} declares {c} vertices but lists {j}"),
                )
            })?;
            poly.push(vertex_index(tok, nv, line, f)?);
        }
        fan(&poly, &mut faces);
    }
    // Data past the declared faces is a wrong count, not a comment.
    if let Some(item) = lines.next() {
        let (line, _) = item?;
        return Err(parse_err(
            FMT,
            Location::Line(line),
            format!("more data after the {nf} faces the header declares (a wrong face count?)"),
        ));
    }
    TriMesh::new(vertices, faces)
}

/// The next content line, or an error saying what the file ends before.
pub(crate) fn next<'a>(
    lines: &mut impl Iterator<Item = Result<(usize, &'a str)>>,
    what: impl FnOnce() -> String,
) -> Result<(usize, &'a str)> {
    match lines.next() {
        Some(r) => r,
        None => Err(parse_err(
            FMT,
            Location::End,
            format!("file ends before {}", what()),
        )),
    }
}

fn check_keyword(keyword: &str, line: usize) -> Result<()> {
    let Some(prefix) = keyword.strip_suffix("OFF") else {
        return Err(parse_err(
            FMT,
            Location::Line(line),
            format!("expected the 'OFF' header, found '{keyword}'"),
        ));
    };
    let mut p = prefix.strip_prefix("ST").unwrap_or(prefix);
    p = p.strip_prefix('C').unwrap_or(p);
    p = p.strip_prefix('N').unwrap_or(p);
    if !p.is_empty() {
        return Err(parse_err(
            FMT,
            Location::Line(line),
            format!("unsupported OFF variant '{keyword}' (only 3D [ST][C][N]OFF is read)"),
        ));
    }
    Ok(())
}

pub(crate) fn vertex_index(tok: &str, nv: usize, line: usize, face: usize) -> Result<usize> {
    match tok.parse::<i64>() {
        Ok(i) if i < 0 => Err(parse_err(
            FMT,
            Location::Line(line),
            format!("face {face} has a negative vertex index {i}"),
        )),
        Ok(i) if (i as u64) >= nv as u64 => Err(parse_err(
            FMT,
            Location::Line(line),
            format!(
                "face {face} refers to vertex {i}, but the file has {nv} vertices (indices are 0-based)"
            ),
        )),
        Ok(i) => Ok(i as usize),
        Err(_) => Err(parse_err(
            FMT,
            Location::Line(line),
            format!("face {face}: '{tok}' is not a vertex index"),
        )),
    }
}

/// Writes a mesh as ASCII OFF. Coordinates are written in the shortest
/// decimal form that reads back to the same `f64`, so write-then-read is
/// exact.
pub fn write_off<W: Write>(w: &mut W, mesh: &TriMesh) -> io::Result<()> {
    writeln!(w, "OFF")?;
    writeln!(w, "{} {} 0", mesh.n_vertices(), mesh.n_faces())?;
    for p in mesh.vertices() {
        writeln!(w, "{:?} {:?} {:?}", p[0], p[1], p[2])?;
    }
    for f in mesh.faces() {
        writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
    }
    Ok(())
}
