//! One classical Gram–Schmidt pass against the Krylov basis, `C = Vᵀ W`
//! then `W −= V C`, for a tall basis V (n x hundreds, column-major) and a
//! thin block W (n x b, b the Lanczos block size).
//!
//! General GEMMs are slow at these shapes: the block is too thin to reuse
//! the basis from registers, and a kernel that walks V across its columns
//! (stride n) a few rows at a time streams hundreds of columns at once.
//! Both products here read V once, column by column in contiguous runs:
//! the coefficients as dot products of four basis columns against all of
//! W at a time, the update a block of rows at a time (those rows of W stay
//! in L1), four basis columns at a time. The kernels are written once
//! in plain Rust and compiled per instruction set by `fmaps-simd`
//! (multiply-adds fused where the CPU has FMA). With several threads the
//! coefficients are split by basis columns and the update by rows, so
//! every value is summed in the same order for any thread count.

use fmaps_simd::{Kernel, SimdLevel, dispatch};

/// Rows per chunk: one AVX-512 register of f64, two AVX2 ones.
const L: usize = 8;
/// W columns per group (the kernels are compiled for 1..=G).
const G: usize = 8;
/// Basis columns per step.
const Q: usize = 4;
/// Rows per block of the update (its W rows: 512 x g x 8 bytes).
const BLOCK: usize = 512;
/// Below this many multiply-adds a pass runs on one thread.
const PAR_MIN: usize = 1 << 18;

/// Projects the n x cols orthonormal basis `v` out of the n x b block `w`
/// (both column-major): `ct[j * cols + c] = V[:, c] · W[:, j]`, then
/// `W −= V C`, with up to `threads` threads.
pub(crate) fn project(
    v: &[f64],
    n: usize,
    w: &mut [f64],
    b: usize,
    ct: &mut [f64],
    threads: usize,
) {
    let cols = v.len().checked_div(n).unwrap_or(0);
    assert!(v.len() == n * cols && w.len() == n * b && ct.len() == b * cols);
    let mut j0 = 0;
    while j0 < b {
        let g = (b - j0).min(G);
        let wg = &mut w[j0 * n..(j0 + g) * n];
        let cg = &mut ct[j0 * cols..(j0 + g) * cols];
        macro_rules! go {
            ($($g:literal)*) => {
                match g {
                    $($g => project_group::<$g>(v, n, cols, wg, cg, threads),)*
                    _ => unreachable!("groups of at most {G} columns"),
                }
            };
        }
        go!(1 2 3 4 5 6 7 8);
        j0 += g;
    }
}

/// [`project`] for g = `K` columns of W.
fn project_group<const K: usize>(
    v: &[f64],
    n: usize,
    cols: usize,
    w: &mut [f64],
    ct: &mut [f64],
    threads: usize,
) {
    // C = Vᵀ W, column-major (ctc[c][j]): whole groups of Q basis columns
    // per thread.
    let mut ctc = vec![[0.0; K]; cols];
    let split = parts(threads, n * cols * K, cols.div_ceil(Q));
    let per = cols.div_ceil(Q).div_ceil(split) * Q;
    {
        let w: &[f64] = w;
        if split <= 1 {
            dispatch(Coef {
                v,
                n,
                w,
                c0: 0,
                out: &mut ctc,
            });
        } else {
            std::thread::scope(|s| {
                for (p, out) in ctc.chunks_mut(per).enumerate() {
                    s.spawn(move || {
                        dispatch(Coef {
                            v,
                            n,
                            w,
                            c0: p * per,
                            out,
                        })
                    });
                }
            });
        }
    }
    for (c, k) in ctc.iter().enumerate() {
        for j in 0..K {
            ct[j * cols + c] = k[j];
        }
    }
    // W −= V C: whole blocks of rows per thread.
    let split = parts(threads, n * cols * K, n.div_ceil(BLOCK));
    let per = n.div_ceil(BLOCK).div_ceil(split) * BLOCK;
    let mut pieces: Vec<Vec<&mut [f64]>> = Vec::new();
    for col in w.chunks_mut(n) {
        for (p, piece) in col.chunks_mut(per).enumerate() {
            if pieces.len() <= p {
                pieces.push(Vec::new());
            }
            pieces[p].push(piece);
        }
    }
    let run = |p: usize, piece: Vec<&mut [f64]>| {
        let Ok(wcols) = <[&mut [f64]; K]>::try_from(piece) else {
            unreachable!("one piece per column")
        };
        dispatch(Update {
            v,
            n,
            ctc: &ctc,
            r0: p * per,
            wcols,
        });
    };
    if pieces.len() <= 1 {
        for (p, piece) in pieces.into_iter().enumerate() {
            run(p, piece);
        }
    } else {
        std::thread::scope(|s| {
            for (p, piece) in pieces.into_iter().enumerate() {
                let run = &run;
                s.spawn(move || run(p, piece));
            }
        });
    }
}

/// How many threads a pass of `work` multiply-adds over `units`
/// independent pieces gets.
fn parts(threads: usize, work: usize, units: usize) -> usize {
    if work < PAR_MIN {
        1
    } else {
        threads.clamp(1, units.max(1))
    }
}

/// The 8 values of `x` from `at`.
#[inline(always)]
fn lanes(x: &[f64], at: usize) -> [f64; L] {
    let mut out = [0.0; L];
    out.copy_from_slice(&x[at..at + L]);
    out
}

/// A fixed-order sum of the lanes.
#[inline(always)]
fn lane_sum(a: [f64; L]) -> f64 {
    ((a[0] + a[4]) + (a[2] + a[6])) + ((a[1] + a[5]) + (a[3] + a[7]))
}

/// `out[i][j] = V[:, c0 + i] · W[:, j]`.
struct Coef<'a, const K: usize> {
    v: &'a [f64],
    n: usize,
    w: &'a [f64],
    c0: usize,
    out: &'a mut [[f64; K]],
}

impl<const K: usize> Kernel for Coef<'_, K> {
    type Output = ();

    #[inline(always)]
    fn run(self, level: SimdLevel) {
        let Coef { v, n, w, c0, out } = self;
        let n8 = n / L * L;
        let cols = out.len();
        let mut i0 = 0;
        while i0 < cols {
            // Fewer than Q columns left: the missing ones repeat the first
            // and are not stored.
            let q = (cols - i0).min(Q);
            let base: [usize; Q] = [0, 1, 2, 3].map(|i| (c0 + i0 + if i < q { i } else { 0 }) * n);
            // One accumulator array per basis column: small arrays stay in
            // registers.
            let (mut a0, mut a1, mut a2, mut a3) =
                ([[0.0; L]; K], [[0.0; L]; K], [[0.0; L]; K], [[0.0; L]; K]);
            let mut r = 0;
            while r < n8 {
                // No closure here: it would not be compiled for the level.
                let (x0, x1, x2, x3) = (
                    lanes(v, base[0] + r),
                    lanes(v, base[1] + r),
                    lanes(v, base[2] + r),
                    lanes(v, base[3] + r),
                );
                for j in 0..K {
                    let y = lanes(w, j * n + r);
                    for l in 0..L {
                        a0[j][l] = level.mul_add(x0[l], y[l], a0[j][l]);
                        a1[j][l] = level.mul_add(x1[l], y[l], a1[j][l]);
                        a2[j][l] = level.mul_add(x2[l], y[l], a2[j][l]);
                        a3[j][l] = level.mul_add(x3[l], y[l], a3[j][l]);
                    }
                }
                r += L;
            }
            let mut sums = [[0.0; K]; Q];
            for j in 0..K {
                sums[0][j] = lane_sum(a0[j]);
                sums[1][j] = lane_sum(a1[j]);
                sums[2][j] = lane_sum(a2[j]);
                sums[3][j] = lane_sum(a3[j]);
            }
            for (i, row) in sums.iter_mut().enumerate() {
                for (j, s) in row.iter_mut().enumerate() {
                    for r in n8..n {
                        *s = level.mul_add(v[base[i] + r], w[j * n + r], *s);
                    }
                }
            }
            out[i0..i0 + q].copy_from_slice(&sums[..q]);
            i0 += q;
        }
    }
}

/// `W −= V C` on rows `r0..r0 + wcols[j].len()` of the K columns of W.
struct Update<'a, 'w, const K: usize> {
    v: &'a [f64],
    n: usize,
    ctc: &'a [[f64; K]],
    r0: usize,
    wcols: [&'w mut [f64]; K],
}

impl<const K: usize> Kernel for Update<'_, '_, K> {
    type Output = ();

    #[inline(always)]
    fn run(self, level: SimdLevel) {
        let Update {
            v,
            n,
            ctc,
            r0,
            wcols,
        } = self;
        let cols = ctc.len();
        let rows = wcols[0].len();
        let mut b0 = 0;
        while b0 < rows {
            let len = (rows - b0).min(BLOCK);
            let len8 = len / L * L;
            let mut c = 0;
            while c < cols {
                // Missing columns repeat column c with a zero coefficient.
                let q = (cols - c).min(Q);
                let base: [usize; Q] =
                    [0, 1, 2, 3].map(|i| (c + if i < q { i } else { 0 }) * n + r0 + b0);
                let mut k = [[0.0; Q]; K];
                for j in 0..K {
                    for i in 0..q {
                        k[j][i] = -ctc[c + i][j];
                    }
                }
                let mut r = 0;
                while r < len8 {
                    // No closure here: it would not be compiled for the level.
                    let x = [
                        lanes(v, base[0] + r),
                        lanes(v, base[1] + r),
                        lanes(v, base[2] + r),
                        lanes(v, base[3] + r),
                    ];
                    for j in 0..K {
                        let mut a = lanes(wcols[j], b0 + r);
                        for l in 0..L {
                            a[l] = level.mul_add(
                                x[3][l],
                                k[j][3],
                                level.mul_add(
                                    x[2][l],
                                    k[j][2],
                                    level.mul_add(
                                        x[1][l],
                                        k[j][1],
                                        level.mul_add(x[0][l], k[j][0], a[l]),
                                    ),
                                ),
                            );
                        }
                        wcols[j][b0 + r..b0 + r + L].copy_from_slice(&a);
                    }
                    r += L;
                }
                for r in len8..len {
                    for j in 0..K {
                        let mut s = wcols[j][b0 + r];
                        for i in 0..Q {
                            s = level.mul_add(v[base[i] + r], k[j][i], s);
                        }
                        wcols[j][b0 + r] = s;
                    }
                }
                c += q;
            }
            b0 += len;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random(len: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..len)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    /// The pass in plain f64 loops: `C = Vᵀ W`, `W −= V C`.
    fn naive(v: &[f64], n: usize, w: &[f64], b: usize) -> (Vec<f64>, Vec<f64>) {
        let cols = v.len() / n;
        let mut ct = vec![0.0; b * cols];
        for j in 0..b {
            for c in 0..cols {
                ct[j * cols + c] = (0..n).map(|r| v[c * n + r] * w[j * n + r]).sum();
            }
        }
        let mut out = w.to_vec();
        for j in 0..b {
            for r in 0..n {
                out[j * n + r] -= (0..cols)
                    .map(|c| v[c * n + r] * ct[j * cols + c])
                    .sum::<f64>();
            }
        }
        (ct, out)
    }

    /// Every level the CPU has, every thread count, and shapes with row
    /// tails (n mod 8), partial column groups (cols mod 4), more W columns
    /// than one group (b > 8) and several row blocks: the pass equals the
    /// plain loops to rounding (relative to the terms' magnitudes), and
    /// two threads give the bits of one.
    #[test]
    fn the_pass_equals_plain_loops_at_every_level_and_thread_count() {
        let shapes = [
            (1, 1, 1),
            (7, 3, 2),
            (5000, 10, 5),
            (1203, 9, 9),
            (40, 401, 3),
            (700, 64, 8),
        ];
        fmaps_simd::at_every_level(|level| {
            for &(n, cols, b) in &shapes {
                let v = random(n * cols, 1 + n as u64);
                let w = random(n * b, 2 + cols as u64);
                let (ct_ref, w_ref) = naive(&v, n, &w, b);
                let mut first: Option<(Vec<f64>, Vec<f64>)> = None;
                for threads in [1, 2, 3] {
                    let mut ct = vec![f64::NAN; b * cols];
                    let mut wo = w.clone();
                    project(&v, n, &mut wo, b, &mut ct, threads);
                    // |terms| <= 0.25 each: n (or cols) of them bound the
                    // rounding by ~len * eps * 0.25 per sum.
                    let tol_c = 1e-15 * n as f64;
                    let tol_w = 1e-15 * (n * cols) as f64;
                    for (x, y) in ct.iter().zip(&ct_ref) {
                        assert!(
                            (x - y).abs() <= tol_c,
                            "{level:?} {n}x{cols} b={b}: C {x} vs {y}"
                        );
                    }
                    for (x, y) in wo.iter().zip(&w_ref) {
                        assert!(
                            (x - y).abs() <= tol_w,
                            "{level:?} {n}x{cols} b={b}: W {x} vs {y}"
                        );
                    }
                    match &first {
                        None => first = Some((ct, wo)),
                        Some((c1, w1)) => {
                            assert!(c1.iter().zip(&ct).all(|(a, b)| a.to_bits() == b.to_bits()));
                            assert!(w1.iter().zip(&wo).all(|(a, b)| a.to_bits() == b.to_bits()));
                        }
                    }
                }
            }
        });
    }
}
