//! Checks on the benchmark datasets (`FMAPS_DATA`, or `../shared/datasets`
//! beside the repository; skipped with a note when absent, a failure with
//! `FMAPS_REQUIRE_DATA=1`): geodesics on real meshes, and the benchmark's
//! layout, published maps and ground truth through the evaluation.

use fmaps::eval::*;
use fmaps::geodesic::{DijkstraSolver, DistanceSolver, ExactSolver, HeatParams, HeatSolver};

/// On real benchmark meshes (skipped when the dataset is absent): the heat
/// method is within a few percent of exact distances — also on TOSCA, whose
/// remeshings have many non-Delaunay edges (the intrinsic Delaunay
/// Laplacian is what makes that work) — and Dijkstra is above them.
#[test]
fn benchmark_meshes_exact_heat_dijkstra() {
    let Some(dir) = fmaps_tests::data_dir("bcicp") else {
        fmaps_tests::missing_data("the benchmark data (bcicp)");
        return;
    };
    for rel in [
        "bcicp/FAUST/vtx_5k/tr_reg_000.off",
        "bcicp/TOSCA_Isometric/vtx_5k/cat0.off",
    ] {
        let path = dir.join(rel);
        if !path.exists() {
            fmaps_tests::missing_data(&path.display().to_string());
            continue;
        }
        let mesh = fmaps::mesh_io::read_mesh(&path).unwrap();
        let de = ExactSolver::new(&mesh).unwrap().distances(&[1234]).unwrap();
        let dh = HeatSolver::new(&mesh, &HeatParams::default())
            .unwrap()
            .distances(&[1234])
            .unwrap();
        let dj = DijkstraSolver::new(&mesh).distances(&[1234]).unwrap();
        let dmax = de.iter().copied().fold(0.0, f64::max);
        let far: Vec<usize> = (0..de.len()).filter(|&i| de[i] > 0.2 * dmax).collect();
        let dev = far
            .iter()
            .map(|&i| (dh[i] - de[i]).abs() / de[i])
            .sum::<f64>()
            / far.len() as f64;
        // Measured 1.4–2.1% on these meshes.
        assert!(dev < 0.03, "{rel}: heat vs exact {dev}");
        assert!(de.iter().zip(&dj).all(|(e, j)| *e <= j + 1e-12));
    }
}

#[test]
fn benchmark_layout_and_a_published_map() {
    let Some(data) = fmaps_tests::data_dir("bcicp/TOSCA_Isometric/test_pairs.txt") else {
        fmaps_tests::missing_data("TOSCA_Isometric (bcicp/TOSCA_Isometric)");
        return;
    };
    let root = data.join("bcicp");
    let c = Collection::open(&root, "TOSCA_Isometric").unwrap();
    let pairs = c.test_pairs().unwrap();
    assert_eq!(pairs.len(), 284);
    let methods = c.published_methods().unwrap();
    assert!(
        methods.contains(&"WKSini_direct".to_string()),
        "{methods:?}"
    );
    let maps = c.published_maps("WKSini_direct").unwrap();
    let (a, b) = (&pairs[0].0, &pairs[0].1);
    let t_ab = maps
        .read(a, b)
        .unwrap()
        .expect("the first test pair has a published map");
    let (ma, mb) = (c.read_mesh(a).unwrap(), c.read_mesh(b).unwrap());
    assert_eq!(t_ab.len(), ma.n_vertices());
    let gt = c
        .ground_truth(a, b, ma.n_vertices(), mb.n_vertices())
        .unwrap();
    assert_eq!(gt.len(), 5000);
    let r = evaluate(
        &mb,
        &ExactSolver::new(&mb).unwrap(),
        &t_ab,
        &gt,
        None,
        &EvalParams::default(),
    )
    .unwrap();
    // Two independent geodesics: shortest paths along the edges are
    // never shorter than the exact polyhedral ones, point by point, and on
    // this 5000-vertex mesh a little longer on average (measured: mean
    // error 0.0545 along edges against 0.0483 exact, 1.13x; checked at
    // 1.2x).
    let graph = evaluate(
        &mb,
        &DijkstraSolver::new(&mb),
        &t_ab,
        &gt,
        None,
        &EvalParams::default(),
    )
    .unwrap();
    for (i, (e, g)) in r.errors.iter().zip(&graph.errors).enumerate() {
        assert!(*g >= e - 1e-12, "point {i}: edge path {g} < exact {e}");
    }
    assert!(
        graph.mean_error <= 1.2 * r.mean_error,
        "{} vs {}",
        graph.mean_error,
        r.mean_error
    );
    // A published map from WKS descriptors alone: a few percent of
    // sqrt(area).
    assert!(
        r.mean_error > 0.01 && r.mean_error < 0.2,
        "{}",
        r.mean_error
    );
    assert!(r.sym_mean_error.unwrap() <= r.mean_error);
    assert!(maps.read("no_such", "shape").unwrap().is_none());
    assert!(matches!(
        Collection::open(&root, "NOPE"),
        Err(Error::Dataset(_))
    ));
}
