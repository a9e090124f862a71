//! The wedge sums of `fmaps-solve`'s orientation operators, a small
//! numeric kernel compiled for the CPU's vector extensions (the crate is
//! built for baseline x86-64, SSE2), chosen at run time (the detection is
//! cached by the standard library): a portable
//! `#[inline(always)]` body instantiated inside a `#[target_feature]`
//! function for AVX2+FMA and used as is for the baseline, and, where
//! register tiling matters, an AVX-512 version written with intrinsics.
//! Results differ between the variants by rounding only (fused or
//! separate multiply-adds, order of the sums).

#[inline(always)]
fn fma<const FUSED: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FUSED { a.mul_add(b, c) } else { a * b + c }
}

/// The faces around one vertex for [`wedge_sums`]: rows `prev[f]` and
/// `next[f]` of `rows` (row-major, `kp` values per row, the first `k` used)
/// are the basis values at the previous and next corners of face f.
#[derive(Clone, Copy)]
pub struct Fan<'a> {
    /// Basis values, row-major, `kp` per row.
    pub rows: &'a [f64],
    /// Values per row of `rows` (padded: a multiple of 8, at least `k`).
    pub kp: usize,
    /// Basis functions used (the first `k` of each row).
    pub k: usize,
    /// Per face, the row of its previous corner.
    pub prev: &'a [usize],
    /// Per face, the row of its next corner.
    pub next: &'a [usize],
}

/// For j in 1..k, writes `out[j(j−1)/2 + i] = Σ_f P[f,i] N[f,j] − N[f,i] P[f,j]`
/// for i < j: the entries above the diagonal of `Pᵀ N − Nᵀ P`, column by
/// column, where row f of P is row `prev[f]` of `rows` and row f of N is
/// row `next[f]` (`rows` row-major with `kp` values per row, kp ≥ k).
#[inline(always)]
fn wedge_sums_body<const FUSED: bool>(fan: &Fan<'_>, out: &mut [f64]) {
    let (rows, kp, prev, next) = (fan.rows, fan.kp, fan.prev, fan.next);
    let mut base = 0;
    for j in 1..fan.k {
        let o = &mut out[base..base + j];
        o.fill(0.0);
        for (&pf, &nf) in prev.iter().zip(next) {
            let (pr, nr) = (
                &rows[pf * kp..pf * kp + j + 1],
                &rows[nf * kp..nf * kp + j + 1],
            );
            let (a, b) = (nr[j], pr[j]);
            for ((o, p), n) in o.iter_mut().zip(pr).zip(nr) {
                *o = fma::<FUSED>(*n, -b, fma::<FUSED>(*p, a, *o));
            }
        }
        base += j;
    }
}

/// For j in 1..k, writes `out[j(j−1)/2 + i] = Σ_f P[f,i] N[f,j] − N[f,i] P[f,j]`
/// for i < j (see the private portable body for the loop). `rows` must hold `kp` values per row with
/// `kp` a multiple of 8 (the AVX-512 kernel reads whole vectors of 8; the
/// values past k in each row are read but never affect the output).
pub fn wedge_sums(fan: &Fan<'_>, out: &mut [f64]) {
    let (kp, k) = (fan.kp, fan.k);
    assert!(kp.is_multiple_of(8) && kp >= k && fan.prev.len() == fan.next.len());
    let whole_row = |&v: &usize| (v + 1) * kp <= fan.rows.len();
    assert!(fan.prev.iter().chain(fan.next).all(whole_row));
    assert!(out.len() >= k * k.saturating_sub(1) / 2);
    #[cfg(target_arch = "x86_64")]
    {
        if crate::has_v4() {
            // SAFETY: the CPU supports AVX-512F (checked just above); the
            // bounds the kernel relies on are asserted above.
            return unsafe { x86::wedge_sums_avx512(fan, out) };
        }
        if crate::has_v3() {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            return unsafe { x86::wedge_sums_avx2(fan, out) };
        }
    }
    wedge_sums_body::<false>(fan, out)
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::Fan;
    use std::arch::x86_64::*;

    /// [`wedge_sums_body`](super::wedge_sums_body) with register tiles of
    /// up to 32 rows i x 4 columns j (16 accumulators, each a chain of
    /// 2·deg multiply-adds; per face, NV row loads and 8 broadcasts feed
    /// 8·NV multiply-adds), the tile height cut to the rows the columns
    /// need in steps of 8. Writes only the k(k−1)/2 results (masked stores
    /// at the ends of columns).
    ///
    /// # Safety
    /// AVX-512F must be available; every index in `prev` and `next` must
    /// address a whole row of `kp` values of `rows`, kp a multiple of 8 and
    /// ≥ k (checked by the caller).
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn wedge_sums_avx512(fan: &Fan<'_>, out: &mut [f64]) {
        let k = fan.k;
        let mut j = 1;
        while j < k {
            let cols = (k - j).min(W);
            // Rows needed by the last column of the tile.
            let need = j + cols - 1;
            let mut i0 = 0;
            while i0 < need {
                let nv = (need - i0).div_ceil(8).min(4);
                // SAFETY: forwarded from the caller; rows i0 .. i0 + 8 nv lie
                // within kp (i0 + 8 nv ≤ round_up(need, 8) ≤ kp).
                unsafe {
                    match nv {
                        1 => tile::<1>(fan, out, j, cols, i0),
                        2 => tile::<2>(fan, out, j, cols, i0),
                        3 => tile::<3>(fan, out, j, cols, i0),
                        _ => tile::<4>(fan, out, j, cols, i0),
                    }
                }
                i0 += 32;
            }
            j += cols;
        }
    }

    /// Columns per tile.
    const W: usize = 4;

    /// One tile: rows i0 .. i0 + 8 NV of columns j .. j + cols.
    ///
    /// # Safety
    /// As [`wedge_sums_avx512`], and i0 + 8 NV ≤ kp.
    #[target_feature(enable = "avx512f")]
    unsafe fn tile<const NV: usize>(
        fan: &Fan<'_>,
        out: &mut [f64],
        j: usize,
        cols: usize,
        i0: usize,
    ) {
        let Fan {
            rows,
            kp,
            k,
            prev,
            next,
        } = *fan;
        // Columns past the tile repeat its last one (never stored).
        let jc: [usize; W] = std::array::from_fn(|c| (j + c).min(k - 1));
        let mut acc = [[_mm512_setzero_pd(); NV]; W];
        let base = rows.as_ptr();
        for (&pf, &nf) in prev.iter().zip(next) {
            // SAFETY: rows pf and nf hold kp values and i0 + 8 NV ≤ kp, jc < k ≤ kp.
            unsafe {
                let (pr, nr) = (base.add(pf * kp), base.add(nf * kp));
                let pv: [__m512d; NV] =
                    std::array::from_fn(|v| _mm512_loadu_pd(pr.add(i0 + 8 * v)));
                let nv: [__m512d; NV] =
                    std::array::from_fn(|v| _mm512_loadu_pd(nr.add(i0 + 8 * v)));
                for c in 0..W {
                    let a = _mm512_set1_pd(*nr.add(jc[c]));
                    let b = _mm512_set1_pd(-*pr.add(jc[c]));
                    for v in 0..NV {
                        let t = _mm512_fmadd_pd(pv[v], a, acc[c][v]);
                        acc[c][v] = _mm512_fmadd_pd(nv[v], b, t);
                    }
                }
            }
        }
        for (c, acc) in acc.iter().enumerate().take(cols) {
            let col = j + c;
            if i0 >= col {
                continue;
            }
            let len = (col - i0).min(8 * NV);
            let dst = &mut out[col * (col - 1) / 2 + i0..][..len];
            for (v, a) in acc.iter().enumerate().take(len.div_ceil(8)) {
                let m = (len - 8 * v).min(8);
                // SAFETY: lanes 8v .. 8v + m of dst exist (m ≤ len − 8v), and
                // the mask enables exactly those m lanes.
                unsafe {
                    _mm512_mask_storeu_pd(dst.as_mut_ptr().add(8 * v), ((1u16 << m) - 1) as u8, *a);
                }
            }
        }
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn wedge_sums_avx2(fan: &Fan<'_>, out: &mut [f64]) {
        super::wedge_sums_body::<true>(fan, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The dispatched kernel and the portable body both equal the naive
    /// double sum, for sizes on and off the tile edges (k = 1 … 70, fan
    /// sizes 1 … 9), and write every output entry.
    #[test]
    fn wedge_sums_match_the_definition() {
        for k in [1usize, 2, 7, 8, 9, 33, 40, 50, 64, 70] {
            let kp = k.div_ceil(8) * 8;
            let n = 12;
            let rows: Vec<f64> = (0..n * kp)
                .map(|t| {
                    if t % kp < k {
                        ((t * 7919) % 1013) as f64 / 1013.0 - 0.5
                    } else {
                        0.0
                    }
                })
                .collect();
            for deg in [1usize, 3, 6, 9] {
                let prev: Vec<usize> = (0..deg).map(|f| (f * 5 + 1) % n).collect();
                let next: Vec<usize> = (0..deg).map(|f| (f * 7 + 3) % n).collect();
                let m = k * k.saturating_sub(1) / 2;
                let mut want = vec![0.0; m];
                let mut t = 0;
                for j in 1..k {
                    for i in 0..j {
                        want[t] = (0..deg)
                            .map(|f| {
                                let (p, q) = (prev[f] * kp, next[f] * kp);
                                rows[p + i] * rows[q + j] - rows[q + i] * rows[p + j]
                            })
                            .sum();
                        t += 1;
                    }
                }
                let mut fast = vec![f64::NAN; m];
                let fan = Fan {
                    rows: &rows,
                    kp,
                    k,
                    prev: &prev,
                    next: &next,
                };
                wedge_sums(&fan, &mut fast);
                let mut plain = vec![f64::NAN; m];
                wedge_sums_body::<false>(&fan, &mut plain);
                for t in 0..m {
                    assert!((fast[t] - want[t]).abs() < 1e-13, "k {k} deg {deg} at {t}");
                    assert!((plain[t] - want[t]).abs() < 1e-13, "k {k} deg {deg} at {t}");
                }
            }
        }
    }
}
