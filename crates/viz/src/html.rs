//! A map as one self-contained HTML page: both shapes side by side in
//! WebGL, turning together under the mouse, with the colour transfer, a
//! checkerboard texture transfer, the per-vertex error (when given) and
//! picking (click a point on A, see its image on B). The meshes, the map
//! and the viewer's script are inside the page, so it opens offline, from
//! disk or from an e-mail.
//!
//! ```
//! use fmaps_viz::html::{Scene, Surface, viewer_html};
//! let mesh = fmaps_shapes::icosphere(1.0, 2);
//! let identity: Vec<usize> = (0..mesh.n_vertices()).collect();
//! let page = viewer_html(&Scene {
//!     title: "a sphere onto itself",
//!     a: Surface { name: "A", vertices: mesh.vertices(), faces: mesh.faces() },
//!     b: Surface { name: "B", vertices: mesh.vertices(), faces: mesh.faces() },
//!     map_ab: &identity,
//!     error: None,
//!     up: fmaps_viz::Axis::Y,
//! })?;
//! assert!(page.starts_with("<!DOCTYPE html>") && !page.contains("http"));
//! # Ok::<(), fmaps_viz::Error>(())
//! ```

use crate::{Axis, Error, Result, check_colored_mesh};

/// One shape of a [`Scene`].
#[derive(Debug, Clone, Copy)]
pub struct Surface<'a> {
    /// Its name, shown above it (a file name, say).
    pub name: &'a str,
    /// Vertex positions.
    pub vertices: &'a [[f64; 3]],
    /// Triangles (0-based vertex indices).
    pub faces: &'a [[usize; 3]],
}

/// What the page shows.
#[derive(Debug, Clone, Copy)]
pub struct Scene<'a> {
    /// The page's title.
    pub title: &'a str,
    /// The source shape A.
    pub a: Surface<'a>,
    /// The target shape B.
    pub b: Surface<'a>,
    /// For each vertex of A, the vertex of B it goes to.
    pub map_ab: &'a [usize],
    /// A value per vertex of A for the error view (NaN: none, drawn grey)
    /// and the value at the top of its colour scale; `None`: no error
    /// view.
    pub error: Option<(&'a [f64], f64)>,
    /// The shapes' vertical axis.
    pub up: Axis,
}

const SCRIPT: &str = include_str!("viewer.js");

/// The page of `scene`: HTML with the data (base64 little-endian float32
/// and uint32 arrays) and the viewer's script inline. Errors: faces that
/// refer to missing vertices, a map of the wrong length or into missing
/// vertices, an error array of the wrong length, meshes above 2^32
/// vertices.
pub fn viewer_html(scene: &Scene<'_>) -> Result<String> {
    let (a, b) = (&scene.a, &scene.b);
    check_surface(a)?;
    check_surface(b)?;
    if scene.map_ab.len() != a.vertices.len() {
        return Err(Error::Size {
            what: "map entries (one per vertex of A)",
            found: scene.map_ab.len(),
            expected: a.vertices.len(),
        });
    }
    if let Some(&j) = scene.map_ab.iter().find(|&&j| j >= b.vertices.len()) {
        return Err(Error::Size {
            what: "map entry (a vertex of B)",
            found: j,
            expected: b.vertices.len(),
        });
    }
    let error = match scene.error {
        Some((e, vmax)) => {
            if e.len() != a.vertices.len() {
                return Err(Error::Size {
                    what: "error values (one per vertex of A)",
                    found: e.len(),
                    expected: a.vertices.len(),
                });
            }
            let vmax = if vmax.is_finite() && vmax > 0.0 {
                vmax
            } else {
                1.0
            };
            format!(
                "\"{}\", \"error_max\": {vmax}",
                base64(e.iter().flat_map(|&x| (x as f32).to_le_bytes()))
            )
        }
        None => "null".to_string(),
    };
    let data = format!(
        "{{\"a\": {}, \"b\": {}, \"map_ab\": \"{}\", \"error\": {error}, \"up\": {}}}",
        surface_json(a),
        surface_json(b),
        base64(scene.map_ab.iter().flat_map(|&i| (i as u32).to_le_bytes())),
        up_index(scene.up)
    );
    Ok(page(scene.title, &data))
}

/// One mesh on its own as a page: turning, zooming, picking a vertex.
///
/// ```
/// use fmaps_viz::html::{Surface, mesh_html};
/// let mesh = fmaps_shapes::icosphere(1.0, 1);
/// let surface = Surface { name: "sphere", vertices: mesh.vertices(), faces: mesh.faces() };
/// let page = mesh_html("a sphere", surface, fmaps_viz::Axis::Y)?;
/// assert!(page.contains("\"b\": null"));
/// # Ok::<(), fmaps_viz::Error>(())
/// ```
pub fn mesh_html(title: &str, mesh: Surface<'_>, up: Axis) -> Result<String> {
    check_surface(&mesh)?;
    let data = format!(
        "{{\"a\": {}, \"b\": null, \"map_ab\": null, \"error\": null, \"up\": {}}}",
        surface_json(&mesh),
        up_index(up)
    );
    Ok(page(title, &data))
}

fn up_index(up: Axis) -> u8 {
    match up {
        Axis::X => 0,
        Axis::Y => 1,
        Axis::Z => 2,
    }
}

/// Faces within the vertices, indices that fit in 32 bits.
fn check_surface(s: &Surface<'_>) -> Result<()> {
    check_colored_mesh(s.vertices, s.faces, &vec![[0u8; 3]; s.vertices.len()])?;
    if s.vertices.len() > u32::MAX as usize {
        return Err(Error::Size {
            what: "vertices (the viewer indexes them with 32 bits)",
            found: s.vertices.len(),
            expected: u32::MAX as usize,
        });
    }
    Ok(())
}

/// A surface as the page's JSON: name, base64 float32 vertices, base64
/// uint32 faces.
fn surface_json(s: &Surface<'_>) -> String {
    format!(
        "{{\"name\": \"{}\", \"vertices\": \"{}\", \"faces\": \"{}\"}}",
        json_escape(s.name),
        base64(
            s.vertices
                .iter()
                .flatten()
                .flat_map(|&x| (x as f32).to_le_bytes())
        ),
        base64(
            s.faces
                .iter()
                .flatten()
                .flat_map(|&i| (i as u32).to_le_bytes())
        )
    )
}

/// The page around the data (a JSON object) and the viewer's script.
fn page(title: &str, data: &str) -> String {
    let title = html_escape(title);
    format!(
        r#"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="fmaps {version}">
<title>{title}</title>
<style>
  body {{ margin: 0; font: 14px system-ui, sans-serif; color: #222; background: #fff; }}
  header {{ display: flex; flex-wrap: wrap; gap: 8px; align-items: center; padding: 8px 12px; }}
  h1 {{ font-size: 16px; margin: 0 12px 0 0; }}
  button {{ font: inherit; padding: 3px 10px; border: 1px solid #888; background: #f4f4f4; border-radius: 4px; cursor: pointer; }}
  button.on {{ background: #333; color: #fff; }}
  button:disabled {{ opacity: 0.4; cursor: default; }}
  .names {{ display: flex; }}
  .names div {{ flex: 1; text-align: center; color: #555; }}
  #view {{ display: block; width: 100%; height: calc(100vh - 110px); min-height: 200px; touch-action: none; }}
  #legend {{ display: inline-block; width: 160px; height: 12px; vertical-align: middle;
    background: linear-gradient(to right, #440154, #414487, #2a788e, #22a884, #7ad151, #fde725); }}
  footer {{ padding: 4px 12px; color: #555; }}
  #errors {{ color: #b00; margin: 0; }}
</style>
</head>
<body>
<header>
  <h1>{title}</h1>
  <button data-mode="color">colour transfer</button>
  <button data-mode="texture">texture transfer</button>
  <button data-mode="error">error on A</button>
  <span id="legend-box" style="display:none">0 <span id="legend"></span> <span id="legend-max"></span></span>
  <span id="picked"></span>
</header>
<div class="names"><div id="name-a"></div><div id="name-b"></div></div>
<canvas id="view"></canvas>
<footer><span id="status" data-state="loading">Loading...</span><pre id="errors"></pre></footer>
<script type="application/json" id="fmaps-data">{data}</script>
<script>
{SCRIPT}
</script>
</body>
</html>
"#,
        version = env!("CARGO_PKG_VERSION"),
    )
}

/// Standard base64 (RFC 4648, with padding).
fn base64(bytes: impl Iterator<Item = u8>) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let bytes: Vec<u8> = bytes.collect();
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ABC[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// `s` inside a JSON string inside a `<script>` element: quotes,
/// backslashes, control characters and `<` escaped.
fn json_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '<' => out.push_str("\\u003c"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out
}

/// `s` as HTML text.
fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_the_rfc_4648_test_vectors() {
        for (plain, coded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.bytes()), coded);
        }
    }

    #[test]
    fn names_cannot_close_the_script_element() {
        assert_eq!(
            json_escape("a</script>\"\\\n"),
            "a\\u003c/script>\\\"\\\\\\u000a"
        );
        assert_eq!(html_escape("<b>&\""), "&lt;b&gt;&amp;&quot;");
    }

    #[test]
    fn bad_maps_and_error_arrays_are_refused() {
        let v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let f = [[0, 1, 2]];
        let s = Surface {
            name: "t",
            vertices: &v,
            faces: &f,
        };
        let scene = |map: &'static [usize], error| Scene {
            title: "t",
            a: s,
            b: s,
            map_ab: map,
            error,
            up: Axis::Y,
        };
        assert!(viewer_html(&scene(&[0, 1, 2], None)).is_ok());
        assert!(viewer_html(&scene(&[0, 1], None)).is_err());
        assert!(viewer_html(&scene(&[0, 1, 3], None)).is_err());
        assert!(viewer_html(&scene(&[0, 1, 2], Some((&[0.0][..], 1.0)))).is_err());
        let bad_face = [[0, 1, 5]];
        let bad = Scene {
            a: Surface {
                faces: &bad_face,
                ..s
            },
            ..scene(&[0, 1, 2], None)
        };
        assert!(viewer_html(&bad).is_err());
    }
}
