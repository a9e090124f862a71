//! The interactive viewer page of a map (`render transfer/error --html`,
//! `demo`): the meshes, the map and their names, as `fmaps_viz::html`
//! draws them.

use std::path::Path;

use fmaps::mesh_io::TriMesh;
use fmaps::viz::Axis;

use crate::{Failure, runtime};

/// What [`save_html`] writes: the meshes, the map and their names.
pub(crate) struct ViewerPage<'a> {
    pub(crate) title: String,
    pub(crate) names: [String; 2],
    pub(crate) meshes: [&'a TriMesh; 2],
    pub(crate) t_ab: &'a [usize],
    pub(crate) error: Option<(&'a [f64], f64)>,
    pub(crate) up: Axis,
}

/// The viewer page of a map between the meshes of two files (named by
/// their file names).
pub(crate) fn viewer_page<'a>(
    files: [&Path; 2],
    meshes: [&'a TriMesh; 2],
    t_ab: &'a [usize],
    error: Option<(&'a [f64], f64)>,
    up: Axis,
) -> ViewerPage<'a> {
    let names = files.map(|p| {
        p.file_name().map_or_else(
            || p.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        )
    });
    ViewerPage {
        title: format!("{} \u{2192} {}", names[0], names[1]),
        names,
        meshes,
        t_ab,
        error,
        up,
    }
}

impl ViewerPage<'_> {
    /// The page's HTML.
    pub(crate) fn html(&self) -> Result<String, Failure> {
        use fmaps::viz::html::{Scene, Surface, viewer_html};
        let surface = |i: usize| Surface {
            name: &self.names[i],
            vertices: self.meshes[i].vertices(),
            faces: self.meshes[i].faces(),
        };
        viewer_html(&Scene {
            title: &self.title,
            a: surface(0),
            b: surface(1),
            map_ab: self.t_ab,
            error: self.error,
            up: self.up,
        })
        .map_err(runtime)
    }
}
