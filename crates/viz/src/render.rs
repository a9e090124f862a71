//! Headless software rasterisation of a triangle mesh: orthographic view,
//! z-buffer, per-vertex colours interpolated across triangles, Lambert
//! shading with a two-sided light.

use crate::image::Image;
use crate::{Error, Result};

/// A coordinate axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Axis {
    /// The x axis.
    X,
    /// The y axis (the default "up": FAUST, the built-in shapes).
    #[default]
    Y,
    /// The z axis ("up" in TOSCA and many scans).
    Z,
}

/// Camera and picture settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// The shape's vertical axis: it is drawn pointing up, and the camera
    /// looks at the shape along one of the other two axes (for `Y`, along
    /// -z; for `Z`, along +y; for `X`, along -z).
    pub up: Axis,
    /// Picture width in pixels.
    pub width: usize,
    /// Picture height in pixels.
    pub height: usize,
    /// Rotation about the vertical (y) axis, radians, applied first.
    pub yaw: f64,
    /// Rotation about the horizontal (x) axis, radians, applied second.
    pub pitch: f64,
    /// Background colour.
    pub background: [u8; 3],
    /// Empty border around the shape, as a fraction of the picture.
    pub margin: f64,
}

impl Default for View {
    fn default() -> Self {
        View {
            up: Axis::Y,
            width: 480,
            height: 480,
            yaw: 0.0,
            pitch: 0.0,
            background: [255, 255, 255],
            margin: 0.06,
        }
    }
}

impl View {
    /// The vertex in camera coordinates (x right, y up, z towards the
    /// viewer, before fitting to the picture): the `up` axis is turned to
    /// y, then `yaw` and `pitch` are applied.
    ///
    /// ```
    /// use fmaps_viz::{Axis, View};
    /// let view = View { up: Axis::Z, ..View::default() };
    /// // z-up shapes stand upright: +z becomes up, +y goes away from the viewer.
    /// assert_eq!(view.camera([0.0, 0.0, 1.0]), [0.0, 1.0, 0.0]);
    /// assert_eq!(view.camera([0.0, 1.0, 0.0]), [0.0, 0.0, -1.0]);
    /// ```
    pub fn camera(&self, p: [f64; 3]) -> [f64; 3] {
        let p = match self.up {
            Axis::Y => p,
            Axis::Z => [p[0], p[2], -p[1]],
            Axis::X => [-p[1], p[0], p[2]],
        };
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        let x = cy * p[0] + sy * p[2];
        let z = -sy * p[0] + cy * p[2];
        let y = cp * p[1] - sp * z;
        let z = sp * p[1] + cp * z;
        [x, y, z]
    }
}

/// Renders the mesh with one colour per vertex. The shape is fitted to
/// the picture (same scale on both axes) after the view rotation.
///
/// ```
/// use fmaps_viz::{View, render};
/// let mesh = fmaps_shapes::icosphere(1.0, 2);
/// let colors = vec![[200, 60, 40]; mesh.n_vertices()];
/// let img = render(mesh.vertices(), mesh.faces(), &colors, &View::default())?;
/// // The sphere fills the middle of the picture; the corner is background.
/// assert_ne!(img.get(240, 240), [255, 255, 255]);
/// assert_eq!(img.get(2, 2), [255, 255, 255]);
/// # Ok::<(), fmaps_viz::Error>(())
/// ```
pub fn render(
    vertices: &[[f64; 3]],
    faces: &[[usize; 3]],
    colors: &[[u8; 3]],
    view: &View,
) -> Result<Image> {
    crate::check_colored_mesh(vertices, faces, colors)?;
    if view.width == 0 || view.height == 0 {
        return Err(Error::Size {
            what: "picture size",
            found: 0,
            expected: 1,
        });
    }
    let mut img = Image::new(view.width, view.height, view.background);
    if vertices.is_empty() {
        return Ok(img);
    }
    let cam: Vec<[f64; 3]> = vertices.iter().map(|&p| view.camera(p)).collect();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &cam {
        for d in 0..2 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    let (w, h) = (view.width as f64, view.height as f64);
    let usable = 1.0 - 2.0 * view.margin;
    let scale =
        (usable * w / (hi[0] - lo[0]).max(1e-300)).min(usable * h / (hi[1] - lo[1]).max(1e-300));
    let (cx, cy) = ((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0);
    let screen: Vec<[f64; 3]> = cam
        .iter()
        .map(|p| {
            [
                w / 2.0 + scale * (p[0] - cx),
                h / 2.0 - scale * (p[1] - cy),
                p[2],
            ]
        })
        .collect();
    let light = {
        let l: [f64; 3] = [-0.35, 0.45, 1.0];
        let n = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
        [l[0] / n, l[1] / n, l[2] / n]
    };
    let mut depth = vec![f64::NEG_INFINITY; view.width * view.height];
    for f in faces {
        let [a, b, c] = f.map(|i| cam[i]);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let shade = if len > 0.0 {
            let ndl = (n[0] * light[0] + n[1] * light[1] + n[2] * light[2]) / len;
            0.3 + 0.7 * ndl.abs()
        } else {
            0.3
        };
        let [p0, p1, p2] = f.map(|i| screen[i]);
        let area = (p1[0] - p0[0]) * (p2[1] - p0[1]) - (p2[0] - p0[0]) * (p1[1] - p0[1]);
        if area.abs() < 1e-12 {
            continue;
        }
        let x0 = p0[0].min(p1[0]).min(p2[0]).floor().max(0.0) as usize;
        let x1 = (p0[0].max(p1[0]).max(p2[0]).ceil() as usize).min(view.width - 1);
        let y0 = p0[1].min(p1[1]).min(p2[1]).floor().max(0.0) as usize;
        let y1 = (p0[1].max(p1[1]).max(p2[1]).ceil() as usize).min(view.height - 1);
        let cols = f.map(|i| colors[i]);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let w0 = ((p1[0] - px) * (p2[1] - py) - (p2[0] - px) * (p1[1] - py)) / area;
                let w1 = ((p2[0] - px) * (p0[1] - py) - (p0[0] - px) * (p2[1] - py)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < -1e-9 || w1 < -1e-9 || w2 < -1e-9 {
                    continue;
                }
                let z = w0 * p0[2] + w1 * p1[2] + w2 * p2[2];
                let k = y * view.width + x;
                if z <= depth[k] {
                    continue;
                }
                depth[k] = z;
                let mut rgb = [0u8; 3];
                for d in 0..3 {
                    let c = w0 * f64::from(cols[0][d])
                        + w1 * f64::from(cols[1][d])
                        + w2 * f64::from(cols[2][d]);
                    rgb[d] = (c * shade).round().clamp(0.0, 255.0) as u8;
                }
                img.set(x as i64, y as i64, rgb);
            }
        }
    }
    Ok(img)
}
