//! Checks of the pipeline's inputs and results that turn would-be garbage
//! into errors: the unit-area scaling over the whole range of f64, the
//! determinacy of the solved C, and the multi-start syntax.

use fmaps_mesh_io::TriMesh;
use nalgebra::DMatrix;

use super::MatchError;

/// Parses the command line's multi-start list: `none` (a single start) or
/// sizes `K1,K2,..` (each at least 1; spaces around commas allowed) for
/// [`MatchParams::starts`](super::MatchParams::starts).
///
/// ```
/// use fmaps::pipeline::parse_starts;
/// assert_eq!(parse_starts("20, 30"), Ok(vec![20, 30]));
/// assert_eq!(parse_starts("none"), Ok(vec![]));
/// assert!(parse_starts("20,,30").is_err());
/// ```
pub fn parse_starts(text: &str) -> Result<Vec<usize>, String> {
    let text = text.trim();
    if text == "none" {
        return Ok(Vec::new());
    }
    text.split(',')
        .map(|s| match s.trim().parse::<usize>() {
            Ok(k) if k >= 1 => Ok(k),
            _ => Err(format!(
                "'{text}': expected sizes K1,K2,.. (each at least 1, e.g. 20,30) or none"
            )),
        })
        .collect()
}

/// `mesh` scaled to unit area, and the factor applied. Coordinates are
/// first scaled by a power of two (exact) to a largest magnitude in
/// [1, 2), so that the area neither overflows nor underflows for any
/// finite coordinates (1e300 or 1e-300 units match like metres).
pub(super) fn unit_area(mesh: &TriMesh) -> Result<(TriMesh, f64), String> {
    let extent = mesh
        .vertices()
        .iter()
        .flatten()
        .fold(0.0f64, |m, c| m.max(c.abs()));
    let zero = || "the area is 0: it cannot be normalized (collinear or degenerate faces only?)";
    if extent == 0.0 {
        return Err(zero().into());
    }
    let pre = 2f64.powi(-(extent.log2().floor() as i32));
    if !pre.is_finite() || pre == 0.0 {
        return Err(format!(
            "coordinates of magnitude {extent:e} are beyond double precision's range for a surface"
        ));
    }
    let pre_mesh = mesh.scaled(pre).map_err(|e| e.to_string())?;
    let area = pre_mesh.area();
    if !(area.is_finite() && area > 0.0) {
        return Err(zero().into());
    }
    let s = 1.0 / area.sqrt();
    let out = pre_mesh.scaled(s).map_err(|e| e.to_string())?;
    Ok((out, pre * s))
}

/// Largest `|C_ij|`, relative to the area scale, accepted from the solve.
/// C_BA pulls functions on B back to A: for a map that spreads A's area
/// over B (ratio `r`) its columns have norm about `√r` between
/// L²-orthonormal bases (≤ 1 entries for an isometry). A thousand times
/// that is not a map; an undetermined solve gives 1e10 and more.
const MAX_C_ENTRY: f64 = 1e3;

/// Errors with [`MatchError::Undetermined`] when `c_ba` cannot be the
/// pull-back of a map between shapes of areas `area_a` and `area_b`: far
/// larger than one can be, or of numerical rank below half its size (the
/// pull-back of a map that reaches most of B has singular values of order
/// 1; a solve whose descriptors span only the constants on one shape gives
/// rank 1).
pub(super) fn check_determined(
    c_ba: &DMatrix<f64>,
    area_a: f64,
    area_b: f64,
) -> Result<(), MatchError> {
    let ratio = (area_a / area_b).max(area_b / area_a);
    let scale = if ratio.is_finite() { ratio.sqrt() } else { 1.0 };
    let max_entry = c_ba.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let k = c_ba.nrows().min(c_ba.ncols());
    let sv = c_ba.singular_values();
    let top = sv.iter().fold(0.0f64, |m, &x| m.max(x));
    let rank = sv.iter().filter(|&&x| x > 1e-8 * top).count();
    if max_entry <= MAX_C_ENTRY * scale && 2 * rank >= k {
        return Ok(());
    }
    let ctc = c_ba.transpose() * c_ba;
    let orthonormality = (ctc - DMatrix::identity(c_ba.ncols(), c_ba.ncols())).norm();
    Err(MatchError::Undetermined {
        max_entry,
        rank,
        k,
        orthonormality,
    })
}
