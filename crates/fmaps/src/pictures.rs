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

/// A checkerboard on the source, parameterised by the picture plane of
/// `view` (a planar projection towards the camera; `squares` per side),
/// and carried to the target through `t_ab`: distortion and
/// discontinuities of the map show as bent or torn squares.
pub fn texture_transfer(
    source: &TriMesh,
    target: &TriMesh,
    t_ab: &[usize],
    squares: usize,
    view: &View,
) -> fmaps_viz::Result<Transfer> {
    let uv = camera_uv(source, view);
    transfer(source, target, t_ab, checkerboard(&uv, squares), view)
}

/// The picture-plane coordinates of the vertices in `view` (x right, y
/// up): a planar parameterisation for [`checkerboard`] textures.
pub fn camera_uv(mesh: &TriMesh, view: &View) -> Vec<[f64; 2]> {
    mesh.vertices()
        .iter()
        .map(|&p| {
            let c = view.camera(p);
            [c[0], c[1]]
        })
        .collect()
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

/// Per-vertex values from per-point values of a ground truth: `points[r]`
/// is the source vertex of ground-truth row `r` and `values[r]` its
/// error. A vertex gets the mean of its rows; vertices without a row
/// (remeshed datasets leave about a third of the vertices out) take the
/// value of the nearest vertex that has one, along the mesh edges.
/// Vertices in components without any row are NaN (drawn grey).
///
/// ```
/// use fmaps::pictures::vertex_values;
/// let mesh = fmaps::shapes::grid(1.0, 1.0, 3, 1); // 4 x 2 vertices
/// let v = vertex_values(&mesh, &[0, 0, 7], &[1.0, 3.0, 5.0]);
/// assert_eq!(v[0], 2.0); // mean of its two rows
/// assert_eq!(v[7], 5.0);
/// assert!(v.iter().all(|x| *x == 2.0 || *x == 5.0)); // the rest filled
/// ```
pub fn vertex_values(mesh: &TriMesh, points: &[usize], values: &[f64]) -> Vec<f64> {
    let n = mesh.n_vertices();
    let (mut sum, mut count) = (vec![0.0; n], vec![0usize; n]);
    for (&i, &e) in points.iter().zip(values) {
        if i < n && e.is_finite() {
            sum[i] += e;
            count[i] += 1;
        }
    }
    let mut out = vec![f64::NAN; n];
    let mut queue = std::collections::VecDeque::new();
    for i in 0..n {
        if count[i] > 0 {
            out[i] = sum[i] / count[i] as f64;
            queue.push_back(i);
        }
    }
    let mut adj = vec![Vec::new(); n];
    for f in mesh.faces() {
        for k in 0..3 {
            adj[f[k]].push(f[(k + 1) % 3]);
            adj[f[(k + 1) % 3]].push(f[k]);
        }
    }
    while let Some(v) = queue.pop_front() {
        for &w in &adj[v] {
            if out[w].is_nan() {
                out[w] = out[v];
                queue.push_back(w);
            }
        }
    }
    out
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

/// Colours of per-vertex features (`features[s]`: n_s x d on shape `s`):
/// their first three principal components (of every shape's rows
/// together, centred) as red, green and blue, each stretched from its
/// 1st to its 99th percentile. The components are the same on every
/// shape, so where two shapes have similar features they have similar
/// colours: a learned feature extractor's picture of a correspondence.
///
/// ```
/// use nalgebra::DMatrix;
/// // Features that vary along one direction only: one component, the
/// // other two channels flat.
/// let f = DMatrix::from_fn(100, 4, |i, j| if j == 0 { i as f64 } else { 0.0 });
/// let c = fmaps::pictures::feature_colors(&[&f]);
/// assert_eq!(c[0].len(), 100);
/// assert!(c[0][0][0] < c[0][99][0] || c[0][0][0] > c[0][99][0]);
/// ```
pub fn feature_colors(features: &[&nalgebra::DMatrix<f64>]) -> Vec<Vec<[u8; 3]>> {
    let d = features.iter().map(|f| f.ncols()).max().unwrap_or(0);
    let rows: usize = features.iter().map(|f| f.nrows()).sum();
    if d == 0 || rows == 0 || features.iter().any(|f| f.ncols() != d) {
        return features.iter().map(|f| vec![[128; 3]; f.nrows()]).collect();
    }
    let mean = features.iter().fold(nalgebra::DVector::zeros(d), |m, f| {
        m + f.row_sum().transpose()
    }) / rows as f64;
    let mut cov = nalgebra::DMatrix::zeros(d, d);
    for f in features {
        let mut c = (*f).clone();
        for mut r in c.row_iter_mut() {
            r -= mean.transpose();
        }
        cov += c.transpose() * &c;
    }
    let eig = nalgebra::SymmetricEigen::new(cov);
    let mut order: Vec<usize> = (0..d).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
    let axes: Vec<nalgebra::DVector<f64>> = order
        .iter()
        .take(3)
        .map(|&i| eig.eigenvectors.column(i).into_owned())
        .collect();
    let project = |f: &nalgebra::DMatrix<f64>, a: &nalgebra::DVector<f64>| -> Vec<f64> {
        f.row_iter()
            .map(|r| (r.transpose() - &mean).dot(a))
            .collect()
    };
    let coords: Vec<Vec<Vec<f64>>> = features
        .iter()
        .map(|f| axes.iter().map(|a| project(f, a)).collect())
        .collect();
    let mut ranges = Vec::new();
    for c in 0..axes.len() {
        let mut all: Vec<f64> = coords.iter().flat_map(|s| s[c].iter().copied()).collect();
        all.sort_by(f64::total_cmp);
        let at = |q: f64| all[((all.len() - 1) as f64 * q).round() as usize];
        ranges.push((at(0.01), at(0.99)));
    }
    coords
        .iter()
        .map(|s| {
            (0..s.first().map_or(0, Vec::len))
                .map(|i| {
                    std::array::from_fn(|c| match ranges.get(c) {
                        Some(&(lo, hi)) if hi > lo => {
                            (((s[c][i] - lo) / (hi - lo)).clamp(0.0, 1.0) * 255.0).round() as u8
                        }
                        _ => 128,
                    })
                })
                .collect()
        })
        .collect()
}

/// Meshes side by side, each coloured by its per-vertex features
/// ([`feature_colors`], the components shared by all of them).
pub fn features_picture(
    meshes: &[&TriMesh],
    features: &[&nalgebra::DMatrix<f64>],
    view: &View,
) -> fmaps_viz::Result<Image> {
    let colors = feature_colors(features);
    let images = meshes
        .iter()
        .zip(&colors)
        .map(|(m, c)| render(m.vertices(), m.faces(), c, view))
        .collect::<fmaps_viz::Result<Vec<_>>>()?;
    Ok(Image::hstack(&images, WHITE))
}
