//! Operators on a reduced basis derived from vertex functions: descriptor
//! multiplication (`Φᵀ M diag(d) Φ`) and orientation (Ren et al., "Continuous
//! and orientation-preserving correspondences via functional maps", 2018).
//!
//! The orientation operator of a function f maps g to the normal component
//! of `∇f × ∇g`, i.e. `⟨n × ∇f, ∇g⟩`. On a triangle both gradients are
//! constant and lie in its plane, and with ψ_u the hat functions and e_u the
//! edge opposite to u (from next(u) to prev(u) in the face's order),
//! `⟨n × ∇f, area·∇ψ_u⟩ = ⟨∇f, e_u⟩ / 2 = (f_prev(u) − f_next(u)) / 2`:
//! the discrete operator needs only the oriented faces, no coordinates. Its
//! reduced form `Φᵀ M O_f Φ` (O_f averaged to vertices with the lumped
//! mass, as in pyFM, so M cancels) is
//! `Σ_F ∫_F φ_i ⟨n × ∇f, ∇φ_j⟩`, antisymmetric on closed meshes.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use crate::{Error, Result};

/// `Φᵀ M diag(d_q) Φ` (k x k) for every column d_q of `descriptors`
/// (n x p), with `phi` n x k.
///
/// All p operators are one product: with the products of pairs of basis
/// functions per vertex, `K[v, (i ≤ j)] = φ_i(v) φ_j(v)` (the operators are
/// symmetric, so k(k+1)/2 pairs), `X[(i, j), q] = Σ_v K[v, (i, j)] m_v
/// d_q(v)` is one GEMM of shape k(k+1)/2 x n x p, in chunks of vertices
/// (half the multiply-adds of p separate `Φᵀ (M d_q Φ)` products, and a
/// GEMM shape that runs near peak). Blocks of vertices are summed in a
/// fixed order, so the result does not depend on the number of threads.
pub fn multiplication_operators(
    phi: &DMatrix<f64>,
    mass: &DVector<f64>,
    descriptors: &DMatrix<f64>,
) -> Result<Vec<DMatrix<f64>>> {
    let (n, k) = phi.shape();
    check_rows(n, mass.len(), "mass length vs basis rows")?;
    check_rows(n, descriptors.nrows(), "descriptor rows vs basis rows")?;
    let p = descriptors.ncols();
    let pairs = k * (k + 1) / 2;
    let phi_rows = row_major(phi);
    let out = sum_over_blocks(n, pairs, p, |v0, v1, acc, kt| {
        let m = v1 - v0;
        // kt[(pair), v] (pairs x m, column-major), w[v, q] = m_v d_q(v).
        kt.resize(pairs * m, 0.0);
        for (v, col) in (v0..v1).zip(kt.chunks_mut(pairs)) {
            let row = &phi_rows[v * k..(v + 1) * k];
            let mut t = 0;
            for (j, &pj) in row.iter().enumerate() {
                for (o, &pi) in col[t..t + j + 1].iter_mut().zip(&row[..=j]) {
                    *o = pi * pj;
                }
                t += j + 1;
            }
        }
        let w = faer::Mat::<f64>::from_fn(m, p, |v, q| mass[v0 + v] * descriptors[(v0 + v, q)]);
        matmul(
            acc,
            Accum::Add,
            MatRef::from_column_major_slice(&kt[..pairs * m], pairs, m),
            w.as_ref(),
            1.0,
            Par::Seq,
        );
    });
    Ok((0..p)
        .map(|q| {
            let col = &out[q * pairs..(q + 1) * pairs];
            let mut x = DMatrix::zeros(k, k);
            let mut t = 0;
            for j in 0..k {
                for i in 0..=j {
                    x[(i, j)] = col[t];
                    x[(j, i)] = col[t];
                    t += 1;
                }
            }
            x
        })
        .collect())
}

/// The reduced orientation operators `Φᵀ M O_{d_q} Φ` (k x k) of every
/// column d_q of `descriptors` (n x p) on a mesh with oriented triangles
/// `faces` and basis `phi` (n x k). `reversing` negates them (the operators
/// of orientation-reversing maps).
pub fn orientation_operators(
    faces: &[[usize; 3]],
    phi: &DMatrix<f64>,
    descriptors: &DMatrix<f64>,
    reversing: bool,
) -> Result<Vec<DMatrix<f64>>> {
    let n = phi.nrows();
    check_rows(n, descriptors.nrows(), "descriptor rows vs basis rows")?;
    if let Some((at, f)) = faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&v| v >= n))
    {
        return Err(Error::IndexOutOfRange {
            at,
            index: f.iter().copied().max().unwrap_or(0),
            n,
        });
    }
    let k = phi.ncols();
    let p = descriptors.ncols();
    // φ row-major with rows padded to a multiple of 8 (whole vectors for
    // the wedge kernel; the padding is zero and never reaches the output).
    let kp = k.div_ceil(8) * 8;
    let mut padded = vec![0.0; n * kp];
    for (j, col) in phi.column_iter().enumerate() {
        for (v, &x) in col.iter().enumerate() {
            padded[v * kp + j] = x;
        }
    }
    let sign = if reversing { -1.0 } else { 1.0 } / 6.0;
    // Descriptor values row-major (the p values of a vertex contiguous),
    // less the midpoint of each descriptor's range: Σ_u W_u = 0 below (the
    // operator of a constant vanishes), so the shift changes nothing in
    // exact arithmetic, keeps the sums small where a descriptor varies
    // little, and makes the operator of a constant exactly zero.
    let mut d_rows = row_major(descriptors);
    for q in 0..p {
        let (lo, hi) = descriptors
            .column(q)
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        let mid = if lo.is_finite() && hi.is_finite() {
            0.5 * lo + 0.5 * hi
        } else {
            0.0
        };
        for v in 0..n {
            d_rows[v * p + q] -= mid;
        }
    }
    // Faces around each vertex: (next, prev) vertices of the vertex's
    // corner in each.
    let mut start = vec![0usize; n + 1];
    for f in faces {
        for &v in f {
            start[v + 1] += 1;
        }
    }
    for v in 0..n {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut around = vec![(0usize, 0usize); start[n]];
    for &[a, b, c] in faces {
        for (u, next, prev) in [(a, b, c), (b, c, a), (c, a, b)] {
            around[fill[u]] = (next, prev);
            fill[u] += 1;
        }
    }
    // W_u = Σ_{F ∋ u} S_F (φ_next − φ_prev)ᵀ (S_F the sum of φ over F's
    // corners), so that O_q = sign Σ_u d_q(u) W_u. Where the next and prev
    // vertices of u's faces are the same multiset (u inside a closed fan,
    // any number of them), the terms telescope to
    // W_u = Σ_F (φ_prev φ_nextᵀ − φ_next φ_prevᵀ): antisymmetric, so only
    // its k(k−1)/2 entries above the diagonal are formed. Other vertices
    // (boundary, inconsistent orientation) get the full k x k form.
    let closed_fan = |u: usize| {
        let fan = &around[start[u]..start[u + 1]];
        // Small fans (all of them on meshes of sane valence) on the stack.
        const SMALL: usize = 24;
        if fan.len() <= SMALL {
            let (mut nexts, mut prevs) = ([0usize; SMALL], [0usize; SMALL]);
            for (i, f) in fan.iter().enumerate() {
                (nexts[i], prevs[i]) = (f.0, f.1);
            }
            let (nexts, prevs) = (&mut nexts[..fan.len()], &mut prevs[..fan.len()]);
            nexts.sort_unstable();
            prevs.sort_unstable();
            nexts == prevs
        } else {
            let mut nexts: Vec<usize> = fan.iter().map(|f| f.0).collect();
            let mut prevs: Vec<usize> = fan.iter().map(|f| f.1).collect();
            nexts.sort_unstable();
            prevs.sort_unstable();
            nexts == prevs
        }
    };
    let (inner, open): (Vec<usize>, Vec<usize>) = (0..n).partition(|&u| closed_fan(u));
    let gather_d = |list: &[usize]| -> Vec<f64> {
        let mut out = Vec::with_capacity(list.len() * p);
        for &u in list {
            out.extend_from_slice(&d_rows[u * p..(u + 1) * p]);
        }
        out
    };
    let row = |v: usize| &padded[v * kp..v * kp + k];
    let pairs = k * k.saturating_sub(1) / 2;
    let anti = sum_over_blocks(inner.len(), pairs, p, |i0, i1, acc, wt| {
        let list = &inner[i0..i1];
        // Every entry is written below: no zeroing.
        wt.resize(pairs * list.len(), 0.0);
        let (mut prev, mut next) = (Vec::new(), Vec::new());
        for (idx, &u) in list.iter().enumerate() {
            let fan = &around[start[u]..start[u + 1]];
            next.clear();
            prev.clear();
            next.extend(fan.iter().map(|f| f.0));
            prev.extend(fan.iter().map(|f| f.1));
            let col = &mut wt[idx * pairs..(idx + 1) * pairs];
            let fan = fmaps_simd::Fan {
                rows: &padded,
                kp,
                k,
                prev: &prev,
                next: &next,
            };
            fmaps_simd::wedge_sums(&fan, col);
        }
        let d = gather_d(list);
        matmul(
            acc,
            Accum::Add,
            MatRef::from_column_major_slice(&wt[..pairs * list.len()], pairs, list.len()),
            MatRef::from_row_major_slice(&d, list.len(), p),
            1.0,
            Par::Seq,
        );
    });
    let full = sum_over_blocks(open.len(), k * k, p, |i0, i1, acc, wt| {
        let list = &open[i0..i1];
        wt.clear();
        wt.resize(k * k * list.len(), 0.0);
        let mut sf = vec![0.0; k];
        for (&u, col) in list.iter().zip(wt.chunks_mut((k * k).max(1))) {
            for &(next, prev) in &around[start[u]..start[u + 1]] {
                let (pu, pn, pp) = (row(u), row(next), row(prev));
                for (((o, a), b), c) in sf.iter_mut().zip(pu).zip(pn).zip(pp) {
                    *o = a + b + c;
                }
                for (j, cj) in col.chunks_mut(k).enumerate() {
                    let e = pn[j] - pp[j];
                    for (o, s) in cj.iter_mut().zip(&sf) {
                        *o += s * e;
                    }
                }
            }
        }
        let d = gather_d(list);
        matmul(
            acc,
            Accum::Add,
            MatRef::from_column_major_slice(&wt[..k * k * list.len()], k * k, list.len()),
            MatRef::from_row_major_slice(&d, list.len(), p),
            1.0,
            Par::Seq,
        );
    });
    Ok((0..p)
        .map(|q| {
            let (a, f) = (
                &anti[q * pairs..(q + 1) * pairs],
                &full[q * k * k..(q + 1) * k * k],
            );
            let mut o = DMatrix::from_fn(k, k, |i, j| sign * f[i + k * j]);
            let mut t = 0;
            for j in 1..k {
                for i in 0..j {
                    o[(i, j)] += sign * a[t];
                    o[(j, i)] -= sign * a[t];
                    t += 1;
                }
            }
            o
        })
        .collect())
}

/// `Σ_blocks f(i0, i1, acc)` over fixed blocks of `0..len` (vertices or
/// positions in a list of vertices): each call adds the block's
/// contribution to `acc` (rows x cols, column-major), with a scratch
/// buffer reused from block to block. Blocks are grouped
/// into at most 16 fixed ranges summed in parallel, and the partial sums
/// added in order, so the result is the same for any number of threads.
fn sum_over_blocks<F>(len: usize, rows: usize, cols: usize, f: F) -> Vec<f64>
where
    F: Fn(usize, usize, MatMut<'_, f64>, &mut Vec<f64>) + Sync,
{
    const BLOCK: usize = 64;
    let blocks = len.div_ceil(BLOCK);
    let per_range = blocks.div_ceil(16).max(1);
    let ranges = blocks.div_ceil(per_range);
    let partial: Vec<Vec<f64>> = (0..ranges)
        .into_par_iter()
        .map(|g| {
            let mut acc = vec![0.0; rows * cols];
            let mut scratch = Vec::new();
            for blk in g * per_range..((g + 1) * per_range).min(blocks) {
                let (i0, i1) = (blk * BLOCK, ((blk + 1) * BLOCK).min(len));
                f(
                    i0,
                    i1,
                    MatMut::from_column_major_slice_mut(&mut acc, rows, cols),
                    &mut scratch,
                );
            }
            acc
        })
        .collect();
    let mut out = vec![0.0; rows * cols];
    for part in partial {
        for (o, x) in out.iter_mut().zip(part) {
            *o += x;
        }
    }
    out
}

fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

fn check_rows(n: usize, found: usize, what: &'static str) -> Result<()> {
    if found == n {
        Ok(())
    } else {
        Err(Error::SizeMismatch {
            what,
            found,
            expected: n,
        })
    }
}
