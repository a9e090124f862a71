//! Exact nearest neighbours ranked on the CPU's matrix tiles (Intel AMX,
//! bf16 dot products accumulated in f32): every query is compared with
//! every data row in the full dimension at ~6x the f32 GEMM rate, and the
//! rows whose bf16 score lies within a rigorous error bound of the best
//! are re-checked with direct f64 distances, so the answer is the exact
//! f64 nearest row (ties: the smallest index), as with every strategy.
//!
//! The bound, per query q against row x (q̃, x̃ their bf16 roundings,
//! flushed to zero below f32's normal range as the tiles do; ρ = 2⁻⁸ +
//! 2⁻²³ bounds the relative rounding of f64 → f32 → bf16): `q·x − q̃·x̃ =
//! q̃·(x − x̃) + (q − q̃)·x`, so `|q·x − q̃·x̃| ≤ |q̃| ρ |x| + |q − q̃| |x|`
//! (the query's residual computed exactly); the product of two bf16
//! numbers is exact in f32 and the f32 accumulation of d of them is off by
//! at most `γ |q̃||x̃|`, `γ = d 2⁻²⁴` (taken twice). With the f32 scan
//! (`|x|²` rounded, the subtraction) the computed score `s = |x|² − 2ĉ` is
//! within `K |x| + 2.01 u |x|²` of the true `|x|² − 2 q·x`, K per query;
//! and `|x| ≤ (|x|²/m + m)/2` for any m > 0 — m = |q|, near which the
//! nearest rows' norms lie — makes the bound `α |x|² + β`, so a scan needs
//! nothing per row beyond the score and `|x|²`. A chunk of rows whose
//! smallest lower end `(1 − α)|x|² − 2ĉ − β` is above the best distance
//! found so far (the guess's, when given) is skipped; otherwise its rows
//! whose lower end is under both that and the chunk's smallest upper end
//! get an f64 distance. Everything the f32 arithmetic of the scans adds is
//! covered by a per-query slack of a few u. In the worst case (every
//! coordinate rounding the same way) the bound is tight within 10%: a test
//! fails with 0.9 times it.
//!
//! The kernel: 2 x 2 tiles of 16 x 16 f32 results (32 data rows against
//! 32 queries), 32 coordinates per step, several times the f32 GEMM rate
//! (docs/tuning.md); the data packed once per search as 16 x 32 bf16 blocks,
//! the queries per block of 128 in the tiles' pair layout. Scores come out
//! one data row per 32 query lanes, so the scans (smallest lower and upper
//! ends, then the candidates) run down the rows with no horizontal
//! reductions.
//!
//! The tiles are used only where the CPU has them (AMX-TILE and AMX-BF16,
//! enabled in XCR0) and Linux grants the process their state
//! (`arch_prctl(ARCH_REQ_XCOMP_PERM)`); `FMAPS_NO_AMX=1` in the
//! environment turns them off. Everything else falls back to the f32
//! strategies.

use crate::rows::Rows;

/// Whether the matrix-tile search can run here (detected once, in
/// [`crate::cpu`]).
pub fn available() -> bool {
    crate::cpu::amx_available()
}

/// The exact nearest rows, ranked on the tiles; `None` when they are not
/// available or a row is not finite with a norm below 1e14
/// (where the bf16 products could overflow).
pub(crate) fn search_rows(
    data: Rows<'_>,
    queries: Rows<'_>,
    hint: Option<&[usize]>,
) -> Option<Vec<usize>> {
    let (nx, d) = data.shape();
    if !available() || d == 0 || nx == 0 || queries.shape().1 != d {
        return None;
    }
    imp::search(data, queries, hint)
}

/// The nearest representable bf16 (round to nearest, ties to even) of a
/// finite f64, through f32; values below f32's normal range become zero,
/// as the tiles treat them.
#[cfg_attr(
    not(all(target_arch = "x86_64", target_os = "linux")),
    allow(dead_code)
)]
#[inline(always)]
fn to_bf16(v: f64) -> u16 {
    let f = v as f32;
    let b = f.to_bits();
    let h = (b.wrapping_add(0x7fff + ((b >> 16) & 1)) >> 16) as u16;
    // Branch-free, so that loops of it vectorize.
    h * u16::from(f.abs() >= f32::MIN_POSITIVE)
}

/// The value of a bf16.
#[cfg_attr(
    not(all(target_arch = "x86_64", target_os = "linux")),
    allow(dead_code)
)]
#[inline(always)]
fn from_bf16(h: u16) -> f64 {
    f64::from(f32::from_bits(u32::from(h) << 16))
}

#[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
mod imp {
    pub fn search(
        _data: crate::rows::Rows<'_>,
        _queries: crate::rows::Rows<'_>,
        _hint: Option<&[usize]>,
    ) -> Option<Vec<usize>> {
        None
    }
}

#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
mod imp {
    use std::arch::asm;
    use std::arch::x86_64::*;

    use rayon::prelude::*;

    use super::{from_bf16, to_bf16};
    use crate::rows::{Rows, dist2_below};

    /// Queries per tile block (two tiles of 16 columns).
    const QT: usize = 32;
    /// Queries per parallel task: the data chunk in cache serves them all.
    const QB: usize = 128;
    /// Data rows per chunk (a multiple of 32).
    const CHUNK: usize = 256;

    /// The tile configuration: palette 1, eight tiles of 16 rows of 64
    /// bytes.
    #[repr(C, align(64))]
    struct Config([u8; 64]);

    impl Config {
        fn new() -> Config {
            let mut c = [0u8; 64];
            c[0] = 1;
            for t in 0..8 {
                c[16 + 2 * t] = 64;
                c[48 + t] = 16;
            }
            Config(c)
        }
    }

    /// Everything a block of queries needs.
    struct Ctx<'a> {
        d: usize,
        nx: usize,
        /// Padded dimension (a multiple of 32).
        dp: usize,
        /// Data rows in bf16, in tiles: for each group of 16 rows and each
        /// step of 32 coordinates, the 16 x 32 block row by row (1 KB,
        /// contiguous); padded with zero rows to a multiple of 32.
        xb: Aligned<u16>,
        /// Data rows (f64), for the re-checks.
        x_rows: Rows<'a>,
        /// |x|² in f32 (rounded), f32::MAX on the padding rows (never
        /// candidates, never an overflow).
        xn32: Vec<f32>,
        /// Largest |x|².
        xn_max: f64,
    }

    /// A zeroed buffer whose first element is 64-byte aligned, so that no
    /// tile row or 16-float line straddles two cache lines (unaligned
    /// score stores cost a visible share of ZoomOut: docs/tuning.md).
    struct Aligned<T> {
        buf: Vec<T>,
        off: usize,
        len: usize,
    }

    impl<T: Copy + Default> Aligned<T> {
        fn zeroed(len: usize) -> Aligned<T> {
            let size = std::mem::size_of::<T>();
            let buf = vec![T::default(); len + 64 / size];
            let off = ((64 - buf.as_ptr() as usize % 64) % 64) / size;
            Aligned { buf, off, len }
        }
    }

    impl<T> std::ops::Deref for Aligned<T> {
        type Target = [T];
        fn deref(&self) -> &[T] {
            &self.buf[self.off..self.off + self.len]
        }
    }

    impl<T> std::ops::DerefMut for Aligned<T> {
        fn deref_mut(&mut self) -> &mut [T] {
            &mut self.buf[self.off..self.off + self.len]
        }
    }

    /// `v` rounded up to f32.
    fn up32(v: f64) -> f32 {
        let r = v as f32;
        if f64::from(r) < v { r.next_up() } else { r }
    }

    pub fn search(
        x_rows: Rows<'_>,
        q_rows: Rows<'_>,
        hint: Option<&[usize]>,
    ) -> Option<Vec<usize>> {
        let ((nx, d), nq) = (x_rows.shape(), q_rows.shape().0);
        let dp = d.div_ceil(32) * 32;
        let nxp = nx.div_ceil(32) * 32;
        let mut xb = Aligned::<u16>::zeroed(nxp * dp);
        let mut xn = vec![0.0f64; nx];
        // Group by group of 16 rows (in parallel), row by row: bf16
        // values to their tiles, and |x|².
        let in_range = xb
            .par_chunks_mut(dp * 16)
            .zip(xn.par_chunks_mut(16))
            .enumerate()
            .map(|(g, (out, xn))| {
                let mut ok = true;
                for (rr, xn) in xn.iter_mut().enumerate() {
                    let r = g * 16 + rr;
                    let row = x_rows.row(r);
                    for (kc, part) in row.chunks(32).enumerate() {
                        let o = &mut out[kc * 512 + rr * 32..kc * 512 + rr * 32 + part.len()];
                        for (h, &v) in o.iter_mut().zip(part) {
                            *h = to_bf16(v);
                        }
                    }
                    *xn = row.iter().map(|v| v * v).sum();
                    ok &= within_range(*xn);
                }
                ok
            })
            .reduce(|| true, |a, b| a && b);
        if !in_range {
            return None;
        }
        let mut xn32: Vec<f32> = xn.iter().map(|&v| v as f32).collect();
        xn32.resize(nxp, f32::MAX);
        let ctx = Ctx {
            d,
            nx,
            dp,
            xb,
            x_rows,
            xn32,
            xn_max: xn.iter().fold(0.0f64, |a, &b| a.max(b)),
        };
        let starts: Vec<usize> = (0..nq).step_by(QB).collect();
        let found: Vec<Option<Vec<usize>>> = starts
            .par_iter()
            .map_init(
                || Work {
                    q: Aligned::zeroed(QB * dp),
                    s: Aligned::zeroed(CHUNK * QT),
                    cand: Vec::new(),
                },
                |work, &q0| {
                    let rows = QB.min(nq - q0);
                    let hint = hint.map(|h| &h[q0..q0 + rows]);
                    // SAFETY: `available()` checked the tiles and AVX-512F.
                    unsafe { block(&ctx, &q_rows, q0, rows, hint, work) }
                },
            )
            .collect();
        let mut out = Vec::with_capacity(nq);
        for block in found {
            out.extend(block?);
        }
        Some(out)
    }

    /// Whether a row whose squared norm was computed as `norm2` has every
    /// value finite and below 1e14 in magnitude (then no bf16 product or
    /// f32 sum of such values overflows): a NaN or an infinity makes the
    /// sum NaN or infinite, and each |v| is at most the norm.
    #[inline(always)]
    fn within_range(norm2: f64) -> bool {
        norm2 < 1e28
    }

    /// Per-thread buffers.
    struct Work {
        /// A block's queries in bf16 in the tiles' pair layout: groups of
        /// 16 queries; in a group, for each pair of coordinates (2p,
        /// 2p + 1), the 16 queries' two values (64 bytes).
        q: Aligned<u16>,
        /// Scores of a chunk of rows against QT queries (f32, one row of
        /// QT per data row).
        s: Aligned<f32>,
        /// Candidates of a chunk: (query lane, row in the chunk).
        cand: Vec<(u32, u32)>,
    }

    /// Per query lane of a tile block: the bound's factors, β and slack,
    /// and |q|².
    #[derive(Clone, Copy)]
    struct Lane {
        lo: f32,
        hi: f32,
        beta: f64,
        slack: f64,
        qn: f64,
    }

    /// The nearest rows of up to QB queries (`q_rows`, f64 row-major);
    /// `None` if a query is not [`within_range`].
    ///
    /// # Safety
    /// The CPU must have the tiles (and Linux must have granted them) and
    /// AVX-512F.
    #[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
    unsafe fn block(
        ctx: &Ctx<'_>,
        q_rows: &Rows<'_>,
        q0: usize,
        rows: usize,
        hint: Option<&[usize]>,
        work: &mut Work,
    ) -> Option<Vec<usize>> {
        let (d, dp, nx) = (ctx.d, ctx.dp, ctx.nx);
        let q_row = |i: usize| q_rows.row(q0 + i);
        let u = f64::from(f32::EPSILON) / 2.0;
        // Queries in bf16 (padding lanes and coordinates zero) and per
        // query the bound on |computed score − true score|.
        work.q.iter_mut().for_each(|v| *v = 0);
        let padding = Lane {
            lo: 1.0,
            hi: 1.0,
            beta: 0.0,
            slack: 0.0,
            qn: 0.0,
        };
        let mut lanes = vec![padding; rows.div_ceil(QT) * QT];
        // Relative rounding of f64 -> f32 -> bf16 and the accumulation.
        let rho = (2.0f64).powi(-8) + (2.0f64).powi(-23);
        let gamma = 2.0 * dp as f64 * u;
        let mut h = vec![0u16; dp];
        for i in 0..rows {
            let row = q_row(i);
            for (o, &v) in h.iter_mut().zip(row) {
                *o = to_bf16(v);
            }
            let group = &mut work.q[(i / 16) * dp * 16..(i / 16 + 1) * dp * 16];
            for (p, pair) in h.chunks_exact(2).enumerate() {
                group[p * 32 + (i % 16) * 2] = pair[0];
                group[p * 32 + (i % 16) * 2 + 1] = pair[1];
            }
            let (mut n2, mut r2) = ([0.0f64; 8], [0.0f64; 8]);
            let (rc, oc) = (row.chunks_exact(8), h[..d].chunks_exact(8));
            let (rest_v, rest_h) = (rc.remainder(), oc.remainder());
            for (vs, hs) in rc.zip(oc) {
                for l in 0..8 {
                    let (v, t) = (vs[l], from_bf16(hs[l]));
                    n2[l] += v * v;
                    r2[l] += (v - t) * (v - t);
                }
            }
            for (l, (&v, &hh)) in rest_v.iter().zip(rest_h).enumerate() {
                let t = from_bf16(hh);
                n2[l] += v * v;
                r2[l] += (v - t) * (v - t);
            }
            let sum = |a: [f64; 8]| a.iter().sum::<f64>();
            let (n2, rq) = (sum(n2), sum(r2).sqrt());
            if !within_range(n2) {
                return None;
            }
            let qt = (n2.sqrt() + rq) * (1.0 + 1e-15);
            // |s − t| <= K |x| + 2.01 u |x|² (module docs), and
            // |x| <= (|x|²/m + m)/2 for any m > 0; m = |q|, near which the
            // nearest rows' norms lie.
            let k = 2.0 * qt * rho + 2.0 * rq + (2.0 * gamma + 4.2 * u) * (1.0 + rho) * qt;
            // Absolute terms: row coordinates flushed to zero (each off by
            // less than f32's smallest normal), and products or partial
            // sums flushed by the tiles (2 per coordinate pair).
            let tiny = f64::from(f32::MIN_POSITIVE);
            let flushed = 2.0 * qt * (dp as f64).sqrt() * tiny + 4.0 * dp as f64 * tiny;
            let m = n2.sqrt().max(1e-150);
            let alpha = k / (2.0 * m) + 2.01 * u;
            let beta = k * m / 2.0 + flushed;
            // The f32 operations of the scans (the factors rounded, the
            // product, the subtraction): each off by at most u of a
            // magnitude below (1 + α)|x|² + 2|ĉ| + β.
            let e_max = alpha * ctx.xn_max + beta;
            lanes[i] = Lane {
                lo: (1.0 - alpha) as f32,
                hi: (1.0 + alpha) as f32,
                beta,
                slack: 8.0
                    * u
                    * (2.0 * ctx.xn_max + 2.0 * qt * ctx.xn_max.sqrt() * (1.0 + rho) + e_max)
                    + 1e-30,
                qn: n2,
            };
        }
        // The best row so far per query (f64 distance, index).
        let mut best: Vec<(f64, usize)> = (0..rows)
            .map(|i| {
                let q = q_row(i);
                match hint.map(|h| h[i]) {
                    Some(h) if h < nx => (dist(ctx, q, h), h),
                    _ => (f64::INFINITY, usize::MAX),
                }
            })
            .collect();
        let cfg = Config::new();
        // SAFETY: `available()` checked the CPU, the OS state and the
        // permission; the configuration is valid for palette 1.
        unsafe { asm!("ldtilecfg [{}]", in(reg) cfg.0.as_ptr(), options(nostack, readonly)) };
        let nxp = ctx.xn32.len();
        for c0 in (0..nxp).step_by(CHUNK) {
            let width = CHUNK.min(nxp - c0);
            let xn = &ctx.xn32[c0..c0 + width];
            for t0 in (0..rows).step_by(QT) {
                let lane = &lanes[t0..t0 + QT];
                // SAFETY: the tiles are configured; the query buffer holds
                // QB queries in groups of 16, the data nxp rows of dp
                // values, the score buffer CHUNK x QT.
                unsafe {
                    scores(
                        ctx.xb[c0 * dp..].as_ptr(),
                        dp,
                        work.q[t0 * dp..].as_ptr(),
                        width,
                        work.s.as_mut_ptr(),
                    );
                }
                let s = &work.s[..width * QT];
                let (lo_f, hi_f): ([f32; QT], [f32; QT]) = (
                    std::array::from_fn(|l| lane[l].lo),
                    std::array::from_fn(|l| lane[l].hi),
                );
                // SAFETY: AVX-512F (checked by `available()`).
                let (low, high) = unsafe { bounds(s, xn, &lo_f, &hi_f) };
                // Per lane: a row can be nearer than `best` only if the
                // lower end of its score's interval is at most the bar;
                // and the chunk's nearest row's true score is at most the
                // smallest upper end.
                let mut bar = [f32::NEG_INFINITY; QT];
                let mut any = false;
                for l in 0..QT.min(rows - t0) {
                    let (ln, b) = (lane[l], best[t0 + l].0);
                    let over =
                        b * (1.0 + 1e-12) + 1e-12 * ln.qn - ln.qn + ln.beta + ln.slack + 1e-300;
                    if f64::from(low[l]) > over {
                        continue;
                    }
                    bar[l] = up32(over.min(f64::from(high[l]) + 2.0 * ln.beta + 2.0 * ln.slack));
                    any = true;
                }
                if !any {
                    continue;
                }
                work.cand.clear();
                // SAFETY: as above.
                unsafe { under(s, xn, &lo_f, &bar, &mut work.cand) };
                for &(l, r) in &work.cand {
                    let i = t0 + l as usize;
                    consider(ctx, q_row(i), c0 + r as usize, &mut best[i]);
                }
            }
        }
        // SAFETY: releases the tile state this thread configured.
        unsafe { asm!("tilerelease", options(nostack, nomem)) };
        Some(best.into_iter().map(|b| b.1).collect())
    }

    fn dist(ctx: &Ctx<'_>, q: &[f64], r: usize) -> f64 {
        dist2_below(ctx.x_rows.row(r), q, f64::INFINITY).unwrap_or(f64::NAN)
    }

    /// Row `r` replaces `best` if nearer (ties: the smaller index).
    #[inline(always)]
    fn consider(ctx: &Ctx<'_>, q: &[f64], r: usize, best: &mut (f64, usize)) {
        if r >= ctx.nx {
            return;
        }
        if let Some(dk) = dist2_below(ctx.x_rows.row(r), q, best.0)
            && (dk < best.0 || r < best.1)
        {
            *best = (dk, r);
        }
    }

    /// `s[r][l] = x̃_r · q̃_l` for `width` data rows (in tiles from `x`,
    /// see [`Ctx::xb`]) and 32 queries (two groups of 16 in the pair
    /// layout from `q`), in f32, rows of 32 floats. Two by two tiles of 16
    /// x 16 results, 32 coordinates per step.
    ///
    /// # Safety
    /// The tiles must be configured (palette 1, 16 rows of 64 bytes); `x`
    /// must hold `width` (a multiple of 32) rows of `dp` values, `q` two
    /// groups of `16 dp` values, `s` `width` rows of 32 floats.
    unsafe fn scores(x: *const u16, dp: usize, q: *const u16, width: usize, s: *mut f32) {
        for r in (0..width).step_by(32) {
            let a0 = x.wrapping_add(r * dp);
            let a1 = x.wrapping_add((r + 16) * dp);
            // SAFETY: the caller's contract; every load stays inside the
            // 32 rows and the two query groups, every store inside `s`.
            unsafe {
                asm!(
                    "tilezero tmm0",
                    "tilezero tmm1",
                    "tilezero tmm2",
                    "tilezero tmm3",
                    options(nostack, nomem)
                );
                for kc in 0..dp / 32 {
                    asm!(
                        // Loads interleaved with the products that
                        // wait for them (faster: docs/tuning.md).
                        "tileloadd tmm4, [{a0} + {st} * 1]",
                        "tileloadd tmm6, [{b0} + {st} * 1]",
                        "tdpbf16ps tmm0, tmm4, tmm6",
                        "tileloadd tmm7, [{b1} + {st} * 1]",
                        "tdpbf16ps tmm1, tmm4, tmm7",
                        "tileloadd tmm5, [{a1} + {st} * 1]",
                        "tdpbf16ps tmm2, tmm5, tmm6",
                        "tdpbf16ps tmm3, tmm5, tmm7",
                        a0 = in(reg) a0.add(kc * 512),
                        a1 = in(reg) a1.add(kc * 512),
                        b0 = in(reg) q.add(kc * 512),
                        b1 = in(reg) q.add(16 * dp + kc * 512),
                        st = in(reg) 64usize,
                        options(nostack, readonly)
                    );
                }
                let c0 = s.add(r * 32);
                asm!(
                    "tilestored [{c0} + {ss} * 1], tmm0",
                    "tilestored [{c1} + {ss} * 1], tmm1",
                    "tilestored [{c2} + {ss} * 1], tmm2",
                    "tilestored [{c3} + {ss} * 1], tmm3",
                    c0 = in(reg) c0,
                    c1 = in(reg) c0.add(16),
                    c2 = in(reg) c0.add(16 * 32),
                    c3 = in(reg) c0.add(16 * 32 + 16),
                    ss = in(reg) 128usize,
                    options(nostack)
                );
            }
        }
    }

    /// The 32 lanes as two vectors.
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[inline]
    #[target_feature(enable = "avx512f")]
    unsafe fn lanes(v: &[f32; QT]) -> [__m512; 2] {
        // SAFETY: two loads of 16 from a 32-element array.
        unsafe {
            [
                _mm512_loadu_ps(v.as_ptr()),
                _mm512_loadu_ps(v.as_ptr().add(16)),
            ]
        }
    }

    /// Per query lane, the smallest `lo xn[r] − 2 s[r][l]` and `hi xn[r] −
    /// 2 s[r][l]` over the rows of a chunk (`s`: rows of 32 lanes).
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[target_feature(enable = "avx512f,fma")]
    unsafe fn bounds(
        s: &[f32],
        xn: &[f32],
        lo_f: &[f32; QT],
        hi_f: &[f32; QT],
    ) -> ([f32; QT], [f32; QT]) {
        let n = xn.len().min(s.len() / QT);
        // SAFETY: the caller's AVX-512F.
        let (a, b) = unsafe { (lanes(lo_f), lanes(hi_f)) };
        // Two rows per step (independent chains).
        let mut lo = [[_mm512_set1_ps(f32::INFINITY); 2]; 2];
        let mut hi = [[_mm512_set1_ps(f32::INFINITY); 2]; 2];
        let mut r = 0;
        while r < n {
            for (e, (lo, hi)) in lo.iter_mut().zip(hi.iter_mut()).enumerate() {
                let k = r + e;
                if k >= n {
                    break;
                }
                let x = _mm512_set1_ps(xn[k]);
                for h in 0..2 {
                    // SAFETY: row k < n of 32 floats.
                    let v = unsafe { _mm512_loadu_ps(s.as_ptr().add(k * QT + 16 * h)) };
                    let v2 = _mm512_add_ps(v, v);
                    lo[h] = _mm512_min_ps(lo[h], _mm512_fmsub_ps(a[h], x, v2));
                    hi[h] = _mm512_min_ps(hi[h], _mm512_fmsub_ps(b[h], x, v2));
                }
            }
            r += 2;
        }
        let mut low = [0.0f32; QT];
        let mut high = [0.0f32; QT];
        for h in 0..2 {
            // SAFETY: 16 lanes into 32-element arrays.
            unsafe {
                _mm512_storeu_ps(
                    low.as_mut_ptr().add(16 * h),
                    _mm512_min_ps(lo[0][h], lo[1][h]),
                );
                _mm512_storeu_ps(
                    high.as_mut_ptr().add(16 * h),
                    _mm512_min_ps(hi[0][h], hi[1][h]),
                );
            }
        }
        (low, high)
    }

    /// Appends every (lane, row) with `lo xn[r] − 2 s[r][l] <= bar[l]` to
    /// `out`.
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[target_feature(enable = "avx512f,fma")]
    unsafe fn under(
        s: &[f32],
        xn: &[f32],
        lo_f: &[f32; QT],
        bar: &[f32; QT],
        out: &mut Vec<(u32, u32)>,
    ) {
        let n = xn.len().min(s.len() / QT);
        // SAFETY: the caller's AVX-512F.
        let (a, b) = unsafe { (lanes(lo_f), lanes(bar)) };
        // Only the halves (16 lanes) with a lane to search.
        for h in (0..2).filter(|&h| {
            bar[16 * h..16 * h + 16]
                .iter()
                .any(|&b| b > f32::NEG_INFINITY)
        }) {
            for r in 0..n {
                let x = _mm512_set1_ps(xn[r]);
                // SAFETY: row r < n of 32 floats.
                let v = unsafe { _mm512_loadu_ps(s.as_ptr().add(r * QT + 16 * h)) };
                let low = _mm512_fmsub_ps(a[h], x, _mm512_add_ps(v, v));
                let mut mask = _mm512_cmp_ps_mask::<_CMP_LE_OQ>(low, b[h]);
                while mask != 0 {
                    out.push(((16 * h) as u32 + mask.trailing_zeros(), r as u32));
                    mask &= mask - 1;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Round to nearest, ties to even, at 8 significant bits; zero below
    /// f32's normal range.
    #[test]
    fn bf16_rounding() {
        let cases = [
            (1.0, 1.0),
            (1.0 + 2f64.powi(-8), 1.0), // tie: to even
            (1.0 + 3.0 * 2f64.powi(-8), 1.0 + 2f64.powi(-6)), // tie: to even
            (1.0 + 2f64.powi(-8) + 2f64.powi(-20), 1.0 + 2f64.powi(-7)),
            (-3.0, -3.0),
            (1e-39, 0.0),
            (-1e-40, 0.0),
            (0.0, 0.0),
        ];
        for (v, want) in cases {
            assert_eq!(from_bf16(to_bf16(v)), want, "{v}");
        }
        // Relative error at most 2⁻⁸ (+ the f32 step) over many magnitudes.
        let mut v = 1.2345e-30f64;
        while v < 1e30 {
            let t = from_bf16(to_bf16(v));
            assert!((v - t).abs() <= (2f64.powi(-8) + 2f64.powi(-23)) * v, "{v}");
            v *= 1.7;
        }
    }
}
