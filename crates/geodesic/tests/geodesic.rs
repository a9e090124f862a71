//! Exact geodesics against closed forms and invariants.

use fmaps_geodesic::*;
use fmaps_mesh_io::TriMesh;
use fmaps_shapes::{disjoint_union, grid, icosphere, torus, translated};
use proptest::prelude::*;

fn euclid(p: [f64; 3], q: [f64; 3]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

/// A grid whose interior vertices are jittered in the plane: still flat, so
/// geodesic distance from any vertex is Euclidean (the domain is convex).
fn jittered_grid(nx: usize, ny: usize) -> TriMesh {
    let (mut v, f) = grid(1.0, 1.0, nx, ny).into_parts();
    for (k, p) in v.iter_mut().enumerate() {
        let (i, j) = (k % (nx + 1), k / (nx + 1));
        if i > 0 && i < nx && j > 0 && j < ny {
            p[0] += 0.2 / nx as f64 * ((k * 7) as f64).sin();
            p[1] += 0.2 / ny as f64 * ((k * 13) as f64).cos();
        }
    }
    TriMesh::new(v, f).unwrap()
}

#[test]
fn flat_grid_is_euclidean_from_any_source() {
    for mesh in [grid(2.0, 1.0, 12, 7), jittered_grid(10, 9)] {
        let solver = ExactSolver::new(&mesh).unwrap();
        let v = mesh.vertices();
        for s in [0, 5, v.len() / 2, v.len() - 1, 3 * 13 + 4] {
            let s = s.min(v.len() - 1);
            let d = solver.distances(&[s]).unwrap();
            for (i, p) in v.iter().enumerate() {
                let e = euclid(*p, v[s]);
                assert!(
                    (d[i] - e).abs() < 1e-9,
                    "source {s} vertex {i}: {} vs {e}",
                    d[i]
                );
            }
        }
    }
}

/// An L-shaped flat domain: [0,2]x[0,2] minus (1,2]x(1,2]. From the source
/// at (1.75, 0.25), points hidden behind the reflex corner c = (1, 1) are
/// reached through it: distance |s c| + |c p|.
#[test]
fn l_shape_bends_around_the_reflex_corner() {
    let n = 8;
    let full = grid(2.0, 2.0, n, n);
    let (v, f) = full.into_parts();
    let keep = |p: [f64; 3]| !(p[0] > 1.0 + 1e-9 && p[1] > 1.0 + 1e-9);
    let faces: Vec<[usize; 3]> = f
        .into_iter()
        .filter(|t| {
            let c = [0, 1, 2].map(|k| v[t[k]]);
            keep([
                (c[0][0] + c[1][0] + c[2][0]) / 3.0,
                (c[0][1] + c[1][1] + c[2][1]) / 3.0,
                0.0,
            ])
        })
        .collect();
    let mesh = TriMesh::new(v.clone(), faces).unwrap();
    let solver = ExactSolver::new(&mesh).unwrap();
    let src = v
        .iter()
        .position(|p| (p[0] - 1.75).abs() < 1e-9 && (p[1] - 0.25).abs() < 1e-9)
        .unwrap();
    let d = solver.distances(&[src]).unwrap();
    let (s, c) = (v[src], [1.0, 1.0, 0.0]);
    let mut hidden_count = 0;
    for (i, p) in v.iter().enumerate() {
        if !keep(*p) {
            assert!(d[i].is_infinite(), "removed vertex {i} must be unreachable");
            continue;
        }
        // p is hidden iff the segment s-p crosses y = 1 at x > 1 (into the
        // removed square): s is below it, inside 1 <= x <= 2.
        let hidden = p[1] > 1.0 + 1e-12 && {
            let x_at = s[0] + (p[0] - s[0]) * (1.0 - s[1]) / (p[1] - s[1]);
            x_at > 1.0 + 1e-12
        };
        hidden_count += usize::from(hidden);
        let want = if hidden {
            euclid(s, c) + euclid(c, *p)
        } else {
            euclid(s, *p)
        };
        assert!(
            (d[i] - want).abs() < 1e-9,
            "vertex {i} at {p:?}: {} vs {want} (hidden {hidden})",
            d[i]
        );
    }
    assert!(
        hidden_count >= 10,
        "the test must exercise the pseudo-source"
    );
}

#[test]
fn sphere_distances_approach_great_circles() {
    let mesh = icosphere(1.0, 4);
    let v = mesh.vertices();
    let d = ExactSolver::new(&mesh).unwrap().distances(&[0]).unwrap();
    let dj = DijkstraSolver::new(&mesh).distances(&[0]).unwrap();
    for (i, p) in v.iter().enumerate() {
        let chord = euclid(*p, v[0]);
        let great = 2.0 * (chord / 2.0).asin();
        // Polyhedral geodesics are at least the chord, at most the edge path,
        // and within the discretization error of the great circle.
        assert!(d[i] >= chord - 1e-12 && d[i] <= dj[i] + 1e-12, "vertex {i}");
        assert!(
            (d[i] - great).abs() < 0.01 * great.max(0.1),
            "vertex {i}: {} vs {great}",
            d[i]
        );
    }
}

#[test]
fn disconnected_meshes_give_infinity() {
    let s = icosphere(1.0, 1);
    let mesh = disjoint_union(&s, &translated(&s, [3.0, 0.0, 0.0]).unwrap());
    let n = s.n_vertices();
    for solver in [
        Box::new(ExactSolver::new(&mesh).unwrap()) as Box<dyn DistanceSolver>,
        Box::new(DijkstraSolver::new(&mesh)),
        Box::new(HeatSolver::new(&mesh, &HeatParams::default()).unwrap()),
    ] {
        let d = solver.distances(&[0]).unwrap();
        assert!(d[..n].iter().all(|x| x.is_finite()), "{}", solver.name());
        assert!(
            d[n..].iter().all(|x| x.is_infinite() && !x.is_nan()),
            "{}",
            solver.name()
        );
    }
    // Sources on both components: each component's distances are those of
    // its own sources, as on the component alone (the heat method's
    // per-component constant is fixed by the component's own sources).
    let alone = HeatSolver::new(&s, &HeatParams::default()).unwrap();
    let both = HeatSolver::new(&mesh, &HeatParams::default()).unwrap();
    let d = both.distances(&[0, n + 5]).unwrap();
    let (d0, d5) = (
        alone.distances(&[0]).unwrap(),
        alone.distances(&[5]).unwrap(),
    );
    for v in 0..n {
        // Up to the Poisson shift (1e-8 of the first eigenvalue, set by the
        // total area, which differs).
        assert!(
            (d[v] - d0[v]).abs() < 1e-6,
            "vertex {v}: {} vs {}",
            d[v],
            d0[v]
        );
        assert!(
            (d[n + v] - d5[v]).abs() < 1e-6,
            "vertex {}: {} vs {}",
            n + v,
            d[n + v],
            d5[v]
        );
    }
}

#[test]
fn early_stop_agrees_with_full_field() {
    let mesh = torus(2.0, 0.7, 24, 12);
    let exact = ExactSolver::new(&mesh).unwrap();
    for solver in [
        Box::new(exact.clone()) as Box<dyn DistanceSolver>,
        Box::new(exact.with_algorithm(ExactAlgorithm::WindowOrdered)),
        Box::new(DijkstraSolver::new(&mesh)),
    ] {
        let full = solver.distances(&[3]).unwrap();
        let targets = [3, 17, 200, 5, 140];
        let some = solver.distances_to(&[3], &targets).unwrap();
        // A stopped run is the full run cut short: the same numbers.
        for (t, d) in targets.iter().zip(&some) {
            assert_eq!(*d, full[*t], "{}", solver.name());
        }
        // Several sources: the distance to the nearest.
        let two = solver.distances(&[3, 150]).unwrap();
        let other = solver.distances(&[150]).unwrap();
        for i in 0..full.len() {
            assert!((two[i] - full[i].min(other[i])).abs() < 1e-12);
        }
        let fields = solver.fields(&[3, 150]).unwrap();
        assert_eq!(fields[0], full);
        assert_eq!(fields[1], other);
    }
}

/// Early stop on a mesh where most vertices are saddles (windows cast
/// from everywhere, settled vertices still improving): near and far
/// targets, one or several, give their full-field values, and the run
/// stops early for near targets.
#[test]
fn early_stop_is_exact_among_saddles() {
    let mesh = noisy_sphere();
    let solver = ExactSolver::new(&mesh).unwrap();
    let n = mesh.n_vertices();
    for s in [0, n / 2, n - 1] {
        let full = solver.distances(&[s]).unwrap();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| full[a].total_cmp(&full[b]));
        for targets in [
            vec![order[1]],
            vec![order[n / 10], order[3]],
            vec![order[n / 2]],
            vec![order[n - 1], order[n / 3], s],
        ] {
            let d = solver.distances_until(&[s], &targets).unwrap();
            for &t in &targets {
                assert_eq!(d[t], full[t], "source {s} target {t}");
            }
            if targets.len() == 1 && targets[0] == order[1] {
                // Stopped early: far vertices not reached yet.
                assert!(d.iter().any(|x| x.is_infinite()));
            }
        }
    }
}

#[test]
fn errors() {
    let mesh = grid(1.0, 1.0, 2, 2);
    let s = ExactSolver::new(&mesh).unwrap();
    assert_eq!(
        s.distances(&[9]).unwrap_err(),
        Error::VertexOutOfRange {
            index: 9,
            n_vertices: 9
        }
    );
    assert_eq!(s.distances(&[]).unwrap_err(), Error::NoSources);
    assert_eq!(
        s.distances_to(&[0], &[42]).unwrap_err(),
        Error::VertexOutOfRange {
            index: 42,
            n_vertices: 9
        }
    );
    let (mut v, mut f) = grid(1.0, 1.0, 2, 2).into_parts();
    v.push([0.25, 0.0, 0.0]);
    f.push([0, 9, 1]);
    assert_eq!(
        ExactSolver::new(&TriMesh::new(v.clone(), f.clone()).unwrap()).unwrap_err(),
        Error::DegenerateFace { face: 8 }
    );
    f.pop();
    v.push([0.5, -1.0, 0.3]);
    f.push([0, 1, 10]); // edge 0-1 is on the boundary: now shared by 2 faces, fine
    f.push([1, 0, 10]); // duplicate geometry: 0-1 now has three faces
    assert!(matches!(
        ExactSolver::new(&TriMesh::new(v, f).unwrap()),
        Err(Error::NonManifoldEdge { .. })
    ));
}

fn irregular() -> TriMesh {
    // A bumpy torus: saddle and non-saddle vertices, no symmetry.
    let t = torus(2.0, 0.8, 18, 11);
    let (mut v, f) = t.into_parts();
    for (k, p) in v.iter_mut().enumerate() {
        let s = 1.0 + 0.08 * ((k * 31 % 17) as f64 / 17.0 - 0.5);
        *p = [p[0] * s, p[1] * s, p[2] * (2.0 - s)];
    }
    TriMesh::new(v, f).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn symmetric_and_triangle_inequality(a in 0usize..198, b in 0usize..198, c in 0usize..198) {
        let mesh = irregular();
        let s = ExactSolver::new(&mesh).unwrap();
        let da = s.distances(&[a]).unwrap();
        let db = s.distances(&[b]).unwrap();
        prop_assert!((da[b] - db[a]).abs() <= 1e-9 * (1.0 + da[b]));
        prop_assert!(da[c] <= da[b] + db[c] + 1e-9);
        let dj = DijkstraSolver::new(&mesh).distances(&[a]).unwrap();
        prop_assert!(da[c] <= dj[c] + 1e-12);
        prop_assert!(da[c] >= euclid(mesh.vertices()[a], mesh.vertices()[c]) - 1e-12);
    }
}

/// The heat method approximates exact distances: within a few percent away
/// from the source (its error is of the order of the mesh spacing).
#[test]
fn heat_method_approximates_exact_distances() {
    for (name, mesh) in [
        ("sphere", icosphere(1.0, 4)),
        ("grid", jittered_grid(30, 30)),
        ("bumpy torus", irregular()),
    ] {
        let exact = ExactSolver::new(&mesh).unwrap();
        let heat = HeatSolver::new(&mesh, &HeatParams::default()).unwrap();
        assert_eq!(heat.name(), "heat");
        let src = mesh.n_vertices() / 3;
        let de = exact.distances(&[src]).unwrap();
        let dh = heat.distances(&[src]).unwrap();
        assert_eq!(dh[src], 0.0);
        let dmax = de.iter().copied().fold(0.0, f64::max);
        let far: Vec<f64> = (0..de.len())
            .filter(|&i| de[i] > 0.2 * dmax)
            .map(|i| (dh[i] - de[i]).abs() / de[i])
            .collect();
        let mean = far.iter().sum::<f64>() / far.len() as f64;
        assert!(mean < 0.05, "{name}: mean relative deviation {mean}");
        // Reused across sources: a second source gives a different field.
        let d2 = heat.distances(&[0]).unwrap();
        assert_eq!(d2[0], 0.0);
        assert!(d2[src] > 0.0);
    }
}

/// A sphere with every vertex pushed in or out: most vertices become
/// saddles, the hard case of exact propagation (pseudo-sources everywhere).
fn noisy_sphere() -> TriMesh {
    let (mut v, f) = icosphere(1.0, 3).into_parts();
    for (k, p) in v.iter_mut().enumerate() {
        let s = 1.0 + 0.04 * (((k * 7919) % 101) as f64 / 101.0 - 0.5);
        *p = [p[0] * s, p[1] * s, p[2] * s];
    }
    TriMesh::new(v, f).unwrap()
}

/// The two exact schemes share only the window geometry: their
/// scheduling and pruning (vertex queue, one angle two sides, saddle shadows
/// versus window order and trimming against every accepted window)
/// differ, so agreement to rounding on meshes with many saddles, a
/// boundary, a reflex corner and several sources checks both.
#[test]
fn vtp_agrees_with_window_ordered_propagation() {
    let n = 24;
    let (v, f) = grid(2.0, 2.0, n, n).into_parts();
    let keep: Vec<[usize; 3]> = f
        .into_iter()
        .filter(|t| {
            t.iter()
                .any(|&i| v[i][0] <= 1.0 + 1e-9 || v[i][1] <= 1.0 + 1e-9)
        })
        .filter(|t| {
            !t.iter()
                .all(|&i| v[i][0] >= 1.0 - 1e-9 && v[i][1] >= 1.0 - 1e-9)
        })
        .collect();
    let l_shape = TriMesh::new(v, keep).unwrap();
    let meshes = [
        ("bumpy torus", irregular()),
        ("noisy sphere", noisy_sphere()),
        ("jittered grid", jittered_grid(12, 9)),
        ("L shape", l_shape),
        (
            "two spheres",
            disjoint_union(
                &icosphere(1.0, 2),
                &translated(&noisy_sphere(), [3.0, 0.0, 0.0]).unwrap(),
            ),
        ),
    ];
    for (name, mesh) in meshes {
        let vtp = ExactSolver::new(&mesh).unwrap();
        assert_eq!(vtp.algorithm(), ExactAlgorithm::Vtp);
        let ordered = vtp.clone().with_algorithm(ExactAlgorithm::WindowOrdered);
        let nv = mesh.n_vertices();
        for sources in [vec![0], vec![nv / 3], vec![nv - 1, nv / 2], vec![7, 8, 9]] {
            let (a, sa) = vtp.distances_with_stats(&sources).unwrap();
            let (b, sb) = ordered.distances_with_stats(&sources).unwrap();
            assert!(sa.windows > 0 && sb.windows > 0);
            for i in 0..nv {
                assert!(
                    a[i] == b[i] || (a[i] - b[i]).abs() <= 1e-12 * (1.0 + b[i]),
                    "{name}, sources {sources:?}, vertex {i}: VTP {} vs {}",
                    a[i],
                    b[i]
                );
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// VTP against the window-ordered scheme on randomly roughened
    /// spheres (random saddles, random excess angles up to tens of
    /// degrees) from a random source, whole fields and one early stop.
    #[test]
    fn vtp_agrees_on_random_rough_spheres(
        noise in proptest::collection::vec(-1.0f64..1.0, 162),
        amplitude in 0.0f64..0.15,
        source in 0usize..162,
        target in 0usize..162,
    ) {
        let (mut v, f) = icosphere(1.0, 2).into_parts();
        for (p, e) in v.iter_mut().zip(&noise) {
            let s = 1.0 + amplitude * e;
            *p = [p[0] * s, p[1] * s, p[2] * s];
        }
        let mesh = TriMesh::new(v, f).unwrap();
        let vtp = ExactSolver::new(&mesh).unwrap();
        let ordered = vtp.clone().with_algorithm(ExactAlgorithm::WindowOrdered);
        let a = vtp.distances(&[source]).unwrap();
        let b = ordered.distances(&[source]).unwrap();
        for i in 0..a.len() {
            prop_assert!((a[i] - b[i]).abs() <= 1e-12 * (1.0 + b[i]), "vertex {}: {} vs {}", i, a[i], b[i]);
        }
        let early = vtp.distances_to(&[source], &[target]).unwrap();
        prop_assert_eq!(early[0], a[target]);
    }
}
