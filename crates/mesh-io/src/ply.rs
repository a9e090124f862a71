//! Stanford PLY: ASCII and binary (little and big endian).

use std::fmt::Write as _;
use std::io::{self, Write};

use crate::TriMesh;
use crate::error::{Error, Location, MeshProblem, Result, parse_err};
use crate::text::fan;

const FMT: &str = "PLY";

#[derive(Debug, Clone, Copy, PartialEq)]
enum Encoding {
    Ascii,
    BinaryLe,
    BinaryBe,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Debug, Clone)]
enum Property {
    Scalar {
        name: String,
        ty: Scalar,
    },
    List {
        name: String,
        count: Scalar,
        item: Scalar,
    },
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
    line: usize,
}

/// Parses a PLY file (ASCII, `binary_little_endian` or `binary_big_endian`).
///
/// Reads the `x y z` properties of the `vertex` element (any scalar type)
/// and the `vertex_indices` (or `vertex_index`) list of the `face` element
/// (any integer count and index types). Other properties and elements are
/// skipped. Polygons are fan-triangulated.
///
/// Errors give the header or ASCII line, or the byte offset in binary data:
/// a bad header, a missing `vertex`/`face` element or property, non-finite
/// coordinates, negative or out-of-range indices, faces with fewer than 3
/// vertices, non-integer indices, and truncated data.
pub fn parse_ply(data: &[u8]) -> Result<TriMesh> {
    let data = crate::text::strip_bom(data);
    let (encoding, elements, body_start, body_line) = parse_header(data)?;
    let vidx = elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| {
            parse_err(
                FMT,
                Location::Line(1),
                "the header declares no 'vertex' element",
            )
        })?;
    let fidx = elements
        .iter()
        .position(|e| e.name == "face")
        .ok_or_else(|| {
            parse_err(
                FMT,
                Location::Line(1),
                "the header declares no 'face' element",
            )
        })?;
    let vel = &elements[vidx];
    let coord_slots: Vec<usize> = ["x", "y", "z"]
        .iter()
        .map(|want| {
            vel.props
                .iter()
                .position(|p| matches!(p, Property::Scalar { name, .. } if name == want))
                .ok_or_else(|| {
                    parse_err(
                        FMT,
                        Location::Line(vel.line),
                        format!("the 'vertex' element has no scalar property '{want}'"),
                    )
                })
        })
        .collect::<Result<_>>()?;
    let fel = &elements[fidx];
    let index_slot = fel
        .props
        .iter()
        .position(|p| matches!(p, Property::List { name, .. } if name == "vertex_indices" || name == "vertex_index"))
        .ok_or_else(|| {
            parse_err(
                FMT,
                Location::Line(fel.line),
                "the 'face' element has no list property 'vertex_indices'",
            )
        })?;
    if let Property::List { item, .. } = &fel.props[index_slot]
        && !item.is_integer()
    {
        return Err(parse_err(
            FMT,
            Location::Line(fel.line),
            "face indices must have an integer type",
        ));
    }
    let nv = vel.count;
    let nf = fel.count;
    if nv == 0 || nf == 0 {
        return Err(Error::InvalidMesh {
            path: None,
            problem: MeshProblem::Empty {
                n_vertices: nv,
                n_faces: nf,
            },
        });
    }
    // Indices are checked against the vertex count of the header, so the
    // element order does not matter.

    let mut reader: Box<dyn ValueReader> = match encoding {
        Encoding::Ascii => Box::new(AsciiReader::new(&data[body_start..], body_line)),
        Encoding::BinaryLe => Box::new(BinReader {
            data,
            pos: body_start,
            le: true,
        }),
        Encoding::BinaryBe => Box::new(BinReader {
            data,
            pos: body_start,
            le: false,
        }),
    };
    let body = &data[body_start..];
    let mut vertices = Vec::with_capacity(nv.min(body.len() / 3 + 1));
    let mut faces = Vec::with_capacity(nf.min(body.len() / 3 + 1));
    let mut values = Vec::new();
    let mut poly = Vec::new();
    for (ei, el) in elements.iter().enumerate() {
        for inst in 0..el.count {
            reader.start_instance()?;
            if ei == vidx {
                let loc = reader.location();
                values.clear();
                for p in &el.props {
                    match p {
                        Property::Scalar { ty, .. } => values.push(reader.read(*ty)?),
                        Property::List { count, item, .. } => {
                            let c = reader.read_count(*count)?;
                            for _ in 0..c {
                                reader.read(*item)?;
                            }
                            values.push(f64::NAN);
                        }
                    }
                }
                let mut pos = [0.0; 3];
                for (c, &slot) in coord_slots.iter().enumerate() {
                    let v = values[slot];
                    if !v.is_finite() {
                        return Err(parse_err(
                            FMT,
                            loc,
                            format!("vertex {inst} has a non-finite coordinate {v}"),
                        ));
                    }
                    pos[c] = v;
                }
                vertices.push(pos);
            } else if ei == fidx {
                for (pi, p) in el.props.iter().enumerate() {
                    match p {
                        Property::Scalar { ty, .. } => {
                            reader.read(*ty)?;
                        }
                        Property::List { count, item, .. } => {
                            let loc = reader.location();
                            let c = reader.read_count(*count)?;
                            if pi != index_slot {
                                for _ in 0..c {
                                    reader.read(*item)?;
                                }
                                continue;
                            }
                            if c < 3 {
                                return Err(parse_err(
                                    FMT,
                                    loc,
                                    format!(
                                        "face {inst} has {c} vertices; a face needs at least 3"
                                    ),
                                ));
                            }
                            poly.clear();
                            for _ in 0..c {
                                let loc = reader.location();
                                let v = reader.read(*item)?;
                                if v < 0.0 {
                                    return Err(parse_err(
                                        FMT,
                                        loc,
                                        format!("face {inst} has a negative vertex index {v}"),
                                    ));
                                }
                                if v >= nv as f64 {
                                    return Err(parse_err(
                                        FMT,
                                        loc,
                                        format!(
                                            "face {inst} refers to vertex {v}, but the file has {nv} vertices"
                                        ),
                                    ));
                                }
                                poly.push(v as usize);
                            }
                            fan(&poly, &mut faces);
                        }
                    }
                }
            } else {
                for p in &el.props {
                    match p {
                        Property::Scalar { ty, .. } => {
                            reader.read(*ty)?;
                        }
                        Property::List { count, item, .. } => {
                            let c = reader.read_count(*count)?;
                            for _ in 0..c {
                                reader.read(*item)?;
                            }
                        }
                    }
                }
            }
            reader.end_instance(&el.name, inst)?;
        }
    }
    reader.finish(elements.len())?;
    TriMesh::new(vertices, faces)
}

/// Returns the encoding, the elements, the byte offset of the body and the
/// 1-based line number at which the body starts.
fn parse_header(data: &[u8]) -> Result<(Encoding, Vec<Element>, usize, usize)> {
    let mut pos = 0;
    let mut line_no = 0;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        if pos >= data.len() {
            return Err(parse_err(
                FMT,
                Location::End,
                "file ends inside the header (no 'end_header')",
            ));
        }
        let end = data[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(data.len(), |e| pos + e);
        let raw = &data[pos..end];
        pos = (end + 1).min(data.len());
        line_no += 1;
        let loc = Location::Line(line_no);
        let text = std::str::from_utf8(raw)
            .map_err(|_| parse_err(FMT, loc, "the header is not valid text"))?
            .trim();
        let mut toks = text.split_ascii_whitespace();
        let key = toks.next().unwrap_or("");
        if line_no == 1 {
            if key != "ply" {
                return Err(parse_err(
                    FMT,
                    loc,
                    format!("expected 'ply' on the first line, found '{text}'"),
                ));
            }
            continue;
        }
        match key {
            "" | "comment" | "obj_info" => {}
            "format" => {
                let enc = toks.next().unwrap_or("");
                encoding = Some(match enc {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLe,
                    "binary_big_endian" => Encoding::BinaryBe,
                    _ => return Err(parse_err(FMT, loc, format!("unknown PLY format '{enc}'"))),
                });
                let ver = toks.next().unwrap_or("");
                if ver != "1.0" {
                    return Err(parse_err(
                        FMT,
                        loc,
                        format!("unsupported PLY version '{ver}' (expected 1.0)"),
                    ));
                }
            }
            "element" => {
                let name = toks
                    .next()
                    .ok_or_else(|| parse_err(FMT, loc, "element without a name"))?;
                let count_tok = toks.next().unwrap_or("");
                let count = count_tok.parse::<usize>().map_err(|_| {
                    parse_err(
                        FMT,
                        loc,
                        format!(
                            "element '{name}': count '{count_tok}' is not a non-negative integer"
                        ),
                    )
                })?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                    line: line_no,
                });
            }
            "property" => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| parse_err(FMT, loc, "property before any element"))?;
                let t = toks.next().unwrap_or("");
                let prop = if t == "list" {
                    let ct = toks.next().unwrap_or("");
                    let it = toks.next().unwrap_or("");
                    let name = toks
                        .next()
                        .ok_or_else(|| parse_err(FMT, loc, "list property without a name"))?;
                    let count = Scalar::parse(ct)
                        .filter(|s| s.is_integer())
                        .ok_or_else(|| {
                            parse_err(
                                FMT,
                                loc,
                                format!("list count type '{ct}' is not an integer type"),
                            )
                        })?;
                    let item = Scalar::parse(it)
                        .ok_or_else(|| parse_err(FMT, loc, format!("unknown type '{it}'")))?;
                    Property::List {
                        name: name.to_string(),
                        count,
                        item,
                    }
                } else {
                    let ty = Scalar::parse(t)
                        .ok_or_else(|| parse_err(FMT, loc, format!("unknown type '{t}'")))?;
                    let name = toks
                        .next()
                        .ok_or_else(|| parse_err(FMT, loc, "property without a name"))?;
                    Property::Scalar {
                        name: name.to_string(),
                        ty,
                    }
                };
                el.props.push(prop);
            }
            "end_header" => break,
            other => {
                return Err(parse_err(
                    FMT,
                    loc,
                    format!("unknown header keyword '{other}'"),
                ));
            }
        }
    }
    let encoding = encoding
        .ok_or_else(|| parse_err(FMT, Location::Line(2), "the header has no 'format' line"))?;
    Ok((encoding, elements, pos, line_no + 1))
}

/// Reads values of one element instance after another.
trait ValueReader {
    fn start_instance(&mut self) -> Result<()>;
    fn end_instance(&mut self, element: &str, inst: usize) -> Result<()>;
    fn read(&mut self, ty: Scalar) -> Result<f64>;
    fn location(&self) -> Location;
    /// Errors if data other than whitespace follows the declared elements
    /// (a wrong count in the header would otherwise drop faces silently).
    fn finish(&mut self, n_elements: usize) -> Result<()>;

    fn read_count(&mut self, ty: Scalar) -> Result<usize> {
        let loc = self.location();
        let c = self.read(ty)?;
        if c < 0.0 {
            return Err(parse_err(FMT, loc, format!("negative list length {c}")));
        }
        Ok(c as usize)
    }
}

struct BinReader<'a> {
    data: &'a [u8],
    pos: usize,
    le: bool,
}

impl ValueReader for BinReader<'_> {
    fn start_instance(&mut self) -> Result<()> {
        Ok(())
    }

    fn end_instance(&mut self, _: &str, _: usize) -> Result<()> {
        Ok(())
    }

    fn location(&self) -> Location {
        Location::Byte(self.pos)
    }

    fn finish(&mut self, n_elements: usize) -> Result<()> {
        let rest = &self.data[self.pos.min(self.data.len())..];
        match rest
            .iter()
            .position(|b| !b.is_ascii_whitespace() && *b != 0)
        {
            None => Ok(()),
            Some(_) => Err(parse_err(
                FMT,
                Location::Byte(self.pos),
                format!(
                    "{} more bytes after the {n_elements} elements the header declares (a wrong count?)",
                    rest.len()
                ),
            )),
        }
    }

    fn read(&mut self, ty: Scalar) -> Result<f64> {
        let n = ty.size();
        let Some(bytes) = self.data.get(self.pos..self.pos + n) else {
            return Err(parse_err(
                FMT,
                Location::Byte(self.pos),
                "binary data ends before all declared elements were read (truncated file)",
            ));
        };
        self.pos += n;
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(bytes);
        if self.le != cfg!(target_endian = "little") {
            b[..n].reverse();
        }
        Ok(match ty {
            Scalar::I8 => i8::from_ne_bytes([b[0]]) as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => i16::from_ne_bytes([b[0], b[1]]) as f64,
            Scalar::U16 => u16::from_ne_bytes([b[0], b[1]]) as f64,
            Scalar::I32 => i32::from_ne_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::U32 => u32::from_ne_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F32 => f32::from_ne_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F64 => f64::from_ne_bytes(b),
        })
    }
}

/// The lines of a byte slice, numbered from 0.
type NumberedLines<'a> = std::iter::Enumerate<std::slice::Split<'a, u8, fn(&u8) -> bool>>;

/// ASCII body: one element instance per (non-empty) line.
struct AsciiReader<'a> {
    lines: NumberedLines<'a>,
    first_line: usize,
    line: usize,
    toks: std::vec::IntoIter<&'a str>,
}

impl<'a> AsciiReader<'a> {
    fn new(body: &'a [u8], first_line: usize) -> Self {
        fn nl(b: &u8) -> bool {
            *b == b'\n'
        }
        Self {
            lines: body.split(nl as fn(&u8) -> bool).enumerate(),
            first_line,
            line: first_line,
            toks: Vec::new().into_iter(),
        }
    }
}

impl ValueReader for AsciiReader<'_> {
    fn start_instance(&mut self) -> Result<()> {
        loop {
            let Some((i, raw)) = self.lines.next() else {
                return Err(parse_err(
                    FMT,
                    Location::End,
                    "file ends before all declared elements were read (truncated file)",
                ));
            };
            self.line = self.first_line + i;
            let text = std::str::from_utf8(raw)
                .map_err(|_| parse_err(FMT, Location::Line(self.line), "not valid UTF-8 text"))?;
            let toks: Vec<&str> = text.split_ascii_whitespace().collect();
            if !toks.is_empty() {
                self.toks = toks.into_iter();
                return Ok(());
            }
        }
    }

    fn end_instance(&mut self, element: &str, inst: usize) -> Result<()> {
        if self.toks.len() > 0 {
            return Err(parse_err(
                FMT,
                Location::Line(self.line),
                format!("{element} {inst}: more values on the line than the header declares"),
            ));
        }
        Ok(())
    }

    fn location(&self) -> Location {
        Location::Line(self.line)
    }

    fn finish(&mut self, n_elements: usize) -> Result<()> {
        for (i, raw) in self.lines.by_ref() {
            if raw.iter().any(|b| !b.is_ascii_whitespace()) {
                return Err(parse_err(
                    FMT,
                    Location::Line(self.first_line + i),
                    format!(
                        "more data after the {n_elements} elements the header declares (a wrong count?)"
                    ),
                ));
            }
        }
        Ok(())
    }

    fn read(&mut self, ty: Scalar) -> Result<f64> {
        let loc = Location::Line(self.line);
        let tok = self.toks.next().ok_or_else(|| {
            parse_err(
                FMT,
                loc,
                "fewer values on the line than the header declares",
            )
        })?;
        if ty.is_integer() {
            tok.parse::<i64>()
                .map(|v| v as f64)
                .map_err(|_| parse_err(FMT, loc, format!("'{tok}' is not an integer")))
        } else {
            tok.parse::<f64>()
                .map_err(|_| parse_err(FMT, loc, format!("'{tok}' is not a number")))
        }
    }
}

/// Writes a mesh with one RGB colour per vertex as ASCII PLY (opens in
/// MeshLab, Blender, Open3D): `double` coordinates in the shortest
/// round-trip decimal, `uchar` red, green and blue. An `InvalidInput`
/// error when there is not one colour per vertex.
pub fn write_colored_ply<W: Write>(
    w: &mut W,
    mesh: &TriMesh,
    colors: &[[u8; 3]],
) -> io::Result<()> {
    if colors.len() != mesh.n_vertices() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "{} vertex colours for {} vertices",
                colors.len(),
                mesh.n_vertices()
            ),
        ));
    }
    let mut s = String::with_capacity(40 * (mesh.n_vertices() + mesh.n_faces()) + 256);
    let _ = write!(
        s,
        "ply\nformat ascii 1.0\ncomment written by fmaps-mesh-io\nelement vertex {}\n\
         property double x\nproperty double y\nproperty double z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.n_vertices(),
        mesh.n_faces()
    );
    for (p, c) in mesh.vertices().iter().zip(colors) {
        let _ = writeln!(s, "{} {} {} {} {} {}", p[0], p[1], p[2], c[0], c[1], c[2]);
    }
    for f in mesh.faces() {
        let _ = writeln!(s, "3 {} {} {}", f[0], f[1], f[2]);
    }
    w.write_all(s.as_bytes())
}

/// Writes a mesh as binary little-endian PLY with `double` coordinates and
/// `uchar`/`int` face lists (exact round trip).
pub fn write_ply<W: Write>(w: &mut W, mesh: &TriMesh) -> io::Result<()> {
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment written by fmaps-mesh-io\n\
         element vertex {}\nproperty double x\nproperty double y\nproperty double z\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.n_vertices(),
        mesh.n_faces()
    )?;
    let mut buf = Vec::with_capacity(mesh.n_vertices() * 24 + mesh.n_faces() * 13);
    for p in mesh.vertices() {
        for c in p {
            buf.extend_from_slice(&c.to_le_bytes());
        }
    }
    for f in mesh.faces() {
        buf.push(3);
        for &i in f {
            let i = i32::try_from(i).map_err(|_| {
                io::Error::new(
                    io::ErrorKind::InvalidInput,
                    "vertex index does not fit a PLY int",
                )
            })?;
            buf.extend_from_slice(&i.to_le_bytes());
        }
    }
    w.write_all(&buf)
}
