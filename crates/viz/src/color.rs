//! Per-vertex colours: colour maps, colouring by position, checkerboard
//! textures, and carrying colours through a point map.

/// Viridis-like sequential colour map, `t` in `[0, 1]` (clamped; NaN is
/// grey).
pub fn colormap(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 6] = [
        [68.0, 1.0, 84.0],
        [65.0, 68.0, 135.0],
        [42.0, 120.0, 142.0],
        [34.0, 168.0, 132.0],
        [122.0, 209.0, 81.0],
        [253.0, 231.0, 37.0],
    ];
    if t.is_nan() {
        return [128, 128, 128];
    }
    let s = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f64;
    let i = (s.floor() as usize).min(STOPS.len() - 2);
    let f = s - i as f64;
    let mut out = [0u8; 3];
    for d in 0..3 {
        out[d] = (STOPS[i][d] + f * (STOPS[i + 1][d] - STOPS[i][d])).round() as u8;
    }
    out
}

/// Values mapped through [`colormap`] between `vmin` and `vmax`.
pub fn scalar_colors(values: &[f64], vmin: f64, vmax: f64) -> Vec<[u8; 3]> {
    let span = (vmax - vmin).max(1e-300);
    values
        .iter()
        .map(|&v| colormap((v - vmin) / span))
        .collect()
}

/// Colours from the position: each coordinate normalised over the
/// bounding box drives one channel (x red, y green, z blue), kept away
/// from black so shading stays visible.
pub fn position_colors(vertices: &[[f64; 3]]) -> Vec<[u8; 3]> {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in vertices {
        for d in 0..3 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    vertices
        .iter()
        .map(|p| {
            let mut c = [0u8; 3];
            for d in 0..3 {
                let t = (p[d] - lo[d]) / (hi[d] - lo[d]).max(1e-300);
                c[d] = (40.0 + 215.0 * t).round() as u8;
            }
            c
        })
        .collect()
}

/// A checkerboard texture on a parameterisation: vertex `i` with
/// coordinates `uv[i]` is light or dark by the parity of
/// `floor(u * squares) + floor(v * squares)`, with both coordinates
/// measured from their minimum in units of the longer side of the
/// bounding rectangle (so the squares are square and `squares` of them
/// span the longer side).
pub fn checkerboard(uv: &[[f64; 2]], squares: usize) -> Vec<[u8; 3]> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in uv {
        for d in 0..2 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    let n = squares.max(1) as f64;
    let side = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-300);
    uv.iter()
        .map(|p| {
            let cell = |d: usize| ((p[d] - lo[d]) / side * n).floor() as i64;
            if (cell(0) + cell(1)).rem_euclid(2) == 0 {
                [235, 235, 225]
            } else {
                [200, 60, 50]
            }
        })
        .collect()
}

/// Colours of the target through a point map `t_ab` (a target vertex per
/// source vertex): each target vertex gets the mean colour of the source
/// vertices mapped onto it; target vertices no source vertex reaches take
/// the colour of the nearest reached vertex along the target's edges
/// (`faces`), so holes in the map's coverage do not show as blanks.
/// Vertices in components no mapped vertex reaches stay grey.
pub fn push_colors(
    t_ab: &[usize],
    source_colors: &[[u8; 3]],
    n_target: usize,
    target_faces: &[[usize; 3]],
) -> Vec<[u8; 3]> {
    let mut sum = vec![[0.0f64; 3]; n_target];
    let mut count = vec![0usize; n_target];
    for (a, &b) in t_ab.iter().enumerate() {
        if b < n_target && a < source_colors.len() {
            for d in 0..3 {
                sum[b][d] += f64::from(source_colors[a][d]);
            }
            count[b] += 1;
        }
    }
    let mut out = vec![[128u8; 3]; n_target];
    let mut queue = std::collections::VecDeque::new();
    let mut done = vec![false; n_target];
    for b in 0..n_target {
        if count[b] > 0 {
            for d in 0..3 {
                out[b][d] = (sum[b][d] / count[b] as f64).round() as u8;
            }
            done[b] = true;
            queue.push_back(b);
        }
    }
    let mut adj = vec![Vec::new(); n_target];
    for f in target_faces {
        for k in 0..3 {
            let (x, y) = (f[k], f[(k + 1) % 3]);
            if x < n_target && y < n_target {
                adj[x].push(y);
                adj[y].push(x);
            }
        }
    }
    while let Some(v) = queue.pop_front() {
        for &w in &adj[v] {
            if !done[w] {
                done[w] = true;
                out[w] = out[v];
                queue.push_back(w);
            }
        }
    }
    out
}

/// A vertical colour bar for [`colormap`] from `vmin` (bottom) to `vmax`
/// (top), labelled at both ends and the middle, with a title.
pub fn colorbar(height: usize, vmin: f64, vmax: f64, title: &str) -> crate::Image {
    let width = 150;
    let mut img = crate::Image::new(width, height, crate::image::WHITE);
    let (top, bottom) = (40usize, 20usize);
    let bar = height.saturating_sub(top + bottom).max(1);
    for y in 0..bar {
        let t = 1.0 - y as f64 / (bar - 1).max(1) as f64;
        img.fill_rect(10, (top + y) as i64, 24, 1, colormap(t));
    }
    img.text(4, 12, title, 1, crate::image::BLACK);
    for (t, v) in [(1.0, vmax), (0.5, (vmin + vmax) / 2.0), (0.0, vmin)] {
        let y = top as f64 + (1.0 - t) * (bar - 1) as f64;
        img.text(40, y as i64 - 4, &format!("{v:.3}"), 1, crate::image::BLACK);
    }
    img
}
