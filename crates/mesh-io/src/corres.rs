//! Correspondence files of the shape-matching benchmarks: `.vts` (a list of
//! vertex indices) and `.map` (a target vertex for every source vertex).
//! Both are 1-based on disk and 0-based in memory; this module is the only
//! place that converts.

use std::io::{self, Write};
use std::path::Path;

use crate::error::{Error, Location, Result, parse_err};

/// Parses a list of 1-based vertex indices, one per line, into 0-based
/// indices. Blank lines and `#` comments are skipped; a 0, a negative value,
/// a non-integer or two values on one line are errors naming the line.
///
/// `format` names the file kind in error messages (".vts", ".map").
pub fn parse_index_list(data: &[u8], format: &'static str) -> Result<Vec<usize>> {
    let mut out = Vec::with_capacity(data.len() / 4);
    for item in crate::text::content_lines(data, format) {
        let (line, text) = item?;
        let loc = Location::Line(line);
        let mut toks = text.split_ascii_whitespace();
        let tok = toks.next().unwrap_or("");
        if toks.next().is_some() {
            return Err(parse_err(format, loc, "expected one vertex index per line"));
        }
        let i: i64 = tok.parse().map_err(|_| {
            parse_err(
                format,
                loc,
                format!("'{tok}' is not an integer vertex index"),
            )
        })?;
        if i < 1 {
            return Err(parse_err(
                format,
                loc,
                format!("vertex index {i} is not a 1-based index (must be >= 1)"),
            ));
        }
        out.push((i - 1) as usize);
    }
    Ok(out)
}

fn read_list(path: &Path, format: &'static str) -> Result<Vec<usize>> {
    let data = crate::read_bounded(path, crate::MAX_INPUT_BYTES)?;
    parse_index_list(&data, format).map_err(|e| e.with_path(path))
}

/// Reads a `.vts` file: for line i, the 0-based vertex of this shape that is
/// ground-truth point i of the collection.
pub fn read_vts(path: impl AsRef<Path>) -> Result<Vec<usize>> {
    read_list(path.as_ref(), ".vts")
}

/// Reads a `.map` file `A_B.map`: for every vertex of A (line i), the
/// 0-based vertex of B it maps to. Check the result against the sizes of A
/// and B with [`check_indices`].
pub fn read_map(path: impl AsRef<Path>) -> Result<Vec<usize>> {
    read_list(path.as_ref(), ".map")
}

/// Landmark pairs read from a file, with the line each came from.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Landmarks {
    /// `(source vertex, target vertex)`, 0-based.
    pub pairs: Vec<(usize, usize)>,
    /// The 1-based line of each pair.
    pub lines: Vec<usize>,
}

impl Landmarks {
    /// Checks every pair against the sizes of the two shapes; the error
    /// names the line and the 1-based index as written (and `path`).
    pub fn check(&self, n_source: usize, n_target: usize, path: Option<&Path>) -> Result<()> {
        for (&(a, b), &line) in self.pairs.iter().zip(&self.lines) {
            for (v, n) in [(a, n_source), (b, n_target)] {
                if v >= n {
                    return Err(Error::IndexOutOfRange {
                        path: path.map(Path::to_path_buf),
                        line,
                        index: v.saturating_add(1),
                        n_vertices: n,
                    });
                }
            }
        }
        Ok(())
    }
}

/// Parses a landmark file: per line one pair `a b` of 1-based vertex
/// indices (source, target), or one index used on both shapes. Blank lines
/// and `#` comments are skipped; anything else is an error naming the line.
pub fn parse_landmarks(data: &[u8]) -> Result<Landmarks> {
    const FMT: &str = "landmarks";
    let mut out = Landmarks::default();
    for item in crate::text::content_lines(data, FMT) {
        let (line, text) = item?;
        let loc = Location::Line(line);
        let parse = |tok: &str| -> Result<usize> {
            match tok.parse::<u64>() {
                Ok(v) if v >= 1 && usize::try_from(v).is_ok() => Ok(v as usize - 1),
                _ => Err(parse_err(
                    FMT,
                    loc,
                    format!("'{tok}' is not a 1-based vertex index"),
                )),
            }
        };
        let toks: Vec<&str> = text.split_ascii_whitespace().take(3).collect();
        let pair = match toks.as_slice() {
            [a] => {
                let a = parse(a)?;
                (a, a)
            }
            [a, b] => (parse(a)?, parse(b)?),
            _ => {
                return Err(parse_err(
                    FMT,
                    loc,
                    "expected one or two vertex indices (source, target)",
                ));
            }
        };
        out.pairs.push(pair);
        out.lines.push(line);
    }
    Ok(out)
}

/// Reads a landmark file (see [`parse_landmarks`]); errors name the file.
pub fn read_landmarks(path: impl AsRef<Path>) -> Result<Landmarks> {
    let path = path.as_ref();
    let data = crate::read_bounded(path, crate::MAX_INPUT_BYTES)?;
    parse_landmarks(&data).map_err(|e| e.with_path(path))
}

/// Checks that every 0-based index is below `n_vertices`; the error names
/// the 1-based line and index as written in the file.
pub fn check_indices(indices: &[usize], n_vertices: usize, path: Option<&Path>) -> Result<()> {
    match indices.iter().position(|&i| i >= n_vertices) {
        None => Ok(()),
        Some(line0) => Err(Error::IndexOutOfRange {
            path: path.map(Path::to_path_buf),
            line: line0 + 1,
            index: indices[line0].saturating_add(1),
            n_vertices,
        }),
    }
}

/// Writes 0-based indices as a 1-based list, one per line. An index of
/// `usize::MAX` has no 1-based form: an `InvalidInput` error naming its
/// entry.
pub fn write_index_list<W: Write>(w: &mut W, indices: &[usize]) -> io::Result<()> {
    let mut s = String::with_capacity(indices.len() * 6);
    for (k, &i) in indices.iter().enumerate() {
        let one_based = i.checked_add(1).ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("entry {k}: index {i} has no 1-based form"),
            )
        })?;
        s.push_str(&one_based.to_string());
        s.push('\n');
    }
    w.write_all(s.as_bytes())
}

fn write_list(path: &Path, indices: &[usize]) -> Result<()> {
    crate::atomic::write_atomically(path, |mut w| write_index_list(&mut w, indices))
        .map_err(|e| Error::io(path, e))
}

/// Writes a point map (for every source vertex, a 0-based target vertex) as
/// a 1-based `.map` file.
pub fn write_map(path: impl AsRef<Path>, t_ab: &[usize]) -> Result<()> {
    write_list(path.as_ref(), t_ab)
}

/// Writes 0-based vertex indices as a 1-based `.vts` file.
pub fn write_vts(path: impl AsRef<Path>, indices: &[usize]) -> Result<()> {
    write_list(path.as_ref(), indices)
}
