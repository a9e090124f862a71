//! The ball search's plain test (see [`super`]): for one query, the
//! balls whose plain bound `(|q − c| − r)₊` may be within its reach, from
//! its f32 dot products with the centres; a portable loop, and an
//! AVX-512 kernel with the same operations (the same passing balls).

use super::BallData;
#[cfg(target_arch = "x86_64")]
use super::PAD;

/// A query's plain-bound inputs: `|q|²`, its share of the f32 products'
/// error, the reach (the farthest its nearest row can be) and the slack.
#[derive(Clone, Copy)]
pub(super) struct Plain {
    pub(super) qn: f64,
    pub(super) q_err: f64,
    pub(super) reach: f64,
    pub(super) sl: f64,
}

/// The balls whose plain bound `(|q − c| − r)₊` may be within the reach,
/// in order, written to `list`; returns how many. `g`: the query's f32
/// dot products with the centres; `pass`: room for each ball's margin.
#[inline(always)]
pub(super) fn plain_pass(
    this: &BallData,
    g: &[f32],
    p: Plain,
    pass: &mut [f64],
    list: &mut [u32],
) -> usize {
    let m = pass.len();
    for ((((x, &cn), &gj), &r), &ce) in pass
        .iter_mut()
        .zip(&this.c_norm[..m])
        .zip(g)
        .zip(&this.geo.radii[..m])
        .zip(&this.c_err[..m])
    {
        let s = p.qn + cn;
        let lo2 = (s - 2.0 * f64::from(gj) - p.sl * s - (p.q_err + ce)) * (1.0 - 3.0 * p.sl);
        let far = p.reach + r;
        *x = lo2 - far * far;
    }
    // Eight balls' tests to a bit mask, then only the set bits visited.
    let mut n = 0;
    let chunks = pass.chunks_exact(8);
    let tail = chunks.remainder();
    for (c, ch) in chunks.enumerate() {
        let mut mask = 0u32;
        for l in 0..8 {
            mask |= u32::from(ch[l] <= 0.0) << l;
        }
        while mask != 0 {
            list[n] = (c * 8) as u32 + mask.trailing_zeros();
            n += 1;
            mask &= mask - 1;
        }
    }
    for (l, &x) in tail.iter().enumerate() {
        if x <= 0.0 {
            list[n] = (m - tail.len() + l) as u32;
            n += 1;
        }
    }
    n
}

/// [`plain_pass`] in AVX-512: the same operations on eight balls at a
/// time (no fused multiply-adds: the same margins, bit for bit), the
/// passing balls' indices compressed in a register per sixteen and
/// stored whole (the compressing store to memory is microcoded on AMD's
/// Zen 4, and there a compress with zeroing is several times slower than
/// one merging into a register: LLVM issues 133568 and 206849). `list`
/// holds the m balls' entries and [`PAD`] more (the last store may write
/// up to fifteen past the last ball).
///
/// # Safety
///
/// The CPU must have AVX-512 F and VL, and POPCNT (x86-64-v4). `g`, and
/// the balls' arrays, hold at least `list.len() − PAD` entries.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,popcnt")]
pub(super) unsafe fn plain_pass_avx512(
    this: &BallData,
    g: &[f32],
    p: Plain,
    list: &mut [u32],
) -> usize {
    use std::arch::x86_64::*;
    assert!(list.len() >= PAD, "the list has no room past its balls");
    let m = list.len() - PAD;
    let (c_norm, radii, c_err) = (&this.c_norm[..m], &this.geo.radii[..m], &this.c_err[..m]);
    let g = &g[..m];
    let (qn, q_err, reach) = (
        _mm512_set1_pd(p.qn),
        _mm512_set1_pd(p.q_err),
        _mm512_set1_pd(p.reach),
    );
    let (sl, two, keep) = (
        _mm512_set1_pd(p.sl),
        _mm512_set1_pd(2.0),
        _mm512_set1_pd(1.0 - 3.0 * p.sl),
    );
    let zero = _mm512_setzero_pd();
    // The margins of balls j..j + 8 (lanes past `valid` not loaded) and
    // which are at most 0.
    let margins = |j: usize, valid: __mmask8| -> __mmask8 {
        // SAFETY: masked loads read lanes j..j + 8 within `valid`, which
        // stop at m (every slice holds m values).
        let (cn, gj, r, ce) = unsafe {
            (
                _mm512_maskz_loadu_pd(valid, c_norm.as_ptr().add(j)),
                _mm512_cvtps_pd(_mm256_maskz_loadu_ps(valid, g.as_ptr().add(j))),
                _mm512_maskz_loadu_pd(valid, radii.as_ptr().add(j)),
                _mm512_maskz_loadu_pd(valid, c_err.as_ptr().add(j)),
            )
        };
        let s = _mm512_add_pd(qn, cn);
        let t = _mm512_sub_pd(s, _mm512_mul_pd(two, gj));
        let t = _mm512_sub_pd(t, _mm512_mul_pd(sl, s));
        let t = _mm512_sub_pd(t, _mm512_add_pd(q_err, ce));
        let lo2 = _mm512_mul_pd(t, keep);
        let far = _mm512_add_pd(reach, r);
        let x = _mm512_sub_pd(lo2, _mm512_mul_pd(far, far));
        _mm512_mask_cmp_pd_mask::<_CMP_LE_OQ>(valid, x, zero)
    };
    let lanes = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    let mut n = 0;
    let mut j = 0;
    while j < m {
        let left = m - j;
        let lo: __mmask8 = if left >= 8 { 0xff } else { (1u8 << left) - 1 };
        let hi: __mmask8 = if left >= 16 {
            0xff
        } else if left > 8 {
            (1u8 << (left - 8)) - 1
        } else {
            0
        };
        let mask = u16::from(margins(j, lo))
            | u16::from(if hi != 0 { margins(j + 8, hi) } else { 0 }) << 8;
        let idx = _mm512_add_epi32(_mm512_set1_epi32(j as i32), lanes);
        // SAFETY: n ≤ j < m (each ball adds at most one entry), so the
        // sixteen lanes stored end before m + PAD ≤ list.len().
        unsafe {
            _mm512_storeu_si512(
                list.as_mut_ptr().add(n).cast(),
                _mm512_mask_compress_epi32(idx, mask, idx),
            )
        };
        n += mask.count_ones() as usize;
        j += 16;
    }
    n
}
