//! The protocol on generated meshes with known answers, and the dataset
//! loader on the real benchmark (skipped when absent).

use fmaps_eval::*;
use fmaps_geodesic::{DijkstraSolver, ExactSolver};
use fmaps_shapes::grid;

/// A 2 x 1 grid, 9 x 5 vertices, mirrored by x -> 2 - x.
fn setup() -> (fmaps_mesh_io::TriMesh, Vec<usize>) {
    let m = grid(2.0, 1.0, 8, 4);
    let mirror: Vec<usize> = (0..m.n_vertices())
        .map(|v| (v / 9) * 9 + (8 - v % 9))
        .collect();
    (m, mirror)
}

#[test]
fn identity_map_is_perfect() {
    let (m, mirror) = setup();
    let n = m.n_vertices();
    let id: Vec<usize> = (0..n).collect();
    let gt = GroundTruth::new(id.clone(), id.clone(), Some(mirror)).unwrap();
    let s = ExactSolver::new(&m).unwrap();
    let r = evaluate(&m, &s, &id, &gt, Some(&id), &EvalParams::default()).unwrap();
    assert_eq!(r.mean_error, 0.0);
    assert_eq!(r.sym_mean_error, Some(0.0));
    assert_eq!(r.auc, 1.0);
    assert_eq!(r.coverage, 1.0);
    assert_eq!(r.bijectivity, Some(1.0));
    assert_eq!(r.geodesic, "exact");
    assert!(r.curve.iter().all(|&c| c == 1.0));
}

#[test]
fn mirrored_map_is_wrong_but_symmetry_aware_perfect() {
    let (m, mirror) = setup();
    let n = m.n_vertices();
    let id: Vec<usize> = (0..n).collect();
    let gt = GroundTruth::new(id.clone(), id.clone(), Some(mirror.clone())).unwrap();
    let s = ExactSolver::new(&m).unwrap();
    let r = evaluate(&m, &s, &mirror, &gt, None, &EvalParams::default()).unwrap();
    // Vertex (i, j) goes to (8 - i, j): error |2 - 2x| / sqrt(2), x = i/4.
    let want: f64 = (0..n)
        .map(|v| (2.0 - 2.0 * (v % 9) as f64 / 4.0).abs())
        .sum::<f64>()
        / n as f64
        / 2f64.sqrt();
    assert!(
        (r.mean_error - want).abs() < 1e-12,
        "{} vs {want}",
        r.mean_error
    );
    assert_eq!(r.sym_mean_error, Some(0.0));
    assert_eq!(r.coverage, 1.0);
    // Curve: monotone, from the fraction of exact points to those within 0.25.
    assert!(r.curve.windows(2).all(|w| w[0] <= w[1]));
    assert!((r.curve[0] - 5.0 / 45.0).abs() < 1e-12, "{}", r.curve[0]);
}

#[test]
fn dijkstra_errors_bound_exact_ones_from_above() {
    let (m, _) = setup();
    let n = m.n_vertices();
    let id: Vec<usize> = (0..n).collect();
    let shifted: Vec<usize> = (0..n).map(|v| (v + 10) % n).collect();
    let gt = GroundTruth::new(id.clone(), id, None).unwrap();
    let ex = evaluate(
        &m,
        &ExactSolver::new(&m).unwrap(),
        &shifted,
        &gt,
        None,
        &EvalParams::default(),
    )
    .unwrap();
    let dj_solver = DijkstraSolver::new(&m);
    let dj = evaluate(&m, &dj_solver, &shifted, &gt, None, &EvalParams::default()).unwrap();
    assert_eq!(dj.geodesic, "dijkstra");
    assert!(
        ex.errors
            .iter()
            .zip(&dj.errors)
            .all(|(e, d)| e <= &(d + 1e-12))
    );
    assert!(dj.mean_error > ex.mean_error);
}

#[test]
fn curve_and_area_closed_forms() {
    let t: Vec<f64> = (0..=4).map(|j| j as f64 * 0.25 / 4.0).collect();
    let c = cumulative_curve(&[0.0, 0.1, 0.3, 0.05], &t);
    // Thresholds 0, 0.0625, 0.125, 0.1875, 0.25.
    assert_eq!(c, vec![0.25, 0.5, 0.75, 0.75, 0.75]);
    // A constant curve has that constant as normalized area.
    assert!((area_under(&t, &[0.5; 5]) - 0.5).abs() < 1e-15);
}

#[test]
fn bad_sizes_and_indices_are_errors() {
    let (m, _) = setup();
    let s = ExactSolver::new(&m).unwrap();
    let id: Vec<usize> = (0..45).collect();
    assert!(matches!(
        GroundTruth::new(vec![0, 1], vec![0], None),
        Err(Error::SizeMismatch { .. })
    ));
    // An empty ground truth measures nothing: an error, not a perfect score.
    assert!(matches!(
        GroundTruth::new(Vec::new(), Vec::new(), None),
        Err(Error::EmptyGroundTruth)
    ));
    let gt = GroundTruth::new(vec![0, 1], vec![0, 1], None).unwrap();
    let mut bad = id.clone();
    bad[3] = 45;
    assert!(matches!(
        evaluate(&m, &s, &bad, &gt, None, &EvalParams::default()),
        Err(Error::OutOfRange { index: 45, .. })
    ));
    let gt_far = GroundTruth::new(vec![0, 99], vec![0, 1], None).unwrap();
    assert!(matches!(
        evaluate(&m, &s, &id, &gt_far, None, &EvalParams::default()),
        Err(Error::OutOfRange { index: 99, .. })
    ));
    assert!(matches!(
        evaluate(&m, &s, &id, &gt, Some(&id[..3]), &EvalParams::default()),
        Err(Error::SizeMismatch { .. })
    ));
    let other = grid(1.0, 1.0, 2, 2);
    assert!(matches!(
        evaluate(&other, &s, &[0], &gt, None, &EvalParams::default()),
        Err(Error::SizeMismatch { .. })
    ));
}
