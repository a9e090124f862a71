//! Shapes and maps on screen: the interactive viewer page
//! (`fmaps_viz::html`) for browsers and notebooks (`_repr_html_`, inside
//! an iframe so that several outputs do not clash), and a PNG for
//! front-ends without scripts (`_repr_png_`).

use std::path::PathBuf;

use fmaps::mesh_io::TriMesh;
use fmaps::viz::html::{Scene, Surface, mesh_html, viewer_html};
use fmaps::viz::{Axis, View};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::{Mesh, err};

/// `up` as an axis ("x", "y", "z").
pub(crate) fn axis(up: &str) -> PyResult<Axis> {
    match up {
        "x" => Ok(Axis::X),
        "y" => Ok(Axis::Y),
        "z" => Ok(Axis::Z),
        other => Err(err(format!(
            "up = {other:?}: expected \"x\", \"y\" or \"z\""
        ))),
    }
}

fn surface<'a>(name: &'a str, m: &'a TriMesh) -> Surface<'a> {
    Surface {
        name,
        vertices: m.vertices(),
        faces: m.faces(),
    }
}

/// The page inside an iframe (its own document: the notebook's page and
/// other outputs stay apart), as notebooks display HTML.
pub(crate) fn iframe(page: &str) -> String {
    let escaped = page
        .replace('&', "&amp;")
        .replace('"', "&quot;")
        .replace('<', "&lt;")
        .replace('>', "&gt;");
    format!(
        "<iframe srcdoc=\"{escaped}\" sandbox=\"allow-scripts\" \
         style=\"width: 100%; height: 560px; border: 1px solid #ddd;\"></iframe>"
    )
}

/// A mesh's page.
pub(crate) fn mesh_page(m: &TriMesh) -> PyResult<String> {
    let title = format!(
        "Mesh ({} vertices, {} faces)",
        m.n_vertices(),
        m.faces().len()
    );
    mesh_html(&title, surface("mesh", m), Axis::Y).map_err(err)
}

/// A map's page.
pub(crate) fn map_page(
    title: &str,
    a: &TriMesh,
    b: &TriMesh,
    map_ab: &[usize],
    error: Option<(&[f64], f64)>,
    up: Axis,
) -> PyResult<String> {
    viewer_html(&Scene {
        title,
        a: surface("A", a),
        b: surface("B", b),
        map_ab,
        error,
        up,
    })
    .map_err(err)
}

/// A mesh drawn coloured by position, as PNG bytes.
pub(crate) fn mesh_png<'py>(py: Python<'py>, m: &TriMesh) -> PyResult<Bound<'py, PyBytes>> {
    let colors = fmaps::viz::position_colors(m.vertices());
    let view = View {
        width: 320,
        height: 320,
        ..View::default()
    };
    let png = fmaps::viz::render(m.vertices(), m.faces(), &colors, &view)
        .and_then(|img| img.to_png())
        .map_err(err)?;
    Ok(PyBytes::new(py, &png))
}

/// The colour transfer of a map, as PNG bytes.
pub(crate) fn map_png<'py>(
    py: Python<'py>,
    a: &TriMesh,
    b: &TriMesh,
    map_ab: &[usize],
) -> PyResult<Bound<'py, PyBytes>> {
    let view = View {
        width: 320,
        height: 320,
        ..View::default()
    };
    let png = fmaps::pictures::color_transfer(a, b, map_ab, &view)
        .and_then(|(img, _, _)| img.to_png())
        .map_err(err)?;
    Ok(PyBytes::new(py, &png))
}

/// The interactive viewer as one self-contained HTML page (no network at
/// view time): with `b` and `map_ab`, both shapes side by side turning
/// together, colour and texture transfer, `error` (one value per vertex
/// of A, NaN for none; `error_max` at the top of the scale) and picking
/// (click a point on A, see its image on B); without, `a` alone. Returns
/// the page, and with `path` writes it there (atomically).
#[pyfunction]
#[pyo3(name = "viewer_html", signature = (a, b = None, map_ab = None, *, error = None, error_max = 0.1, up = "y", title = None, path = None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn viewer_html_py(
    a: &Mesh,
    b: Option<&Mesh>,
    map_ab: Option<Bound<'_, PyAny>>,
    error: Option<Bound<'_, PyAny>>,
    error_max: f64,
    up: &str,
    title: Option<String>,
    path: Option<PathBuf>,
) -> PyResult<String> {
    let up = axis(up)?;
    let page = match (b, map_ab) {
        (Some(b), Some(m)) => {
            let (na, nb) = (a.inner.n_vertices(), b.inner.n_vertices());
            let t_ab = crate::map_between(&m, na, nb, "map_ab")?;
            let e = error
                .map(|e| {
                    let e = crate::convert::floats1(&e, "error")?;
                    let v: Vec<f64> = e.as_array().iter().copied().collect();
                    if v.len() != na {
                        return Err(err(format!(
                            "error has {} entries, A has {na} vertices",
                            v.len()
                        )));
                    }
                    Ok(v)
                })
                .transpose()?;
            let title = title.unwrap_or_else(|| "A \u{2192} B".to_string());
            map_page(
                &title,
                &a.inner,
                &b.inner,
                &t_ab,
                e.as_deref().map(|e| (e, error_max)),
                up,
            )?
        }
        (None, None) => {
            if error.is_some() {
                return Err(err("error is drawn on A of a map: give b and map_ab"));
            }
            let t = title.unwrap_or_else(|| "mesh".to_string());
            mesh_html(&t, surface("mesh", &a.inner), up).map_err(err)?
        }
        _ => return Err(err("give both b and map_ab, or neither")),
    };
    if let Some(p) = &path {
        fmaps::mesh_io::atomic::write_atomically(p, |w| w.write_all(page.as_bytes()))
            .map_err(|e| err(format!("{}: {e}", p.display())))?;
    }
    Ok(page)
}
