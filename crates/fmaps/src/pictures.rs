//! Pictures of a correspondence (through [`fmaps_viz`]): colour and
//! texture transfer, per-vertex error, spectral embedding.

use fmaps_eigensolve::SpectralBasis;
use fmaps_mesh_io::TriMesh;
use fmaps_viz::{
    Image, View, WHITE, checkerboard, colorbar, position_colors, push_colors, render, scalar_colors,
};

/// A transfer picture (source left, target right) with the vertex colours
/// of both sides (for coloured PLY).
pub type Transfer = (Image, Vec<[u8; 3]>, Vec<[u8; 3]>);

/// Source coloured by position (left) and the target coloured through
/// `t_ab` (right): where the colours agree, the map is right.
pub fn color_transfer(
    source: &TriMesh,
    target: &TriMesh,
    t_ab: &[usize],
    view: &View,
) -> fmaps_viz::Result<Transfer> {
    let cs = position_colors(source.vertices());
    transfer(source, target, t_ab, cs, view)
}

/// A checkerboard on the source, parameterised by its first two
/// coordinates (a planar projection; `squares` per side), and carried to
/// the target through `t_ab`: distortion and discontinuities of the map
/// show as bent or torn squares.
pub fn texture_transfer(
    source: &TriMesh,
    target: &TriMesh,
    t_ab: &[usize],
    squares: usize,
    view: &View,
) -> fmaps_viz::Result<Transfer> {
    let uv: Vec<[f64; 2]> = source.vertices().iter().map(|p| [p[0], p[1]]).collect();
    transfer(source, target, t_ab, checkerboard(&uv, squares), view)
}

fn transfer(
    source: &TriMesh,
    target: &TriMesh,
    t_ab: &[usize],
    cs: Vec<[u8; 3]>,
    view: &View,
) -> fmaps_viz::Result<Transfer> {
    let ct = push_colors(t_ab, &cs, target.n_vertices(), target.faces());
    let img = Image::hstack(
        &[
            render(source.vertices(), source.faces(), &cs, view)?,
            render(target.vertices(), target.faces(), &ct, view)?,
        ],
        WHITE,
    );
    Ok((img, cs, ct))
}

/// The per-vertex error on the source (`errors`, one per source vertex)
/// from 0 to `vmax`, with a colour bar titled `title`.
pub fn error_map(
    source: &TriMesh,
    errors: &[f64],
    vmax: f64,
    title: &str,
    view: &View,
) -> fmaps_viz::Result<Image> {
    let colors = scalar_colors(errors, 0.0, vmax);
    let img = render(source.vertices(), source.faces(), &colors, view)?;
    let bar = colorbar(view.height, 0.0, vmax, title);
    Ok(Image::hstack(&[img, bar], WHITE))
}

/// The shape drawn with eigenfunctions `which` (column indices of the
/// basis) as its coordinates (the seed's Figure 10), coloured by its
/// original position.
pub fn spectral_embedding(
    mesh: &TriMesh,
    basis: &SpectralBasis,
    which: [usize; 3],
    view: &View,
) -> fmaps_viz::Result<Image> {
    if let Some(&j) = which.iter().find(|&&j| j >= basis.k()) {
        return Err(fmaps_viz::Error::Size {
            what: "eigenfunction index (basis size)",
            found: j,
            expected: basis.k(),
        });
    }
    let coords: Vec<[f64; 3]> = (0..mesh.n_vertices())
        .map(|i| which.map(|j| basis.eigenvectors[(i, j)]))
        .collect();
    render(
        &coords,
        mesh.faces(),
        &position_colors(mesh.vertices()),
        view,
    )
}
