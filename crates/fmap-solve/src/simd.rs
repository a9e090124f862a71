//! Small numeric kernels compiled for the CPU's vector extensions (the
//! crate is built for baseline x86-64, SSE2): each kernel is one
//! `#[inline(always)]` body instantiated inside `#[target_feature]`
//! functions for AVX-512 and AVX2+FMA, chosen at run time (the detection
//! is cached by the standard library), with the baseline as fallback.
//! Results differ between the variants by rounding only (fused or
//! separate multiply-adds).

#[inline(always)]
fn fma<const FUSED: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FUSED { a.mul_add(b, c) } else { a * b + c }
}

/// For j in 1..k, writes `out[j(j−1)/2 + i] = Σ_f P[f,i] N[f,j] − N[f,i] P[f,j]`
/// for i < j: the entries above the diagonal of `Pᵀ N − Nᵀ P`, column by
/// column, for `p` and `n` row-major (`deg` rows of `kp` values, kp a
/// multiple of 32 and ≥ k, zero-padded). Writes in whole blocks of 32, so
/// `out` needs 32 values past the k(k−1)/2 results, which are left with
/// garbage.
#[inline(always)]
fn wedge_sums_body<const FUSED: bool>(
    p: &[f64],
    n: &[f64],
    deg: usize,
    kp: usize,
    k: usize,
    out: &mut [f64],
) {
    let mut base = 0;
    for j in 1..k {
        let mut i0 = 0;
        while i0 < j {
            // Two accumulators per lane (the P and N products), 32 lanes:
            // eight independent chains of deg multiply-adds.
            let mut s = [0.0f64; 32];
            let mut t = [0.0f64; 32];
            for f in 0..deg {
                let (a, b) = (n[f * kp + j], p[f * kp + j]);
                let pr: &[f64; 32] = p[f * kp + i0..f * kp + i0 + 32].try_into().unwrap();
                let nr: &[f64; 32] = n[f * kp + i0..f * kp + i0 + 32].try_into().unwrap();
                for l in 0..32 {
                    s[l] = fma::<FUSED>(pr[l], a, s[l]);
                    t[l] = fma::<FUSED>(nr[l], b, t[l]);
                }
            }
            // All 32 lanes are stored: the ones past column j land in the
            // columns after it (or the padding), written later.
            let o: &mut [f64; 32] = (&mut out[base + i0..base + i0 + 32]).try_into().unwrap();
            for l in 0..32 {
                o[l] = s[l] - t[l];
            }
            i0 += 32;
        }
        base += j;
    }
}

/// See [`wedge_sums_body`].
pub(crate) fn wedge_sums(p: &[f64], n: &[f64], deg: usize, kp: usize, k: usize, out: &mut [f64]) {
    assert!(kp.is_multiple_of(32) && kp >= k && p.len() >= deg * kp && n.len() >= deg * kp);
    assert!(out.len() >= k * k.saturating_sub(1) / 2 + 32);
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU supports AVX-512F (checked just above).
            return unsafe { x86::wedge_sums_avx512(p, n, deg, kp, k, out) };
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            return unsafe { x86::wedge_sums_avx2(p, n, deg, kp, k, out) };
        }
    }
    wedge_sums_body::<false>(p, n, deg, kp, k, out)
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    #[target_feature(enable = "avx512f,fma")]
    pub(super) fn wedge_sums_avx512(
        p: &[f64],
        n: &[f64],
        deg: usize,
        kp: usize,
        k: usize,
        out: &mut [f64],
    ) {
        super::wedge_sums_body::<true>(p, n, deg, kp, k, out)
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn wedge_sums_avx2(
        p: &[f64],
        n: &[f64],
        deg: usize,
        kp: usize,
        k: usize,
        out: &mut [f64],
    ) {
        super::wedge_sums_body::<true>(p, n, deg, kp, k, out)
    }
}
