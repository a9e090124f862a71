//! ZoomOut's fast paths give the plain algorithm's maps, written out
//! here: the fit updated over the changed rows, run ahead of the schedule
//! and cut to each size, and the searches' pruning (the ball clusters of
//! the 1800 rows without matrix tiles, the tiles with them).

use fmaps_refine::RefineInput;
use fmaps_refine::{Refiner, ZoomOut};
use nalgebra::DMatrix;

mod common;
use common::{basis, bumpy};

/// At each size the nearest row of `Φ_A[:, :k] Cᵀ` for every row of
/// `Φ_B[:, :k]` by brute force (ties to the smaller index), then `C =
/// Φ_B[:, :k']ᵀ M_B Π Φ_A[:, :k']` summed vertex by vertex.
#[test]
fn zoomout_equals_the_plain_algorithm() {
    let (a, b) = (bumpy(0.08), bumpy(0.12));
    let (basis_a, basis_b) = (basis(&a, 40), basis(&b, 40));
    // An initial map with errors (the identity's leading block, bent).
    let c0 = DMatrix::from_fn(8, 8, |i, j| {
        (if i == j { 1.0 } else { 0.0 }) + 0.1 * ((3 * i + j) as f64).sin()
    });
    // Steps of 3 from 8: the last one shorter (38 → 40), the fit ahead of
    // the schedule capped at 40.
    let zo = ZoomOut {
        k_start: 8,
        k_final: 40,
        step: 3,
        ..ZoomOut::default()
    };
    let r = zo
        .refine(&RefineInput::new(&c0, &basis_a, &basis_b))
        .unwrap();
    let (phi_a, phi_b) = (&basis_a.eigenvectors, &basis_b.eigenvectors);
    let mass = basis_b.mass.as_slice();
    let nearest = |c: &DMatrix<f64>| -> Vec<usize> {
        let k = c.nrows();
        let image = phi_a.columns(0, k) * c.transpose();
        (0..phi_b.nrows())
            .map(|y| {
                let mut best = (f64::INFINITY, 0);
                for x in 0..image.nrows() {
                    let d: f64 = (0..k)
                        .map(|j| (image[(x, j)] - phi_b[(y, j)]).powi(2))
                        .sum();
                    if d < best.0 {
                        best = (d, x);
                    }
                }
                best.1
            })
            .collect()
    };
    let mut ck = c0.clone();
    let mut changed = Vec::new();
    let mut t_prev: Option<Vec<usize>> = None;
    for k in zo.schedule() {
        let t = nearest(&ck);
        if let Some(tp) = &t_prev {
            changed.push(t.iter().zip(tp).filter(|(a, b)| a != b).count());
        }
        ck = DMatrix::from_fn(k, k, |i, j| {
            (0..t.len())
                .map(|y| mass[y] * phi_b[(y, i)] * phi_a[(t[y], j)])
                .sum()
        });
        t_prev = Some(t);
    }
    assert_eq!(ck.shape(), (40, 40));
    let err = (&r.c_ab - &ck).amax();
    assert!(err < 1e-12, "{err}");
    assert_eq!(r.t_ba, nearest(&ck));
    // The maps changed from step to step (the updates were exercised).
    let reported: Vec<usize> = r.report.iterations[1..].iter().map(|i| i.changed).collect();
    assert_eq!(reported, changed);
    assert!(changed.iter().sum::<usize>() > 100, "{changed:?}");
}
