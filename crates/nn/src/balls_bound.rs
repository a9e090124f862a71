//! The ball search's tangent bound (see [`super`]): per (query, ball),
//! a lower bound on the squared distance to the ball's rows from the
//! query's f32 products with the ball's centre and directions; and an
//! AVX-512 filter that computes the same bounds for eight balls at a
//! time, so that only the balls it keeps take the scalar path.

use super::{BallData, TANGENT};

/// A lower bound on the squared distance from `q` to every row of ball
/// `j`, from its tangent box: with `v = q − c`, `t = Uv` and `P` the
/// orthogonal projector onto the directions' span, `|q − x|² = |P(v −
/// e)|² + |P⊥(v − e)|² ≥ |t − a|² / (1 + η) + (|P⊥v| − r⊥)₊²` for every
/// row `x = c + e` (coordinates `a = Ue` inside the box, `|P⊥e| ≤ r⊥`),
/// and `|P⊥v|² ≥ |v|² − |t|² / (1 − η)`; also the plain `(|v| − r)₊²`.
/// `|v|²` comes from `|q|² + |c|² − 2 q·c` (`qc` = q·c) and `t` from `Uq
/// − Uc` (`uq` = Uq), each moved the safe way by the slack `sl` relative
/// to the norms involved.
///
/// `None` when the box part alone, `|t − a|²(1 − η)`, already puts the
/// ball beyond `cutoff` (the rest of the bound, which needs the square
/// roots, is then not computed): the whole bound is at least that part,
/// in floating point too (the same rounded terms, then a sum of
/// non-negative terms, a max and the same factor: all monotone).
/// `q_norm`: `|q|` (`√qn`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn tangent_bound(
    this: &BallData,
    j: usize,
    (qn, q_norm): (f64, f64),
    qc: f64,
    uq: &[f64],
    err: Err32,
    sl: f64,
    cutoff: f64,
) -> Option<Tangent> {
    let eps = sl * (q_norm + this.c_len[j]) + err.uq + f64::MIN_POSITIVE;
    let (lo, hi) = (
        &this.geo.box_lo[j * TANGENT..(j + 1) * TANGENT],
        &this.geo.box_hi[j * TANGENT..(j + 1) * TANGENT],
    );
    let uc = &this.geo.uc[j * TANGENT..(j + 1) * TANGENT];
    let (mut gap2, mut t2) = (0.0, 0.0);
    let mut t = [0.0; TANGENT];
    for i in 0..TANGENT {
        let ti = uq[i] - uc[i];
        t[i] = ti;
        t2 += ti * ti;
        let g = ((lo[i] - ti).max(ti - hi[i]) - eps).max(0.0);
        gap2 += g * g;
    }
    let eta = this.geo.eta;
    if gap2 * (1.0 - eta) * (1.0 - 2.0 * sl) > cutoff {
        return None;
    }
    let s = qn + this.c_norm[j];
    let v2_lo = (s - 2.0 * qc - sl * s - err.qc).max(0.0);
    let v2_hi = (s - 2.0 * qc + sl * s + err.qc).max(0.0);
    let dc_lo = v2_lo.sqrt() * (1.0 - sl);
    let dc_hi = v2_hi.sqrt() * (1.0 + sl);
    let tn = t2.sqrt() + 2.0 * eps;
    let perp = (v2_lo - tn * tn * (1.0 + 2.0 * eta)).max(0.0).sqrt() * (1.0 - sl);
    let pb = (perp - this.geo.r_perp[j]).max(0.0);
    let plain = (dc_lo - this.geo.radii[j]).max(0.0);
    Some(Tangent {
        lb2: (gap2 * (1.0 - eta) + pb * pb).max(plain * plain) * (1.0 - 2.0 * sl),
        t,
        eps,
        perp,
        dc_lo,
        dc_hi,
    })
}

/// Bounds on the errors of [`tangent_bound`]'s inputs computed in f32:
/// `2 q·c` (`qc`) and each `u·q` (`uq`).
#[derive(Clone, Copy)]
pub(super) struct Err32 {
    pub(super) qc: f64,
    pub(super) uq: f64,
}

/// [`tangent_bound`]'s results: the ball's bound, the query's
/// coordinates `t` along its directions (each within `eps` of the exact
/// ones) and a lower bound `perp` on its distance to their span.
#[derive(Clone, Copy)]
pub(super) struct Tangent {
    pub(super) lb2: f64,
    pub(super) t: [f64; TANGENT],
    pub(super) eps: f64,
    pub(super) perp: f64,
    /// Bounds on |q − c|.
    pub(super) dc_lo: f64,
    pub(super) dc_hi: f64,
}

/// One query's inputs of [`tangent_filter_avx512`]: `|q|²`, `|q|`, its
/// shares of the f32 products' errors (with the centres, along the
/// directions) and the slack.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct BoundQuery {
    pub(super) qn: f64,
    pub(super) q_norm: f64,
    pub(super) q_err: f64,
    pub(super) t_err: f64,
    pub(super) sl: f64,
}

/// The balls of `list` (one query's, in order) whose [`tangent_bound`]
/// may be at most `cutoff`, written to `keep` in order; returns how many.
/// `slot[j]`: ball j's place among the block's candidates, whose
/// directions' products with the query are `tcol` (`TANGENT` per slot);
/// `g[j]`: the query's product with ball j's centre.
///
/// Eight balls at a time, with the scalar bound's operations in its
/// order (no fused multiply-adds), so the bounds are the same; a ball is
/// dropped only when its bound exceeds `cutoff` by a relative 2⁻⁴⁰ (far
/// more than any rounding), so every ball the scalar bound keeps is kept
/// whatever the last bits: the caller decides on the kept ones with
/// [`tangent_bound`] itself.
///
/// # Safety
///
/// The CPU must have AVX-512 F and VL, and POPCNT (x86-64-v4). Every
/// ball of `list` must be below `g.len()` and `slot.len()`, with a slot
/// whose products lie in `tcol`; `keep` must hold `list.len() + 8`
/// entries (whole vectors of eight are stored).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,popcnt")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn tangent_filter_avx512(
    this: &BallData,
    list: &[u32],
    slot: &[u32],
    tcol: &[f32],
    g: &[f32],
    q: BoundQuery,
    cutoff: f64,
    keep: &mut [u32],
) -> usize {
    use std::arch::x86_64::*;
    assert!(
        keep.len() >= list.len() + 8,
        "`keep` has no room for whole vectors"
    );
    let geo = &this.geo;
    let eta = geo.eta;
    let sl = q.sl;
    let v = _mm512_set1_pd;
    let (zero, two) = (_mm512_setzero_pd(), v(2.0));
    let (sl_v, q_norm, t_err, qn, q_err) = (v(sl), v(q.q_norm), v(q.t_err), v(q.qn), v(q.q_err));
    let (flat, bend, down, keep2) = (
        v(1.0 - eta),
        v(1.0 + 2.0 * eta),
        v(1.0 - sl),
        v(1.0 - 2.0 * sl),
    );
    let tiny = v(f64::MIN_POSITIVE);
    let bar = v(cutoff * (1.0 + 2f64.powi(-40)) + f64::MIN_POSITIVE);
    let mut n = 0;
    let mut k = 0;
    while k < list.len() {
        let left = list.len() - k;
        let valid: __mmask8 = if left >= 8 { 0xff } else { (1u8 << left) - 1 };
        // SAFETY (all loads and gathers below): lanes outside `valid` are
        // neither loaded nor gathered; the balls of `list` index every
        // per-ball array (m entries, TANGENT per ball for the boxes), their
        // slots `tcol` (the caller's contract).
        let (eps, gap2, t2, v2_lo, r_perp, radii) = unsafe {
            let j = _mm256_maskz_loadu_epi32(valid, list.as_ptr().add(k).cast());
            let z = _mm256_setzero_si256();
            let gd = |a: &[f64]| _mm512_mask_i32gather_pd::<8>(zero, valid, j, a.as_ptr().cast());
            let c_len = gd(&this.c_len);
            let eps = _mm512_add_pd(
                _mm512_add_pd(_mm512_mul_pd(sl_v, _mm512_add_pd(q_norm, c_len)), t_err),
                tiny,
            );
            // (Each ball and slot has TANGENT entries.)
            let per = _mm256_set1_epi32(TANGENT as i32);
            let s_idx = _mm256_mullo_epi32(
                _mm256_mmask_i32gather_epi32::<4>(z, valid, j, slot.as_ptr().cast()),
                per,
            );
            let j4 = _mm256_mullo_epi32(j, per);
            let (mut gap2, mut t2) = (zero, zero);
            for t in 0..TANGENT {
                let tt = _mm256_set1_epi32(t as i32);
                let (ji, si) = (_mm256_add_epi32(j4, tt), _mm256_add_epi32(s_idx, tt));
                let uq = _mm512_cvtps_pd(_mm256_mmask_i32gather_ps::<4>(
                    _mm256_setzero_ps(),
                    valid,
                    si,
                    tcol.as_ptr().cast(),
                ));
                let gt =
                    |a: &[f64]| _mm512_mask_i32gather_pd::<8>(zero, valid, ji, a.as_ptr().cast());
                let ti = _mm512_sub_pd(uq, gt(&geo.uc));
                t2 = _mm512_add_pd(t2, _mm512_mul_pd(ti, ti));
                let out = _mm512_max_pd(
                    _mm512_sub_pd(gt(&geo.box_lo), ti),
                    _mm512_sub_pd(ti, gt(&geo.box_hi)),
                );
                let gg = _mm512_max_pd(_mm512_sub_pd(out, eps), zero);
                gap2 = _mm512_add_pd(gap2, _mm512_mul_pd(gg, gg));
            }
            let s = _mm512_add_pd(qn, gd(&this.c_norm));
            let qc = _mm512_cvtps_pd(_mm256_mmask_i32gather_ps::<4>(
                _mm256_setzero_ps(),
                valid,
                j,
                g.as_ptr().cast(),
            ));
            let err_qc = _mm512_add_pd(q_err, gd(&this.c_err));
            let v2 = _mm512_sub_pd(
                _mm512_sub_pd(s, _mm512_mul_pd(two, qc)),
                _mm512_mul_pd(sl_v, s),
            );
            let v2_lo = _mm512_max_pd(_mm512_sub_pd(v2, err_qc), zero);
            (eps, gap2, t2, v2_lo, gd(&geo.r_perp), gd(&geo.radii))
        };
        let dc_lo = _mm512_mul_pd(_mm512_sqrt_pd(v2_lo), down);
        let tn = _mm512_add_pd(_mm512_sqrt_pd(t2), _mm512_mul_pd(two, eps));
        let p2 = _mm512_sub_pd(v2_lo, _mm512_mul_pd(_mm512_mul_pd(tn, tn), bend));
        let perp = _mm512_mul_pd(_mm512_sqrt_pd(_mm512_max_pd(p2, zero)), down);
        let pb = _mm512_max_pd(_mm512_sub_pd(perp, r_perp), zero);
        let plain = _mm512_max_pd(_mm512_sub_pd(dc_lo, radii), zero);
        let lt = _mm512_add_pd(_mm512_mul_pd(gap2, flat), _mm512_mul_pd(pb, pb));
        let lb2 = _mm512_mul_pd(_mm512_max_pd(lt, _mm512_mul_pd(plain, plain)), keep2);
        let pass = _mm512_mask_cmp_pd_mask::<_CMP_LE_OQ>(valid, lb2, bar);
        // The kept indices compressed in a register (merging, not
        // zeroing) and stored whole: see `plain_pass_avx512`.
        // SAFETY: n ≤ k < list.len(), so the eight lanes stored end
        // before list.len() + 8 ≤ keep.len().
        unsafe {
            let j = _mm256_maskz_loadu_epi32(valid, list.as_ptr().add(k).cast());
            _mm256_storeu_si256(
                keep.as_mut_ptr().add(n).cast(),
                _mm256_mask_compress_epi32(j, pass, j),
            );
        }
        n += pass.count_ones() as usize;
        k += 8;
    }
    n
}
