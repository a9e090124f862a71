//! Repeated searches of linear images of the same data rows
//! ([`ImageSearch`]) by queries checked once ([`CheckedRows`]).

use std::sync::{Arc, Mutex};

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};

use crate::balls::BallData;
use crate::brute::{F32_COMFORT, scale_for};
use crate::rows::Rows;
use crate::{Error, Partition, Result, check_finite, check_input};

/// Query rows whose coordinates were checked (all finite) once, with
/// their largest magnitude: searched many times ([`ImageSearch::nearest`]),
/// they are not scanned again. Their leading columns
/// ([`CheckedRows::leading`]) are checked rows too (ZoomOut's queries at
/// each size are the leading columns of one spectral embedding).
///
/// ```
/// let q = faer::Mat::<f64>::from_fn(4, 3, |i, j| (i + j) as f64);
/// let checked = fmaps_nearest::CheckedRows::new(q.as_ref())?;
/// assert_eq!(checked.leading(2).rows().ncols(), 2);
/// assert!(fmaps_nearest::CheckedRows::new(faer::Mat::<f64>::full(2, 2, f64::NAN).as_ref()).is_err());
/// # Ok::<(), fmaps_nearest::Error>(())
/// ```
#[derive(Debug, Clone, Copy)]
pub struct CheckedRows<'a> {
    rows: MatRef<'a, f64>,
    /// At least the largest magnitude of `rows` (that of the rows they
    /// were cut from).
    max_abs: f64,
}

impl<'a> CheckedRows<'a> {
    /// `rows`, checked. Errors: a coordinate that is not finite
    /// ([`Error::NonFinite`], side "query", naming the first one).
    pub fn new(rows: MatRef<'a, f64>) -> Result<Self> {
        match Rows::of(rows).max_abs_finite() {
            Some(max_abs) => Ok(CheckedRows { rows, max_abs }),
            None => {
                check_finite(rows, "query")?;
                unreachable!("a coordinate that is not finite is reported above")
            }
        }
    }

    /// The first `k` columns (all of them when `k` is larger).
    pub fn leading(&self, k: usize) -> CheckedRows<'a> {
        CheckedRows {
            rows: self.rows.subcols(0, k.min(self.rows.ncols())),
            max_abs: self.max_abs,
        }
    }

    /// The rows.
    pub fn rows(&self) -> MatRef<'a, f64> {
        self.rows
    }
}

/// Exact nearest neighbours among linear images `X Mᵀ` of the same data
/// rows `X` (n x K) for any number of matrices `M` (k_out x k_in, k_in ≤
/// K; the first k_in columns of `X` are used), e.g. ZoomOut's `Φ_A Cᵀ`
/// at every size: the ball search ([`NnStrategy::Balls`](crate::NnStrategy::Balls))
/// with the clusters `partition` of the rows, which are copied into the
/// clusters' order once, so that each search computes its image directly
/// in that order (one f64 GEMM, into a buffer kept from search to
/// search) instead of copying it there. The answers are those of
/// [`nearest_rows`](crate::nearest_rows) on the image (the f64 argmin,
/// ties to the smallest index).
///
/// ```
/// use fmaps_nearest::{CheckedRows, ImageSearch, NnParams, NnStrategy, Partition, nearest_rows};
///
/// let x = faer::Mat::<f64>::from_fn(200, 6, |i, j| ((i * (j + 3)) as f64 * 0.01).sin());
/// let m = faer::Mat::<f64>::from_fn(4, 5, |i, j| if i == j { 1.0 } else { 0.1 });
/// let q = faer::Mat::<f64>::from_fn(30, 4, |i, j| ((i + 2 * j) as f64 * 0.05).cos());
/// let search = ImageSearch::new(x.as_ref(), Partition::kmeans(x.as_ref(), 24, 3))?;
/// let found = search.nearest(m.as_ref(), &CheckedRows::new(q.as_ref())?, None)?;
/// let image = x.as_ref().subcols(0, 5) * m.transpose();
/// let params = NnParams::with_strategy(NnStrategy::Brute);
/// assert_eq!(found, nearest_rows(image.as_ref(), q.as_ref(), None, &params)?);
/// # Ok::<(), fmaps_nearest::Error>(())
/// ```
pub struct ImageSearch {
    /// Columns of the rows.
    k: usize,
    /// The rows in the clusters' order (row-major, n x k).
    rows: Vec<f64>,
    /// Original index of each row in that order, and the clusters
    /// (start, length).
    order: Vec<usize>,
    ranges: Vec<(usize, usize)>,
    /// An upper bound on the rows' Euclidean norms.
    norm_max: f64,
    /// The last image's buffer (reused: no allocation or zeroing per
    /// search once it is large enough).
    image: Mutex<Vec<f64>>,
}

impl ImageSearch {
    /// The rows `x` (n x K) and their clusters. Errors: a partition of
    /// another number of rows ([`Error::SizeMismatch`]), a coordinate that
    /// is not finite ([`Error::NonFinite`], side "data").
    pub fn new(x: MatRef<'_, f64>, partition: Arc<Partition>) -> Result<ImageSearch> {
        if partition.len() != x.nrows() {
            return Err(Error::SizeMismatch {
                what: "partition labels vs data rows",
                found: partition.len(),
                expected: x.nrows(),
            });
        }
        check_finite(x, "data")?;
        let (order, ranges) = partition.groups();
        let rows = Rows::of(x).gather(Some(&order), None);
        let k = x.ncols();
        let norm_max = rows
            .chunks_exact(k.max(1))
            .map(|r| crate::rows::dot8(r, r))
            .fold(0.0, f64::max)
            .sqrt();
        Ok(ImageSearch {
            k,
            rows,
            norm_max,
            order,
            ranges,
            image: Mutex::new(Vec::new()),
        })
    }

    /// Number of data rows.
    pub fn len(&self) -> usize {
        self.order.len()
    }

    /// Whether there are no data rows.
    pub fn is_empty(&self) -> bool {
        self.order.is_empty()
    }

    /// For every query row, the nearest row of the image `X[:, :k_in] Mᵀ`
    /// (`m`: k_out x k_in; the queries have k_out columns); `hint`: one
    /// guess per query, as in [`nearest_rows`](crate::nearest_rows).
    ///
    /// Errors: k_in above the rows' K ([`Error::SizeMismatch`]), queries
    /// of another width than k_out, a hint count other than one per
    /// query, queries without data rows, an image coordinate that is not
    /// finite (a non-finite `m`; [`Error::NonFinite`], side "data", naming
    /// the data row).
    pub fn nearest(
        &self,
        m: MatRef<'_, f64>,
        queries: &CheckedRows<'_>,
        hint: Option<&[usize]>,
    ) -> Result<Vec<usize>> {
        let (k_out, k_in) = (m.nrows(), m.ncols());
        if k_in > self.k {
            return Err(Error::SizeMismatch {
                what: "map columns vs data columns",
                found: k_in,
                expected: self.k,
            });
        }
        let n = self.order.len();
        let q = queries.rows;
        if check_input(n, k_out, q, hint)? {
            return Ok(Vec::new());
        }
        if k_out == 0 {
            // Every row is at distance 0: ties go to the smallest index.
            return Ok(vec![0; q.nrows()]);
        }
        let mut image = std::mem::take(&mut *self.image.lock().unwrap_or_else(|e| e.into_inner()));
        // (Only a longer image than the last one zeroes its new tail.)
        image.resize(n * k_out, 0.0);
        let rows = MatRef::from_row_major_slice_with_stride(&self.rows, n, k_in, self.k);
        matmul(
            MatMut::from_row_major_slice_mut(&mut image, n, k_out),
            Accum::Replace,
            rows,
            m.transpose(),
            1.0,
            Par::rayon(0),
        );
        // No scan of the image where it is bounded inside f32's comfort
        // range, like the queries (finite, and no rescaling: the scale
        // found by a scan would be none too): each entry is at most
        // `|x| |m_j|` (Cauchy–Schwarz) plus its rounding, a relative
        // `k_in 2⁻⁵³`; the two norms' own rounding is below `(K + 2) 2⁻⁵³`
        // each: a relative margin of `4 (K + 2) ε` covers all three.
        let q_max = queries.max_abs;
        let margin = 1.0 + 4.0 * (self.k as f64 + 2.0) * f64::EPSILON;
        let bound = self.norm_max * row_norm_max(m) * margin;
        let x_max = if bound <= F32_COMFORT && (1.0 / F32_COMFORT..=F32_COMFORT).contains(&q_max) {
            bound
        } else {
            match Rows::of(MatRef::from_row_major_slice(&image, n, k_out)).max_abs_finite() {
                Some(v) => v,
                None => return Err(self.non_finite(&image, k_out)),
            }
        };
        let scale = scale_for(x_max.max(q_max));
        if let Some(s) = scale {
            // (A power of two: the same values as scaling on a copy.)
            for v in &mut image {
                *v *= s;
            }
        }
        let balls = BallData::assemble(k_out, image, self.order.clone(), self.ranges.clone());
        let found = balls.search_rows(&Rows::of(q), hint, scale);
        *self.image.lock().unwrap_or_else(|e| e.into_inner()) = balls.into_rows();
        Ok(found)
    }

    /// The first coordinate of `image` (in the clusters' order, `k_out`
    /// wide) that is not finite, named in the rows' own order.
    fn non_finite(&self, image: &[f64], k_out: usize) -> Error {
        let (p, col) = image
            .chunks_exact(k_out)
            .enumerate()
            .filter_map(|(p, r)| r.iter().position(|v| !v.is_finite()).map(|c| (p, c)))
            .min_by_key(|&(p, _)| self.order[p])
            .unwrap_or((0, 0));
        Error::NonFinite {
            side: "data",
            row: self.order[p],
            col,
            value: image[p * k_out + col],
        }
    }
}

/// The largest Euclidean norm of the rows of `m` (infinite or NaN when an
/// entry is not finite).
fn row_norm_max(m: MatRef<'_, f64>) -> f64 {
    let mut big = 0.0f64;
    for i in 0..m.nrows() {
        let mut s = 0.0;
        for j in 0..m.ncols() {
            s += m[(i, j)] * m[(i, j)];
        }
        if s.is_nan() {
            return f64::NAN;
        }
        big = big.max(s);
    }
    big.sqrt()
}
