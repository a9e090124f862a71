//! Rows of matrices as contiguous slices, and the f64 distance every
//! strategy decides with.

use faer::MatRef;
use nalgebra::DMatrix;
use rayon::prelude::*;

/// The rows of a matrix, each contiguous: read in place from a view whose
/// column stride is 1, else copied row-major (in parallel).
pub(crate) struct Rows<'a> {
    ptr: *const f64,
    stride: usize,
    n: usize,
    d: usize,
    /// The copy, when one was made (`ptr` points into it).
    _owned: Vec<f64>,
    _view: std::marker::PhantomData<&'a f64>,
}

// SAFETY: `Rows` only reads, through a shared view or its own copy.
unsafe impl Send for Rows<'_> {}
// SAFETY: as above.
unsafe impl Sync for Rows<'_> {}

impl<'a> Rows<'a> {
    pub(crate) fn of(m: MatRef<'a, f64>) -> Rows<'a> {
        let (n, d) = (m.nrows(), m.ncols());
        let rs = m.row_stride();
        if n > 0 && d > 0 && m.col_stride() == 1 && rs >= d as isize {
            return Rows {
                ptr: m.as_ptr(),
                stride: rs as usize,
                n,
                d,
                _owned: Vec::new(),
                _view: std::marker::PhantomData,
            };
        }
        let owned = rows_of(m);
        Rows {
            ptr: owned.as_ptr(),
            stride: d,
            n,
            d,
            _owned: owned,
            _view: std::marker::PhantomData,
        }
    }

    /// The rows of `v` (row-major, `n` x `d`), owned.
    pub(crate) fn owned(v: Vec<f64>, n: usize, d: usize) -> Rows<'static> {
        assert_eq!(v.len(), n * d, "{n} rows of {d}");
        Rows {
            ptr: v.as_ptr(),
            stride: d,
            n,
            d,
            _owned: v,
            _view: std::marker::PhantomData,
        }
    }

    /// Row count and length.
    pub(crate) fn shape(&self) -> (usize, usize) {
        (self.n, self.d)
    }

    /// Row `i`.
    #[inline(always)]
    pub(crate) fn row(&self, i: usize) -> &[f64] {
        assert!(i < self.n, "row {i} of {}", self.n);
        // SAFETY: row i's d elements are elements of the view (column
        // stride 1) or of the copy, both alive for 'a / self.
        unsafe { std::slice::from_raw_parts(self.ptr.add(i * self.stride), self.d) }
    }

    /// The rows `order` (all, in order, when `None`), row-major, each
    /// multiplied by `scale` when given (a power of two: exact).
    pub(crate) fn gather(&self, order: Option<&[usize]>, scale: Option<f64>) -> Vec<f64> {
        let n = order.map_or(self.n, <[usize]>::len);
        let mut out = Vec::with_capacity(n * self.d);
        for p in 0..n {
            // A row a few ahead, from anywhere in the rows: requested now.
            if let Some(&i) = order.and_then(|o| o.get(p + 4)) {
                fmaps_simd::prefetch(self.row(i));
            }
            let src = self.row(order.map_or(p, |o| o[p]));
            match scale {
                Some(s) => out.extend(src.iter().map(|v| v * s)),
                None => out.extend_from_slice(src),
            }
        }
        out
    }

    /// [`Rows::gather`] of the rows `order`, unscaled, with the largest
    /// magnitude among them or `None` when a coordinate is not finite (as
    /// [`Rows::max_abs_finite`] of those rows): one pass over the rows
    /// for the copy, the finiteness check and the scale.
    pub(crate) fn gather_max_abs(&self, order: &[usize]) -> (Vec<f64>, Option<f64>) {
        gather_max_abs(self, order)
    }

    /// The largest magnitude of the rows (0 when none), or `None` when a
    /// coordinate is not finite: one pass for the finiteness check and the
    /// scale. (`v · 0` is 0 for every finite `v` and NaN otherwise, and a
    /// sum of zeros cannot overflow.)
    pub(crate) fn max_abs_finite(&self) -> Option<f64> {
        max_abs_finite(self)
    }
}

crate::cpu::dispatched! {
    /// [`Rows::max_abs_finite`].
    fn max_abs_finite(rows: &Rows<'_>) -> Option<f64> {
            let mut m = MaxAbs::default();
            for i in 0..rows.n {
                m.add(rows.row(i));
            }
            m.result()
    }
}

/// The running largest magnitude of rows, in eight lanes, and their
/// finiteness (`v · 0` is 0 for every finite `v` and NaN otherwise, and a
/// sum of zeros cannot overflow). Inline: inside a dispatched function it
/// is compiled for that level.
#[derive(Default)]
struct MaxAbs {
    lanes: [f64; 8],
    zero: [f64; 8],
}

impl MaxAbs {
    #[inline(always)]
    fn add(&mut self, r: &[f64]) {
        let mut chunks = r.chunks_exact(8);
        for c in &mut chunks {
            for ((l, z), v) in self.lanes.iter_mut().zip(&mut self.zero).zip(c) {
                *l = l.max(v.abs());
                *z += v * 0.0;
            }
        }
        for ((l, z), v) in self
            .lanes
            .iter_mut()
            .zip(&mut self.zero)
            .zip(chunks.remainder())
        {
            *l = l.max(v.abs());
            *z += v * 0.0;
        }
    }

    /// The largest magnitude (0 when none), or `None` when a coordinate
    /// was not finite.
    #[inline(always)]
    fn result(self) -> Option<f64> {
        let finite = self.zero.iter().sum::<f64>() == 0.0;
        finite.then(|| self.lanes.into_iter().fold(0.0, f64::max))
    }
}

crate::cpu::dispatched! {
    /// [`Rows::gather_max_abs`].
    fn gather_max_abs(rows: &Rows<'_>, order: &[usize]) -> (Vec<f64>, Option<f64>) {
            let mut out = Vec::with_capacity(order.len() * rows.d);
            let mut m = MaxAbs::default();
            for p in 0..order.len() {
                // A row a few ahead, from anywhere in the rows: requested now.
                if let Some(&i) = order.get(p + 4) {
                    fmaps_simd::prefetch(rows.row(i));
                }
                let r = rows.row(order[p]);
                out.extend_from_slice(r);
                m.add(r);
            }
            (out, m.result())
    }
}

/// `|a − b|²` in f64, summed in eight lanes (vectorised). Every strategy
/// decides with this one function, so all return the same row.
#[inline(always)]
pub(crate) fn dist2(a: &[f64], b: &[f64]) -> f64 {
    dist2_below(a, b, f64::INFINITY).unwrap_or(f64::NAN)
}

/// The rows of `m` (in `order` when given), row-major. Tiles of 64 rows
/// keep both the column reads and the row writes in cache.
pub(crate) fn row_major(m: &DMatrix<f64>, order: Option<&[usize]>) -> Vec<f64> {
    let (n, d) = m.shape();
    let t = MatRef::from_column_major_slice(m.as_slice(), n, d);
    match order {
        None => rows_of(t),
        Some(order) => Rows::of(t).gather(Some(order), None),
    }
}

/// The rows of a view, copied row-major: tiles of 8 rows (one cache line
/// of each column when the columns are contiguous; the tile stays in L1),
/// in parallel over blocks of tiles.
pub(crate) fn rows_of(m: MatRef<'_, f64>) -> Vec<f64> {
    let (n, d) = (m.nrows(), m.ncols());
    let mut out = vec![0.0; n * d];
    if d == 0 {
        return out;
    }
    let cols: Vec<Option<&[f64]>> = (0..d)
        .map(|j| m.col(j).try_as_col_major().map(|c| c.as_slice()))
        .collect();
    out.par_chunks_mut(512 * d)
        .enumerate()
        .for_each(|(b, block)| {
            for (t, tile) in block.chunks_mut(8 * d).enumerate() {
                let i0 = b * 512 + t * 8;
                let rows = tile.len() / d;
                for (j, col) in cols.iter().enumerate() {
                    match col {
                        Some(c) => {
                            for (i, v) in c[i0..i0 + rows].iter().enumerate() {
                                tile[i * d + j] = *v;
                            }
                        }
                        None => {
                            for i in 0..rows {
                                tile[i * d + j] = m[(i0 + i, j)];
                            }
                        }
                    }
                }
            }
        });
    out
}

#[inline(always)]
/// [`dist2`] when it is at most `bound`, else `None` (possibly decided
/// early: partial sums only grow, and are rounded no higher than the full
/// sum, so a partial sum above the bound proves the full one is).
pub(crate) fn dist2_below(a: &[f64], b: &[f64], bound: f64) -> Option<f64> {
    let n = a.len().min(b.len());
    let mut lanes = [0.0f64; 8];
    let total = |l: &[f64; 8]| ((l[0] + l[4]) + (l[1] + l[5])) + ((l[2] + l[6]) + (l[3] + l[7]));
    let mut i = 0;
    // 32 coordinates per step (lane j takes j, j + 8, ...: the order of
    // eight-wide chunks), then a check against the bound.
    while i + 32 <= n {
        let (x, y) = (&a[i..i + 32], &b[i..i + 32]);
        for c in 0..4 {
            for j in 0..8 {
                let t = x[c * 8 + j] - y[c * 8 + j];
                lanes[j] += t * t;
            }
        }
        if total(&lanes) > bound {
            return None;
        }
        i += 32;
    }
    while i + 8 <= n {
        let (x, y) = (&a[i..i + 8], &b[i..i + 8]);
        for j in 0..8 {
            let t = x[j] - y[j];
            lanes[j] += t * t;
        }
        i += 8;
    }
    for j in 0..n - i {
        let t = a[i + j] - b[i + j];
        lanes[j] += t * t;
    }
    let d = total(&lanes);
    (d <= bound).then_some(d)
}

pub(crate) use fmaps_simd::dot8;

#[cfg(test)]
mod tests {
    use super::*;

    /// `max_abs_finite` against a plain fold, for row lengths around its
    /// 32- and 8-wide chunks, with one entry made infinite or NaN at every
    /// position of a row.
    #[test]
    fn max_abs_finite_is_the_plain_maximum_or_none() {
        for d in [1, 7, 8, 9, 31, 32, 33, 50, 64, 100] {
            let n = 5;
            let data: Vec<f64> = (0..n * d)
                .map(|i| ((i * 37 % 101) as f64 - 50.0) * 1.5f64.powi((i % 13) as i32))
                .collect();
            let m = faer::MatRef::from_row_major_slice(&data, n, d);
            let want = data.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            assert_eq!(Rows::of(m).max_abs_finite(), Some(want), "d = {d}");
            for bad in [f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
                for at in 0..d {
                    let mut x = data.clone();
                    x[2 * d + at] = bad;
                    let m = faer::MatRef::from_row_major_slice(&x, n, d);
                    assert_eq!(Rows::of(m).max_abs_finite(), None, "d = {d}, {bad} at {at}");
                }
            }
        }
    }
}
