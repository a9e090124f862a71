//! The matching pipeline on generated shapes with known correspondence.

use fmaps::mesh_io::TriMesh;
use fmaps::pipeline::{MatchError, MatchParams, Refinement, match_shapes};
use fmaps::refine::starts::StartSelection;
use fmaps::shapes::icosphere;

/// An ellipsoid with two off-axis bumps: no symmetry left.
fn blob() -> TriMesh {
    let (v, f) = icosphere(1.0, 3).into_parts();
    let bump = |p: [f64; 3], c: [f64; 3], h: f64| {
        let d2: f64 = (0..3).map(|i| (p[i] - c[i]).powi(2)).sum();
        1.0 + h * (-d2 * 4.0).exp()
    };
    let v = v
        .into_iter()
        .map(|p| {
            let s = bump(p, [0.6, 0.5, 0.6], 0.35) * bump(p, [-0.7, 0.2, -0.5], 0.2);
            [1.3 * p[0] * s, p[1] * s, 0.8 * p[2] * s]
        })
        .collect();
    TriMesh::new(v, f).unwrap()
}

/// `a` bent about the z axis by an angle of `rate · x` at each point (the
/// same vertices in the same order: the truth is the identity).
fn bent(a: &TriMesh, rate: f64) -> TriMesh {
    let (v, f) = a.clone().into_parts();
    let vb: Vec<[f64; 3]> = v
        .iter()
        .map(|p| {
            let t = rate * p[0];
            [
                p[0] * t.cos() - p[1] * t.sin(),
                p[0] * t.sin() + p[1] * t.cos(),
                p[2],
            ]
        })
        .collect();
    TriMesh::new(vb, f).unwrap()
}

fn small_params() -> MatchParams {
    let mut p = MatchParams::unrefined();
    p.k_process = 40;
    p.descriptors.eigenpairs = 40;
    p.descriptors.n = 40;
    p.k = 20;
    p
}

#[test]
fn a_permuted_copy_is_matched_to_the_true_vertices() {
    let a = blob();
    let n = a.n_vertices();
    // B: the same surface, vertices renumbered (perm[new] = old).
    let perm: Vec<usize> = (0..n).map(|i| (i * 389 + 7) % n).collect();
    let mut inv = vec![0; n];
    for (new, &old) in perm.iter().enumerate() {
        inv[old] = new;
    }
    let (v, f) = a.clone().into_parts();
    let vb: Vec<[f64; 3]> = perm.iter().map(|&old| v[old]).collect();
    let fb: Vec<[usize; 3]> = f.iter().map(|t| t.map(|x| inv[x])).collect();
    let b = TriMesh::new(vb, fb).unwrap();

    let r = match_shapes(&a, &b, &small_params()).unwrap();
    assert_eq!(r.t_ab.len(), n);
    let exact = (0..n).filter(|&x| r.t_ab[x] == inv[x]).count();
    assert_eq!(exact, n, "{exact} of {n} exact");
    // A permuted copy has the same spectrum and the permuted
    // eigenfunctions (up to sign): the exact C is diagonal with entries
    // ±1, orthonormal and commuting with Δ to the eigensolver's rounding
    // (measured 3e-10 and 8e-12).
    assert!(r.metrics.orthonormality < 1e-6, "{:?}", r.metrics);
    assert!(r.metrics.laplacian_commutativity < 1e-8, "{:?}", r.metrics);
    assert_eq!(r.c_ba.shape(), (20, 20));
    assert_eq!(r.t_ab_init, r.t_ab);
    // A near-exact map preserves orientation.
    assert!(r.orientation > 0.9, "orientation {}", r.orientation);
    assert!(r.starts.is_empty());

    // ZoomOut 10 -> 40 (from the 10 x 10 block) and ICP keep or improve it,
    // and the refined ZoomOut map is exact on this isometry.
    for refine in [
        Refinement::zoomout(10, 40, 5),
        Refinement::Icp(fmaps::refine::Icp::default()),
    ] {
        let mut params = small_params();
        params.refinement = refine.clone();
        let r = match_shapes(&a, &b, &params).unwrap();
        let refined = (0..n).filter(|&x| r.t_ab[x] == inv[x]).count();
        assert!(refined >= exact, "{refine:?}: {refined} vs {exact}");
        let report = r.refine.expect("refinement ran");
        assert!(report.nn_searches >= 1);
        if let Refinement::ZoomOut { .. } = refine {
            assert_eq!(refined, n);
            assert_eq!(r.c_ba.shape(), (40, 40));
            assert_eq!(report.iterations.len(), 6);
        }
    }
}

#[test]
fn orientation_term_is_what_tells_a_shape_from_its_mirror_image() {
    // B is the mirror image of A (x -> -x, faces re-oriented to stay
    // outward). The isometric correspondence is the reflection, which
    // reverses orientation: the orientation-reversing solve finds it, the
    // preserving one cannot.
    let a = blob();
    let n = a.n_vertices();
    let (v, f) = a.clone().into_parts();
    let vb: Vec<[f64; 3]> = v.iter().map(|p| [-p[0], p[1], p[2]]).collect();
    let fb: Vec<[usize; 3]> = f.iter().map(|&[x, y, z]| [x, z, y]).collect();
    let b = TriMesh::new(vb, fb).unwrap();
    let exact = |reversing: bool| {
        let mut p = small_params();
        p.energy.orient_reversing = reversing;
        p.energy.weights.orient = 10.0;
        let r = match_shapes(&a, &b, &p).unwrap();
        if reversing {
            assert!(r.orientation < -0.9, "orientation {}", r.orientation);
        }
        (0..n).filter(|&x| r.t_ab[x] == x).count()
    };
    let (rev, pres) = (exact(true), exact(false));
    assert!(rev as f64 > 0.9 * n as f64, "reversing: {rev} of {n}");
    assert!(pres < rev / 2, "preserving: {pres}, reversing {rev}");
}

#[test]
fn bad_parameters_are_errors() {
    let a = blob();
    let mut p = small_params();
    p.k = 300;
    assert!(matches!(
        match_shapes(&a, &a, &p),
        Err(MatchError::InvalidParameter(_))
    ));
    let mut p = small_params();
    p.descriptors.landmarks = vec![(0, a.n_vertices())];
    assert!(matches!(
        match_shapes(&a, &a, &p),
        Err(MatchError::InvalidParameter(_))
    ));
}

#[test]
fn multi_start_keeps_the_best_oriented_start_and_equals_that_single_run() {
    // A against a bent copy of itself (the truth is the identity).
    let a = blob();
    let n = a.n_vertices();
    let v = a.vertices().to_vec();
    let b = bent(&a, 0.1);
    for (reversing, sign) in [(false, 1.0), (true, -1.0)] {
        let mut base = small_params();
        base.refinement = Refinement::zoomout(20, 30, 5);
        base.energy.orient_reversing = reversing;
        base.starts.select = StartSelection::Orientation;
        let mut multi = base.clone();
        multi.starts.sizes = vec![4, 8, 4];
        let r = match_shapes(&a, &b, &multi).unwrap();
        // Duplicates dropped, k first.
        let ks: Vec<usize> = r.starts.iter().map(|s| s.k).collect();
        assert_eq!(ks, [20, 4, 8]);
        let chosen: Vec<_> = r.starts.iter().filter(|s| s.chosen).collect();
        assert_eq!(chosen.len(), 1);
        let best = chosen[0];
        for s in &r.starts {
            assert!(
                sign * s.orientation <= sign * best.orientation,
                "{:?}",
                r.starts
            );
        }
        assert_eq!(r.orientation, best.orientation);
        // The same as a single run from the chosen size.
        let mut single = base.clone();
        single.k = best.k;
        if let Refinement::ZoomOut { zoomout, .. } = &mut single.refinement {
            zoomout.k_start = zoomout.k_start.min(best.k);
        }
        let s = match_shapes(&a, &b, &single).unwrap();
        assert_eq!(s.t_ab, r.t_ab);
        assert_eq!(s.orientation, r.orientation);
        // restart_below: a bar the first start clears keeps it alone; one
        // no start can clear (scores are at most 1) runs every start.
        let first = r.starts[0].orientation;
        let mut lazy = multi.clone();
        lazy.starts.restart_below = Some(sign * first - 1e-9);
        let lazy = match_shapes(&a, &b, &lazy).unwrap();
        assert_eq!(lazy.starts.len(), 1);
        assert_eq!(lazy.orientation, first);
        let mut eager = multi.clone();
        eager.starts.restart_below = Some(1.5);
        let eager = match_shapes(&a, &b, &eager).unwrap();
        assert_eq!(eager.starts.len(), 3);
        assert_eq!(eager.t_ab, r.t_ab);
        // The default selection keeps the start of lowest area distortion.
        let mut by_area = multi.clone();
        by_area.starts.select = StartSelection::default();
        let by_area = match_shapes(&a, &b, &by_area).unwrap();
        let kept = by_area.starts.iter().find(|s| s.chosen).unwrap();
        for s in &by_area.starts {
            assert!(kept.quality.area_distortion <= s.quality.area_distortion);
        }
        if !reversing {
            // Mean distance (on A) between the image and the truth, for a
            // shape about 2.6 across.
            let err = (0..n)
                .map(|x| {
                    let (p, q) = (v[r.t_ab[x]], v[x]);
                    (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt()
                })
                .sum::<f64>()
                / n as f64;
            assert!(err < 0.05, "mean error {err}");
        }
    }
    let mut bad = small_params();
    bad.starts.sizes = vec![0];
    assert!(matches!(
        match_shapes(&a, &a, &bad),
        Err(MatchError::InvalidParameter(_))
    ));
}

/// `select_at`: every start's ZoomOut stops at that size, the start of
/// lowest area distortion there is kept, and only it goes on. With
/// schedules that all pass through the stop (steps of 4 from 4, 8, 12 and
/// 20, stop at 24), the kept start's final map is that start's map without
/// the stop (the continuation repeats its iterations; only the first fit
/// after the stop is summed directly instead of updated), and its report
/// holds every iteration of both parts.
#[test]
fn select_at_keeps_the_best_start_at_the_stop_and_finishes_only_it() {
    let a = blob();
    let b = bent(&a, 0.15);
    let mut base = small_params();
    base.refinement = Refinement::zoomout(20, 40, 4);
    base.starts.sizes = vec![4, 8, 12];
    let mut stopped = base.clone();
    stopped.starts.select_at = Some(24);
    let r = match_shapes(&a, &b, &stopped).unwrap();
    assert_eq!(r.starts.len(), 4);
    let kept = r.starts.iter().find(|s| s.chosen).unwrap();
    for s in &r.starts {
        assert!(kept.quality.area_distortion <= s.quality.area_distortion);
    }
    assert_eq!(r.c_ba.shape(), (40, 40));
    // The same start without the stop and without the other starts.
    let mut single = base.clone();
    single.k = kept.k;
    single.starts.sizes = Vec::new();
    if let Refinement::ZoomOut { zoomout, .. } = &mut single.refinement {
        zoomout.k_start = zoomout.k_start.min(kept.k);
    }
    let s = match_shapes(&a, &b, &single).unwrap();
    assert_eq!(s.t_ab, r.t_ab, "kept start k = {}", kept.k);
    let (rr, sr) = (r.refine.as_ref().unwrap(), s.refine.as_ref().unwrap());
    assert_eq!(rr.iterations.len(), sr.iterations.len());
    assert_eq!(
        rr.iterations.iter().map(|i| i.k).collect::<Vec<_>>(),
        sr.iterations.iter().map(|i| i.k).collect::<Vec<_>>()
    );
    // One extra search: the stopped run's conversion at the stop.
    assert_eq!(rr.nn_searches, sr.nn_searches + 1);
    // A stop at or past the final size changes nothing.
    let mut late = base.clone();
    late.starts.select_at = Some(40);
    let full = match_shapes(&a, &b, &base).unwrap();
    assert_eq!(match_shapes(&a, &b, &late).unwrap().t_ab, full.t_ab);
}

/// The map does not depend on the units of either mesh: the built-in pair
/// (an asymmetric creature and a bent, renumbered copy) matched with
/// ZoomOut gives the same map when the target's or the source's
/// coordinates are multiplied by 1e-3 or 1e3 (the area normalization),
/// and a map close to the truth. Without the normalization the scaled
/// pairs give other maps (the Laplacian mask compares the two shapes'
/// eigenvalues).
#[test]
fn the_map_does_not_depend_on_the_units() {
    let pair = fmaps::shapes::creature_pair(3);
    let (a, b) = (&pair.source, &pair.target);
    let mut params = MatchParams::unrefined();
    params.k_process = 60;
    params.descriptors.eigenpairs = 60;
    params.descriptors.n = 40;
    params.k = 20;
    params.refinement = Refinement::zoomout(20, 50, 5);
    let base = match_shapes(a, b, &params).unwrap();
    let n = base.t_ab.len();
    let exact = (0..n).filter(|&x| base.t_ab[x] == pair.truth[x]).count();
    assert!(exact * 10 > 9 * n, "{exact} of {n} on the truth");
    for s in [1e-3, 1e3] {
        let (sa, sb) = (a.scaled(s).unwrap(), b.scaled(s).unwrap());
        for (x, y, which) in [(a, &sb, "target"), (&sa, b, "source"), (&sa, &sb, "both")] {
            let r = match_shapes(x, y, &params).unwrap();
            let same = (0..n).filter(|&v| r.t_ab[v] == base.t_ab[v]).count();
            assert_eq!(
                same, n,
                "{which} scaled by {s}: {same} of {n} vertices agree"
            );
        }
    }
    // The normalization is what makes it so.
    let mut raw = params;
    raw.area_normalize = false;
    let r = match_shapes(a, &b.scaled(1e3).unwrap(), &raw).unwrap();
    let same = (0..n).filter(|&v| r.t_ab[v] == base.t_ab[v]).count();
    assert!(
        same < n,
        "unnormalized 1e3-scaled target: {same} of {n} agree"
    );
}

/// A sphere's descriptors are constant: matching onto (or from) it leaves
/// C undetermined. The pipeline says so instead of returning a map of
/// 1e11-sized coefficients that sends every vertex to one vertex;
/// a sphere onto itself stays the identity.
#[test]
fn an_undetermined_map_is_an_error() {
    let (a, s) = (blob(), icosphere(1.0, 3));
    let mut p = MatchParams::unrefined();
    p.k = 10;
    p.k_process = 20;
    p.descriptors.eigenpairs = 20;
    for (x, y) in [(&a, &s), (&s, &a)] {
        match match_shapes(x, y, &p) {
            Err(MatchError::Undetermined {
                max_entry, rank, k, ..
            }) => {
                assert!(max_entry > 1e3 || 2 * rank < k, "{max_entry} {rank} {k}");
                let msg = match_shapes(x, y, &p).unwrap_err().to_string();
                assert!(msg.contains("Try landmarks"), "{msg}");
            }
            other => panic!("expected Undetermined, got {:?}", other.map(|r| r.c_ba)),
        }
    }
    assert!(match_shapes(&a, &a, &p).is_ok());
}

/// `refine_point_map`: a map from elsewhere, refined. The true map of the
/// built-in pair stays (nearly) itself under ZoomOut, and the true map with
/// a fifth of its vertices sent to random places is repaired: ZoomOut
/// restores almost all of them (it smooths: a random target is far from its
/// neighbours' images).
#[test]
fn refining_a_given_map() {
    use fmaps::pipeline::{prepare, refine_point_map};
    let pair = fmaps::shapes::creature_pair(3);
    let mut params = MatchParams::unrefined();
    params.k = 30;
    params.k_process = 60;
    params.descriptors.eigenpairs = 60;
    params.refinement = Refinement::zoomout(30, 60, 5);
    let pa = prepare(&pair.source, &params).unwrap();
    let pb = prepare(&pair.target, &params).unwrap();
    let n = pair.truth.len();
    let wrong = |t: &[usize]| t.iter().zip(&pair.truth).filter(|(x, y)| x != y).count();
    let r = refine_point_map(&pa, &pb, &pair.truth, &params).unwrap();
    assert!(
        wrong(&r.t_ab) * 100 <= n,
        "{} of {n} moved off the truth",
        wrong(&r.t_ab)
    );
    assert_eq!(r.t_ab_init, pair.truth);
    assert_eq!(r.c_ba.ncols(), 60);
    let mut noisy = pair.truth.clone();
    let mut x = 12345u64;
    for v in noisy.iter_mut().step_by(5) {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        *v = (x >> 33) as usize % n;
    }
    let before = wrong(&noisy);
    let r = refine_point_map(&pa, &pb, &noisy, &params).unwrap();
    let after = wrong(&r.t_ab);
    // A fifth of the vertices sent anywhere (129 wrong): the refinement
    // recovers all but a few (measured: 1).
    assert!(
        after * 100 <= n && after * 20 < before,
        "{before} wrong before, {after} after"
    );
    // No refinement: the given map back, with its pull-back.
    let mut none = params.clone();
    none.refinement = Refinement::None;
    let r = refine_point_map(&pa, &pb, &noisy, &none).unwrap();
    assert_eq!(r.t_ab, noisy);
    assert_eq!(r.c_ba.shape(), (30, 30));
    assert!(matches!(
        refine_point_map(&pa, &pb, &noisy[1..], &params),
        Err(MatchError::InvalidParameter(_))
    ));
}

/// Multi-start runs a custom refiner from each initial size when it says
/// how (`Refiner::for_initial_size`): bijective ZoomOut from 20 and 10.
#[test]
fn multi_start_with_a_discrete_refiner() {
    use std::sync::Arc;
    let pair = fmaps::shapes::creature_pair(3);
    let d = fmaps::refine::DiscreteOp {
        k_start: 20,
        k_final: 40,
        step: 5,
        ..fmaps::refine::DiscreteOp::preset("bijective-zoomout").unwrap()
    };
    let mut params = MatchParams::unrefined();
    params.k = 20;
    params.k_process = 40;
    params.descriptors.eigenpairs = 40;
    params.descriptors.n = 40;
    params.refinement = Refinement::Custom(Arc::new(d));
    params.starts.sizes = vec![10];
    let r = match_shapes(&pair.source, &pair.target, &params).unwrap();
    assert_eq!(r.starts.len(), 2);
    assert_eq!(r.starts.iter().filter(|s| s.chosen).count(), 1);
    assert_eq!(r.c_ba.shape(), (40, 40));
    let wrong = r
        .t_ab
        .iter()
        .zip(&pair.truth)
        .filter(|(x, y)| x != y)
        .count();
    assert!(
        wrong * 10 < pair.truth.len(),
        "{wrong} of {} wrong",
        pair.truth.len()
    );
}

/// A ZoomOut on farthest-point samples (as `fmaps match` runs on large
/// meshes): the samples are drawn once for every start, the initial map
/// (searched from the samples' map over the target's sample cells) is the
/// plain conversion of the same fit, and the final map is the exact
/// conversion of the final C (after the iteration on every vertex).
#[test]
fn sampled_zoomout_maps_are_exact_conversions() {
    let (v, f) = icosphere(1.0, 4).into_parts();
    let a = TriMesh::new(
        v.iter()
            .map(|p| [1.3 * p[0], p[1] * (1.0 + 0.2 * p[0]), 0.8 * p[2]])
            .collect(),
        f,
    )
    .unwrap();
    let b = bent(&a, 0.15);
    let mut zoomout = fmaps::refine::ZoomOut::default();
    (zoomout.k_start, zoomout.k_final, zoomout.step) = (20, 40, 4);
    let mut sampled = small_params();
    sampled.refinement = Refinement::ZoomOut {
        zoomout,
        samples: Some(600),
    };
    sampled.starts.sizes = vec![8, 12];
    sampled.starts.select_at = Some(28);
    let r = match_shapes(&a, &b, &sampled).unwrap();
    let rep = r.refine.as_ref().unwrap();
    assert!(
        rep.method.contains("samples 600/600 + 1 on every vertex"),
        "{}",
        rep.method
    );
    let kept = r.starts.iter().find(|s| s.chosen).unwrap();
    // The initial map of the kept start: the fit does not depend on the
    // refinement.
    let mut plain = sampled.clone();
    plain.k = kept.k;
    plain.refinement = Refinement::None;
    plain.starts.sizes = Vec::new();
    plain.starts.select_at = None;
    assert_eq!(r.t_ab_init, match_shapes(&a, &b, &plain).unwrap().t_ab_init);
    let (pa, pb) = (
        fmaps::pipeline::prepare(&a, &sampled).unwrap(),
        fmaps::pipeline::prepare(&b, &sampled).unwrap(),
    );
    let exact =
        fmaps::solve::point_map_from_fmap(&r.c_ba, &pb.basis.truncate(40), &pa.basis.truncate(40))
            .unwrap();
    assert_eq!(r.t_ab, exact);
}

/// Smooth Shells takes its rigid alignment from the user's landmarks: an
/// ellipsoid and its copy turned half a turn about its short axis (a
/// symmetry: both maps, the identity and the turn, fit equally well) is
/// matched by whichever the landmarks say, on nearly every vertex.
#[test]
fn smooth_shells_follows_the_landmarks() {
    let (v, f) = icosphere(1.0, 3).into_parts();
    let v: Vec<[f64; 3]> = v.iter().map(|p| [1.6 * p[0], p[1], 0.6 * p[2]]).collect();
    let a = TriMesh::new(v.clone(), f.clone()).unwrap();
    // B: A turned by π about z, same vertex order (the truth "i -> i").
    let turned: Vec<[f64; 3]> = v.iter().map(|p| [-p[0], -p[1], p[2]]).collect();
    let b = TriMesh::new(turned.clone(), f).unwrap();
    // The other map: i -> the vertex of B at A's position of i.
    let partner: Vec<usize> = v
        .iter()
        .map(|p| {
            (0..turned.len())
                .min_by(|&x, &y| {
                    let d = |q: [f64; 3]| (0..3).map(|c| (q[c] - p[c]).powi(2)).sum::<f64>();
                    d(turned[x]).total_cmp(&d(turned[y]))
                })
                .unwrap()
        })
        .collect();
    let close = |t: &[usize], expected: &dyn Fn(usize) -> usize| {
        let ok = (0..t.len())
            .filter(|&i| {
                let (p, q) = (turned[t[i]], turned[expected(i)]);
                (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>().sqrt() < 0.2
            })
            .count();
        ok as f64 / t.len() as f64
    };
    let mut params = MatchParams::default();
    params.starts.sizes.clear();
    let picks = [0, 100, 321, 500, 640];
    params.descriptors.landmarks = picks.iter().map(|&i| (i, i)).collect();
    let r = match_shapes(&a, &b, &params).unwrap();
    let share = close(&r.t_ab, &|i| i);
    assert!(share > 0.95, "landmarks i -> i: {share} of the vertices");
    params.descriptors.landmarks = picks.iter().map(|&i| (i, partner[i])).collect();
    let r = match_shapes(&a, &b, &params).unwrap();
    let share = close(&r.t_ab, &|i| partner[i]);
    assert!(
        share > 0.95,
        "landmarks i -> partner: {share} of the vertices"
    );
}
