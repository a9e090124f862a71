//! The ball search's tangent bound (see [`super`]): per (query, ball),
//! a lower bound on the squared distance to the ball's rows from the
//! query's f32 products with the ball's centre and directions; and an
//! AVX-512 filter that computes the same bounds for eight balls at a
//! time, so that only the balls it keeps take the scalar path.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatRef, Par};

use super::{BallData, BallWork, QUERY_BLOCK, TANGENT};

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

/// The f32 products of a block's `len` queries `qb` (row-major, `d =
/// this.d` columns) with the directions of its candidate balls
/// (`work.cands`, in their slots) into `work.tq`: query i's from `i
/// TANGENT n_cand`, `TANGENT` per slot. `sparse` (AVX-512 only): only
/// the pairs whose ball passed the query's plain test (`work.p_list`), the
/// other slots keeping stale products, which the AVX-512 filter masks
/// out; else all of them, by one GEMM (faer's kernels dispatch on their
/// own; per-pair products lost to it with AVX2).
pub(super) fn direction_products(
    this: &BallData,
    qb: &[f32],
    len: usize,
    work: &mut BallWork,
    sparse: bool,
) {
    let (d, n_cand) = (this.d, work.cands.len());
    let nc3 = n_cand * TANGENT;
    if work.tq.len() < nc3 * len {
        // (Room for every ball: allocated once, not regrown.)
        work.tq = vec![0.0; this.ranges.len().max(n_cand) * TANGENT * QUERY_BLOCK];
    }
    #[cfg(target_arch = "x86_64")]
    if sparse {
        // Per slot, its queries' bits.
        const { assert!(QUERY_BLOCK <= 64, "a block's queries fit a word") };
        let queries = &mut work.slots.queries;
        queries.clear();
        queries.resize(n_cand, 0);
        for i in 0..len {
            for &j in &work.p_list[work.p_start[i]..work.p_start[i + 1]] {
                queries[work.slot[j as usize] as usize] |= 1 << i;
            }
        }
        // SAFETY: `sparse` only with x86-64-v4 (the caller's check).
        unsafe {
            tangent_products_avx512(
                &this.tangent32,
                qb,
                d,
                &work.cands,
                &work.slots.queries,
                &mut work.tq,
            )
        };
        return;
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = sparse;
    work.ut.clear();
    for &j in &work.cands {
        let j = j as usize;
        work.ut
            .extend_from_slice(&this.tangent32[j * TANGENT * d..(j + 1) * TANGENT * d]);
    }
    matmul(
        faer::MatMut::from_column_major_slice_mut(&mut work.tq[..nc3 * len], nc3, len),
        Accum::Replace,
        MatRef::from_row_major_slice(&work.ut, nc3, d),
        MatRef::from_row_major_slice(qb, len, d).transpose(),
        1.0,
        Par::Seq,
    );
}

/// The f32 products of a block's queries (`q`: row-major, `d` columns)
/// with the candidate balls `cands` (directions `tangent`, `TANGENT x d`
/// per ball), only for the pairs that passed the plain test: slot s's
/// queries are the bits of `queries[s]`. Query i's products with slot s
/// go to `out[i nc3 + TANGENT s..][..TANGENT]` (`nc3` = `TANGENT
/// cands.len()`). Their error is within the GEMM's bound (`score_err`: a
/// length-d f32 dot product in any order, from the same f32 operands).
/// Ball by ball (its directions stay in L1), four of its queries at a
/// time (twelve independent chains of fused multiply-adds: fewer
/// roundings than the bound allows for).
///
/// # Safety
///
/// The CPU must have AVX-512 F (and FMA).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma,bmi1")]
unsafe fn tangent_products_avx512(
    tangent: &[f32],
    q: &[f32],
    d: usize,
    cands: &[u32],
    queries: &[u64],
    out: &mut [f32],
) {
    use std::arch::x86_64::*;
    const G: usize = 4;
    const { assert!(TANGENT == 3, "three products per query fit a 128-bit lane") };
    let nc3 = TANGENT * cands.len();
    let whole = d - d % 16;
    let tail: __mmask16 = ((1u32 << (d % 16)) - 1) as __mmask16;
    for (s, (&j, &mask)) in cands.iter().zip(queries).enumerate() {
        let u = &tangent[j as usize * TANGENT * d..(j as usize + 1) * TANGENT * d];
        let mut bits = mask;
        while bits != 0 {
            // Up to G of the ball's queries (the first repeated to fill).
            let mut at = [0usize; G];
            for g in 0..G {
                at[g] = if bits != 0 {
                    bits.trailing_zeros() as usize
                } else {
                    at[0]
                };
                bits &= bits.wrapping_sub(1);
            }
            for &i in &at {
                assert!(
                    (i + 1) * d <= q.len() && i * nc3 + TANGENT * (s + 1) <= out.len(),
                    "a query past the block or its products"
                );
            }
            let mut acc = [[_mm512_setzero_ps(); TANGENT]; G];
            // SAFETY: every load lies within a query's row (checked
            // above) or the ball's directions `u` (3 d floats): whole
            // chunks below `whole`, then the tail masked to d.
            unsafe {
                let up = u.as_ptr();
                let qp: [*const f32; G] = std::array::from_fn(|g| q.as_ptr().add(at[g] * d));
                let mut c = 0;
                while c < whole {
                    let ut: [__m512; TANGENT] =
                        std::array::from_fn(|t| _mm512_loadu_ps(up.add(t * d + c)));
                    for g in 0..G {
                        let qc = _mm512_loadu_ps(qp[g].add(c));
                        for t in 0..TANGENT {
                            acc[g][t] = _mm512_fmadd_ps(ut[t], qc, acc[g][t]);
                        }
                    }
                    c += 16;
                }
                if tail != 0 {
                    let ut: [__m512; TANGENT] =
                        std::array::from_fn(|t| _mm512_maskz_loadu_ps(tail, up.add(t * d + c)));
                    for g in 0..G {
                        let qc = _mm512_maskz_loadu_ps(tail, qp[g].add(c));
                        for t in 0..TANGENT {
                            acc[g][t] = _mm512_fmadd_ps(ut[t], qc, acc[g][t]);
                        }
                    }
                }
            }
            // The twelve sums at once: per direction t, the four queries'
            // accumulators folded to one vector whose 128-bit lane g holds
            // four partial sums of query g's; then within the lanes, so
            // that lane g ends as query g's three products (and a copy).
            let fold: [__m512; TANGENT] = std::array::from_fn(|t| {
                let pair = |a: __m512, b: __m512| {
                    _mm512_add_ps(
                        _mm512_shuffle_f32x4::<0x44>(a, b),
                        _mm512_shuffle_f32x4::<0xEE>(a, b),
                    )
                };
                let (ab, cd) = (pair(acc[0][t], acc[1][t]), pair(acc[2][t], acc[3][t]));
                _mm512_add_ps(
                    _mm512_shuffle_f32x4::<0x88>(ab, cd),
                    _mm512_shuffle_f32x4::<0xDD>(ab, cd),
                )
            });
            let half = |a: __m512, b: __m512| {
                _mm512_add_ps(
                    _mm512_shuffle_ps::<0x88>(a, b),
                    _mm512_shuffle_ps::<0xDD>(a, b),
                )
            };
            let (p, r) = (half(fold[0], fold[1]), half(fold[2], fold[2]));
            let sums = half(p, r);
            let lanes = [
                _mm512_castps512_ps128(sums),
                _mm512_extractf32x4_ps::<1>(sums),
                _mm512_extractf32x4_ps::<2>(sums),
                _mm512_extractf32x4_ps::<3>(sums),
            ];
            for g in 0..G {
                let o = at[g] * nc3 + TANGENT * s;
                // SAFETY: the three floats from `o` lie within `out`
                // (checked above).
                unsafe { _mm_mask_storeu_ps(out.as_mut_ptr().add(o), 0b111, lanes[g]) };
            }
        }
    }
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

/// One query's inputs of [`tangent_filter_avx512`]: its place in the
/// block, `|q|²`, `|q|`, its
/// shares of the f32 products' errors (with the centres, along the
/// directions) and the slack.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct BoundQuery {
    /// The query's place in its block (its bit in `SlotData::queries`).
    pub(super) i: usize,
    pub(super) qn: f64,
    pub(super) q_norm: f64,
    pub(super) q_err: f64,
    pub(super) t_err: f64,
    pub(super) sl: f64,
}

/// The per-ball data of [`tangent_bound`] for a block's candidate balls,
/// in their slot order, one field after another (one entry per
/// candidate each): the
/// AVX-512 filter reads eight slots with plain loads, where its gathers
/// by ball index (nineteen per eight balls) were the slow part on AMD
/// Zen 4 (docs/tuning.md).
#[cfg(target_arch = "x86_64")]
#[derive(Default)]
pub(super) struct SlotData {
    v: Vec<f64>,
    /// Per slot, the block's queries whose plain test it passed (a bit
    /// per query).
    pub(super) queries: Vec<u64>,
}

/// Fields of [`SlotData`]: `c_len`, `c_norm`, `c_err`, `r_perp`, `radii`,
/// then `TANGENT` each of `uc`, `box_lo` and `box_hi`.
#[cfg(target_arch = "x86_64")]
const FIELDS: usize = 5 + 3 * TANGENT;

#[cfg(target_arch = "x86_64")]
impl SlotData {
    /// The data of the balls `cands` (slot s: ball `cands[s]`).
    pub(super) fn fill(&mut self, this: &BallData, cands: &[u32]) {
        let geo = &this.geo;
        self.v.clear();
        for a in [
            &this.c_len,
            &this.c_norm,
            &this.c_err,
            &geo.r_perp,
            &geo.radii,
        ] {
            self.v.extend(cands.iter().map(|&j| a[j as usize]));
        }
        for a in [&geo.uc, &geo.box_lo, &geo.box_hi] {
            for t in 0..TANGENT {
                self.v
                    .extend(cands.iter().map(|&j| a[j as usize * TANGENT + t]));
            }
        }
    }
}

/// The candidate balls (`cands`, in slot order) that passed query `q.i`'s
/// plain test (its bit in [`SlotData`]'s `queries`) whose
/// [`tangent_bound`] may be at most `cutoff`, written to `keep` in slot
/// order; returns how many. `slots`: the candidates' data
/// ([`SlotData::fill`] of `cands`); `tcol`: the query's products with
/// their directions (`TANGENT` per slot, in slot order); `g[j]`: the
/// query's product with ball j's centre; `eta`: the directions' departure
/// from orthonormality.
///
/// Eight slots at a time, with the scalar bound's operations in its
/// order (no fused multiply-adds), so the bounds are the same; a ball is
/// dropped only when its bound exceeds `cutoff` by a relative 2⁻⁴⁰ (far
/// more than any rounding), so every ball the scalar bound keeps is kept
/// whatever the last bits: the caller decides on the kept ones with
/// [`tangent_bound`] itself.
///
/// # Safety
///
/// The CPU must have AVX-512 F and VL, and POPCNT (x86-64-v4). Every
/// ball of `cands` must be below `g.len()`; `slots` must hold the data
/// and the queries' bits of `cands`, `tcol` `TANGENT` products per slot;
/// `keep` must hold `cands.len() + 8` entries (whole vectors of eight are
/// stored).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,popcnt")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn tangent_filter_avx512(
    slots: &SlotData,
    eta: f64,
    cands: &[u32],
    tcol: &[f32],
    g: &[f32],
    q: BoundQuery,
    cutoff: f64,
    keep: &mut [u32],
) -> usize {
    use std::arch::x86_64::*;
    const {
        assert!(
            TANGENT * 8 <= 32,
            "one slot chunk's products fit two vectors"
        )
    };
    let nc = cands.len();
    assert!(
        slots.v.len() == FIELDS * nc
            && tcol.len() >= TANGENT * nc
            && slots.queries.len() == nc
            && q.i < 64
            && keep.len() >= nc + 8,
        "the candidates' data, products, bits or room for whole vectors fall short"
    );
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
    // Per direction t, lane i picks float TANGENT i + t of a chunk's 24
    // products (16 on: of the second vector).
    let lanes = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    let picks: [__m512i; TANGENT] = std::array::from_fn(|t| {
        _mm512_add_epi32(
            _mm512_mullo_epi32(lanes, _mm512_set1_epi32(TANGENT as i32)),
            _mm512_set1_epi32(t as i32),
        )
    });
    let qbit = _mm512_set1_epi64(1 << q.i);
    let mut n = 0;
    let mut k = 0;
    while k < nc {
        let left = nc - k;
        let tail: u8 = if left >= 8 { 0xff } else { (1u8 << left) - 1 };
        // The slots whose plain test query q.i passed.
        // SAFETY: the load is masked to the candidates' slots.
        let valid: __mmask8 = unsafe {
            let bits = _mm512_maskz_loadu_epi64(tail, slots.queries.as_ptr().add(k).cast());
            _mm512_mask_test_epi64_mask(tail, bits, qbit)
        };
        if valid == 0 {
            k += 8;
            continue;
        }
        // SAFETY (all loads and the gather below): lanes outside `valid`
        // are neither loaded nor gathered; `valid` lies within slots
        // k..min(k + 8, nc); every field of `slots` holds nc entries,
        // `tcol` TANGENT nc (the products' loads are masked to them); the
        // candidates index `g`.
        // (TANGENT x 8 = 24 ≤ 32 floats: `lo` and `hi` hold them all.)
        let (j, eps, gap2, t2, v2_lo, r_perp, radii) = unsafe {
            let field = |f: usize| _mm512_maskz_loadu_pd(valid, slots.v.as_ptr().add(f * nc + k));
            let j = _mm256_maskz_loadu_epi32(valid, cands.as_ptr().add(k).cast());
            let eps = _mm512_add_pd(
                _mm512_add_pd(_mm512_mul_pd(sl_v, _mm512_add_pd(q_norm, field(0))), t_err),
                tiny,
            );
            // The products of slots k..k + 8, TANGENT each (24 floats,
            // none read past the candidates'), split by direction below.
            let left = TANGENT * (nc - k);
            let (lo, hi) = (
                _mm512_maskz_loadu_ps(low_bits16(left), tcol.as_ptr().add(TANGENT * k)),
                _mm512_maskz_loadu_ps(
                    low_bits16(left.saturating_sub(16)),
                    tcol.as_ptr().add(TANGENT * k + 16),
                ),
            );
            let (mut gap2, mut t2) = (zero, zero);
            for t in 0..TANGENT {
                let uq = _mm512_cvtps_pd(_mm512_castps512_ps256(_mm512_permutex2var_ps(
                    lo, picks[t], hi,
                )));
                let ti = _mm512_sub_pd(uq, field(5 + t));
                t2 = _mm512_add_pd(t2, _mm512_mul_pd(ti, ti));
                let out = _mm512_max_pd(
                    _mm512_sub_pd(field(5 + TANGENT + t), ti),
                    _mm512_sub_pd(ti, field(5 + 2 * TANGENT + t)),
                );
                let gg = _mm512_max_pd(_mm512_sub_pd(out, eps), zero);
                gap2 = _mm512_add_pd(gap2, _mm512_mul_pd(gg, gg));
            }
            let s = _mm512_add_pd(qn, field(1));
            let qc = _mm512_cvtps_pd(_mm256_mmask_i32gather_ps::<4>(
                _mm256_setzero_ps(),
                valid,
                j,
                g.as_ptr().cast(),
            ));
            let err_qc = _mm512_add_pd(q_err, field(2));
            let v2 = _mm512_sub_pd(
                _mm512_sub_pd(s, _mm512_mul_pd(two, qc)),
                _mm512_mul_pd(sl_v, s),
            );
            let v2_lo = _mm512_max_pd(_mm512_sub_pd(v2, err_qc), zero);
            (j, eps, gap2, t2, v2_lo, field(3), field(4))
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
        // The kept balls compressed in a register (merging, not zeroing)
        // and stored whole: see `plain_pass_avx512`.
        // SAFETY: n ≤ k < nc, so the eight lanes stored end before
        // nc + 8 ≤ keep.len().
        unsafe {
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

/// The mask of the lowest `n` of sixteen lanes.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn low_bits16(n: usize) -> u16 {
    if n >= 16 { u16::MAX } else { (1u16 << n) - 1 }
}
