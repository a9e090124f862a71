//! Dense products of the passes through faer's GEMM (blocked, with
//! AVX-512 kernels where the CPU has them, and threaded over the current
//! rayon pool), on nalgebra's column-major storage without copies.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::DMatrix;

/// Whether an operand is used as stored or transposed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Op {
    /// As stored.
    N,
    /// Transposed.
    T,
}

fn view(m: &DMatrix<f64>, op: Op) -> MatRef<'_, f64> {
    let v = MatRef::from_column_major_slice(m.as_slice(), m.nrows(), m.ncols());
    match op {
        Op::N => v,
        Op::T => v.transpose(),
    }
}

fn par() -> Par {
    match rayon::current_num_threads() {
        1 => Par::Seq,
        n => Par::rayon(n),
    }
}

/// `op(a) op(b)`.
pub(crate) fn mul(a: &DMatrix<f64>, oa: Op, b: &DMatrix<f64>, ob: Op) -> DMatrix<f64> {
    let (av, bv) = (view(a, oa), view(b, ob));
    assert_eq!(av.ncols(), bv.nrows(), "inner dimensions of a product");
    let mut out = DMatrix::zeros(av.nrows(), bv.ncols());
    let (r, c) = out.shape();
    let dst = MatMut::from_column_major_slice_mut(out.as_mut_slice(), r, c);
    matmul(dst, Accum::Replace, av, bv, 1.0, par());
    out
}

/// `out += alpha op(a) op(b)`.
pub(crate) fn mul_add(
    out: &mut DMatrix<f64>,
    alpha: f64,
    a: &DMatrix<f64>,
    oa: Op,
    b: &DMatrix<f64>,
    ob: Op,
) {
    let (av, bv) = (view(a, oa), view(b, ob));
    let (r, c) = out.shape();
    assert_eq!((av.nrows(), bv.ncols()), (r, c), "shape of a product");
    let dst = MatMut::from_column_major_slice_mut(out.as_mut_slice(), r, c);
    matmul(dst, Accum::Add, av, bv, alpha, par());
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random;

    /// Every transposition against nalgebra's product.
    #[test]
    fn products_match_nalgebra() {
        let (a, b) = (random(7, 5, 1), random(5, 4, 2));
        let want = &a * &b;
        let cases = [
            mul(&a, Op::N, &b, Op::N),
            mul(&a.transpose(), Op::T, &b, Op::N),
            mul(&a, Op::N, &b.transpose(), Op::T),
            mul(&a.transpose(), Op::T, &b.transpose(), Op::T),
        ];
        for got in cases {
            assert!((got - &want).abs().max() < 1e-14);
        }
        let mut acc = want.clone();
        mul_add(&mut acc, -2.0, &a, Op::N, &b, Op::N);
        assert!((acc + &want).abs().max() < 1e-14);
    }
}
