//! Line plots (axes, grid, labelled ticks, one polyline per series, a
//! legend) and matrix heat maps. Text uses the 8x8 bitmap glyphs of
//! `font8x8` (compiled in), so no system font library is needed.

use crate::image::{BLACK, Image, WHITE};

/// One curve.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Abscissae.
    pub x: Vec<f64>,
    /// Ordinates.
    pub y: Vec<f64>,
}

/// What to draw.
#[derive(Debug, Clone)]
pub struct Plot<'a> {
    /// Title above the axes.
    pub title: &'a str,
    /// Label of the horizontal axis.
    pub x_label: &'a str,
    /// Label of the vertical axis.
    pub y_label: &'a str,
    /// Horizontal range.
    pub x_range: (f64, f64),
    /// Vertical range.
    pub y_range: (f64, f64),
    /// Horizontal ticks (labelled).
    pub x_ticks: Vec<f64>,
    /// Vertical ticks (labelled).
    pub y_ticks: Vec<f64>,
}

const W: usize = 900;
const H: usize = 600;
const LEFT: usize = 80;
const RIGHT: usize = 30;
const TOP: usize = 50;
const BOTTOM: usize = 70;
const PALETTE: [[u8; 3]; 8] = [
    [31, 119, 180],
    [214, 39, 40],
    [44, 160, 44],
    [255, 127, 14],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [23, 190, 207],
];

/// Renders the series (900 x 600 pixels).
pub fn line_plot(plot: &Plot<'_>, series: &[Series]) -> Image {
    let mut cv = Image::new(W, H, WHITE);
    let (x0, x1) = plot.x_range;
    let (y0, y1) = plot.y_range;
    let px = |x: f64| LEFT as f64 + (x - x0) / (x1 - x0) * (W - LEFT - RIGHT) as f64;
    let py = |y: f64| (H - BOTTOM) as f64 - (y - y0) / (y1 - y0) * (H - TOP - BOTTOM) as f64;
    let grid = [225, 225, 225];
    let black = [0, 0, 0];
    for &t in &plot.x_ticks {
        cv.line((px(t), py(y0)), (px(t), py(y1)), grid, 1);
        let label = format!("{t}");
        cv.text(
            px(t) as i64 - 4 * label.len() as i64,
            (H - BOTTOM + 8) as i64,
            &label,
            1,
            black,
        );
    }
    for &t in &plot.y_ticks {
        cv.line((px(x0), py(t)), (px(x1), py(t)), grid, 1);
        let label = format!("{t}");
        cv.text(
            LEFT as i64 - 10 - 8 * label.len() as i64,
            py(t) as i64 - 4,
            &label,
            1,
            black,
        );
    }
    cv.line((px(x0), py(y0)), (px(x1), py(y0)), black, 2);
    cv.line((px(x0), py(y0)), (px(x0), py(y1)), black, 2);
    cv.text(
        (W / 2) as i64 - 8 * plot.title.len() as i64,
        15,
        plot.title,
        2,
        black,
    );
    cv.text(
        (W / 2) as i64 - 4 * plot.x_label.len() as i64,
        (H - 30) as i64,
        plot.x_label,
        1,
        black,
    );
    cv.text(8, (TOP - 12) as i64, plot.y_label, 1, black);
    for (i, s) in series.iter().enumerate() {
        let c = PALETTE[i % PALETTE.len()];
        for k in 1..s.x.len().min(s.y.len()) {
            cv.line(
                (px(s.x[k - 1]), py(s.y[k - 1])),
                (px(s.x[k]), py(s.y[k])),
                c,
                3,
            );
        }
        // Legend, bottom right.
        let ly = (H - BOTTOM) as i64 - 20 * (series.len() - i) as i64 - 10;
        let lx = (W - RIGHT) as i64 - 340;
        cv.line(
            (lx as f64, ly as f64 + 4.0),
            (lx as f64 + 30.0, ly as f64 + 4.0),
            c,
            3,
        );
        cv.text(lx + 40, ly, &s.label, 1, black);
    }
    cv
}

/// A matrix as a heat map (seed paper, Figure 1): |value| from white (0) to
/// dark (>= `vmax`), positive in red and negative in blue, with a title
/// and the matrix size. One square cell per entry, scaled to ~560 px.
pub fn heatmap(title: &str, m: &nalgebra::DMatrix<f64>, vmax: f64) -> Image {
    const BOX: usize = 540;
    let (rows, cols) = m.shape();
    let big = rows.max(cols).max(1);
    // Whole pixels per entry up to 540 entries; beyond, several entries
    // share a pixel (each pixel shows the entry at its top-left corner).
    let (w, h) = if big <= BOX {
        let cell = BOX / big;
        (cell * cols, cell * rows)
    } else {
        (cols * BOX / big, rows * BOX / big)
    };
    let (x0, y0) = ((W - w) / 2, TOP + 10);
    let mut cv = Image::new(W, H, WHITE);
    let black = BLACK;
    cv.text(x0 as i64, 20, title, 2, black);
    for py in 0..h {
        let i = py * rows / h.max(1);
        for px in 0..w {
            let j = px * cols / w.max(1);
            let v = m[(i, j)];
            let t = if v.is_nan() {
                0.0
            } else {
                (v.abs() / vmax).min(1.0)
            };
            let fade = |full: u8| (255.0 - t * (255.0 - f64::from(full))).round() as u8;
            let c = if v >= 0.0 {
                [fade(178), fade(24), fade(43)]
            } else {
                [fade(33), fade(102), fade(172)]
            };
            cv.set((x0 + px) as i64, (y0 + py) as i64, c);
        }
    }
    let (bx, by) = (x0 as i64, (y0 + h + 14) as i64);
    cv.text(
        bx,
        by,
        &format!("{rows} x {cols}; red > 0, blue < 0, full colour at |C_ij| >= {vmax}"),
        1,
        black,
    );
    cv
}

/// Cumulative error curves: the fraction of points (0 to 1) under each
/// normalised geodesic error threshold from 0 to `max_threshold`.
pub fn cumulative_curves(title: &str, max_threshold: f64, series: &[Series]) -> Image {
    let ticks = 5;
    line_plot(
        &Plot {
            title,
            x_label: "geodesic error / sqrt(area)",
            y_label: "fraction of points",
            x_range: (0.0, max_threshold),
            y_range: (0.0, 1.0),
            x_ticks: (0..=ticks)
                .map(|i| max_threshold * i as f64 / ticks as f64)
                .collect(),
            y_ticks: vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0],
        },
        series,
    )
}
