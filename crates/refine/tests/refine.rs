//! ICP and ZoomOut on a near-isometric pair with known truth: a bumpy torus
//! A and B = A stretched by a few percent with its vertices permuted, so
//! the true map is a permutation and the two bases are independent (signs
//! and near-degenerate eigenspaces differ).

use fmaps_eigensolve::SpectralBasis;
use fmaps_mesh_io::TriMesh;
use fmaps_refine::RefineInput;
use fmaps_refine::{Error, Icp, Refiner, Subsample, ZoomOut, farthest_point_sampling};
use fmaps_shapes::torus;
use fmaps_solve::{fmap_from_point_map, point_map_from_fmap};
use nalgebra::DMatrix;

mod common;
use common::basis;

struct Pair {
    a: TriMesh,
    basis_a: SpectralBasis,
    b: TriMesh,
    basis_b: SpectralBasis,
    /// True map B → A.
    t_ba: Vec<usize>,
}

/// A fixed pseudo-random permutation `perm[new] = old` of `0..n` (from
/// `seed`) and its inverse.
fn permutation(n: usize, seed: u64) -> (Vec<usize>, Vec<usize>) {
    let mut perm: Vec<usize> = (0..n).collect();
    let mut state = seed;
    for i in (1..n).rev() {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        perm.swap(i, (state >> 33) as usize % (i + 1));
    }
    let mut inv = vec![0; n];
    for (new, &old) in perm.iter().enumerate() {
        inv[old] = new;
    }
    (perm, inv)
}

/// `deformed`: B is a differently bumped, bent torus (nearly isometric);
/// otherwise B is A stretched by a few percent, which the low spectrum
/// does not see (the true map converts exactly).
impl Pair {
    /// The refinement input of `c` (A → B) between the pair's bases.
    fn input<'a>(&'a self, c: &'a DMatrix<f64>) -> RefineInput<'a> {
        RefineInput::new(c, &self.basis_a, &self.basis_b)
    }
}

fn pair(k: usize, deformed: bool) -> Pair {
    let (mut v, f) = torus(2.0, 0.8, 44, 18).into_parts();
    for (i, p) in v.iter_mut().enumerate() {
        let s = 1.0 + 0.08 * ((i * 31 % 17) as f64 / 17.0 - 0.5);
        *p = [p[0] * s, p[1] * s * 1.1, p[2] * (2.0 - s)];
    }
    let a = TriMesh::new(v.clone(), f.clone()).unwrap();
    let n = v.len();
    let (perm, inv) = permutation(n, 12345);
    // B: the plain torus with other bumps and a bend, so the shapes are
    // only nearly isometric.
    let (v0, _) = torus(2.0, 0.8, 44, 18).into_parts();
    let vb: Vec<[f64; 3]> = perm
        .iter()
        .map(|&o| {
            if !deformed {
                return [v[o][0] * 1.04, v[o][1], v[o][2] * 0.97];
            }
            let s = 1.0 + 0.1 * ((o * 37 % 19) as f64 / 19.0 - 0.5);
            let p = v0[o];
            [
                p[0] * s * 1.05,
                p[1] * s,
                p[2] * (2.0 - s) + 0.15 * p[0] * p[0],
            ]
        })
        .collect();
    let fb: Vec<[usize; 3]> = f
        .iter()
        .map(|t| [inv[t[0]], inv[t[1]], inv[t[2]]])
        .collect();
    let b = TriMesh::new(vb, fb).unwrap();
    Pair {
        basis_a: basis(&a, k),
        basis_b: basis(&b, k),
        a,
        b,
        t_ba: perm,
    }
}

/// Mean Euclidean distance on A between the predicted and the true image
/// of every vertex of B.
/// [`error`] of the nearest-neighbour point map of the functional map `c`.
fn fmap_error(p: &Pair, c: &DMatrix<f64>) -> f64 {
    error(p, &point_map_from_fmap(c, &p.basis_a, &p.basis_b).unwrap())
}

/// ZoomOut from `k_start` to `k_final` in steps of 2, else the defaults.
fn zoomout(k_start: usize, k_final: usize) -> ZoomOut {
    ZoomOut {
        k_start,
        k_final,
        step: 2,
        ..ZoomOut::default()
    }
}

fn error(p: &Pair, t_ba: &[usize]) -> f64 {
    let va = p.a.vertices();
    let s: f64 = t_ba
        .iter()
        .zip(&p.t_ba)
        .map(|(&x, &y)| {
            let (u, w) = (va[x], va[y]);
            ((u[0] - w[0]).powi(2) + (u[1] - w[1]).powi(2) + (u[2] - w[2]).powi(2)).sqrt()
        })
        .sum();
    s / t_ba.len() as f64
}

fn true_fmap(p: &Pair, k: usize) -> DMatrix<f64> {
    let c = fmap_from_point_map(&p.t_ba, &p.basis_a, &p.basis_b).unwrap();
    c.view((0, 0), (k, k)).into_owned()
}

fn noisy(c: &DMatrix<f64>, sigma: f64, seed: u64) -> DMatrix<f64> {
    let mut state = seed;
    c.map(|v| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let u = (state >> 11) as f64 / (1u64 << 53) as f64;
        v + sigma * (2.0 * u - 1.0)
    })
}

#[test]
fn an_exact_map_stays_exact() {
    let p = pair(60, false);
    let c = true_fmap(&p, 60);
    assert_eq!(
        point_map_from_fmap(&c, &p.basis_a, &p.basis_b).unwrap(),
        p.t_ba
    );
    let icp = Icp::default().refine(&p.input(&c)).unwrap();
    assert_eq!(icp.t_ba, p.t_ba);
    assert!(icp.report.converged, "{}", icp.report);
    let zo = ZoomOut {
        k_start: 20,
        k_final: 60,
        step: 4,
        ..ZoomOut::default()
    }
    .refine(&p.input(&c))
    .unwrap();
    assert_eq!(zo.t_ba, p.t_ba);
    assert_eq!(zo.c_ab.shape(), (60, 60));
    // The refined map is the true one at k = 60.
    assert!((&zo.c_ab - &c).amax() < 1e-12);
    assert_eq!(zo.report.iterations.len(), 10);
    assert_eq!(zo.report.nn_searches, 11);
}

#[test]
fn zoomout_recovers_a_low_rank_truncation() {
    // The true map seen through 6 eigenfunctions converts to a poor point
    // map; ZoomOut to 60 recovers most of it.
    let p = pair(60, true);
    let c6 = true_fmap(&p, 6);
    let before = fmap_error(&p, &c6);
    let zo = zoomout(6, 60).refine(&p.input(&c6)).unwrap();
    let after = error(&p, &zo.t_ba);
    assert!(after < 0.2 * before, "before {before}, after {after}");
    // The iterations shrink the changes of the point map.
    let ch: Vec<usize> = zo.report.iterations.iter().map(|i| i.changed).collect();
    assert!(ch.last().unwrap() * 5 < ch[1], "{ch:?}");
}

#[test]
fn refiners_reduce_the_error_of_a_noisy_map() {
    let p = pair(60, true);
    let c = noisy(&true_fmap(&p, 20), 0.15, 7);
    let before = fmap_error(&p, &c);
    let icp = Icp::default().refine(&p.input(&c)).unwrap();
    let e_icp = error(&p, &icp.t_ba);
    // ICP returns an orthonormal map.
    let ctc = icp.c_ab.tr_mul(&icp.c_ab);
    assert!((ctc - DMatrix::identity(20, 20)).amax() < 1e-10);
    let zo = |z: ZoomOut| error(&p, &z.refine(&p.input(&c)).unwrap().t_ba);
    let base = zoomout(20, 60);
    let e_zo = zo(base.clone());
    let e_adj = zo(ZoomOut {
        adjoint: true,
        ..base.clone()
    });
    let e_bij = zo(ZoomOut {
        bijective: true,
        ..base.clone()
    });
    for (name, e) in [
        ("icp", e_icp),
        ("zoomout", e_zo),
        ("adjoint", e_adj),
        ("bijective", e_bij),
    ] {
        assert!(e < 0.5 * before, "{name}: before {before}, after {e}");
    }
    assert!(e_zo < e_icp, "zoomout {e_zo} vs icp {e_icp}");
}

#[test]
fn subsampled_zoomout_is_close_to_the_full_one() {
    let p = pair(60, true);
    let c = noisy(&true_fmap(&p, 20), 0.15, 7);
    let before = fmap_error(&p, &c);
    let base = zoomout(20, 60);
    let full = error(&p, &base.refine(&p.input(&c)).unwrap().t_ba);
    let sub = Subsample::farthest(p.a.vertices(), p.b.vertices(), 500);
    assert_eq!(sub.a, farthest_point_sampling(p.a.vertices(), 500, 0));
    assert_eq!(sub.b, farthest_point_sampling(p.b.vertices(), 500, 0));
    let z = ZoomOut {
        subsample: Some(sub.clone()),
        ..base.clone()
    };
    let out = z.refine(&p.input(&c)).unwrap();
    assert_eq!(out.t_ba.len(), p.b.vertices().len());
    // The final map (searched from each vertex's nearest sample's image)
    // is the exact conversion of the final C, as without those guesses.
    assert_eq!(
        out.t_ba,
        point_map_from_fmap(&out.c_ab, &p.basis_a, &p.basis_b).unwrap()
    );
    let unguided = ZoomOut {
        subsample: Some(Subsample {
            nearest_b: Vec::new(),
            ..sub.clone()
        }),
        ..base.clone()
    }
    .refine(&p.input(&c))
    .unwrap();
    assert_eq!(unguided.t_ba, out.t_ba);
    // One iteration on every vertex after the samples: the fit of the
    // sampled run's map with B's mass, then its exact conversion.
    let z1 = ZoomOut {
        full_iterations: 1,
        ..z.clone()
    };
    let one = z1.refine(&p.input(&c)).unwrap();
    assert_eq!(one.report.iterations.len(), out.report.iterations.len() + 1);
    assert!(
        z1.name().ends_with("samples 500/500 + 1 on every vertex"),
        "{}",
        z1.name()
    );
    let c1 = fmap_from_point_map(&out.t_ba, &p.basis_a, &p.basis_b).unwrap();
    assert_eq!(c1.shape(), one.c_ab.shape());
    assert!(
        (&c1 - &one.c_ab).amax() < 1e-9,
        "{}",
        (&c1 - &one.c_ab).amax()
    );
    assert_eq!(
        one.t_ba,
        point_map_from_fmap(&one.c_ab, &p.basis_a, &p.basis_b).unwrap()
    );
    // Nearest samples of the wrong length or out of range: errors.
    for nearest_b in [vec![0; 3], vec![500; p.b.vertices().len()]] {
        let err = ZoomOut {
            subsample: Some(Subsample {
                nearest_b,
                ..sub.clone()
            }),
            ..base.clone()
        }
        .refine(&p.input(&c))
        .unwrap_err();
        assert!(matches!(err, Error::InvalidParameter(_)), "{err}");
    }
    let e = error(&p, &out.t_ba);
    assert!(
        e < 0.5 * before && e < 2.0 * full + 0.02,
        "before {before}, full {full}, sub {e}"
    );
    // Too few samples for k = 60 is an error, not a singular solve.
    let few = Subsample {
        a: sub.a.clone(),
        b: sub.b[..40].to_vec(),
        nearest_b: Vec::new(),
        nearest_a: Vec::new(),
    };
    let err = ZoomOut {
        subsample: Some(few),
        ..base.clone()
    }
    .refine(&p.input(&c))
    .unwrap_err();
    assert!(matches!(err, Error::InvalidParameter(_)), "{err}");
    let bad = Subsample {
        a: vec![0, 99_999],
        b: sub.b,
        nearest_b: Vec::new(),
        nearest_a: Vec::new(),
    };
    let err = ZoomOut {
        subsample: Some(bad),
        ..base
    }
    .refine(&p.input(&c))
    .unwrap_err();
    assert_eq!(
        err,
        Error::SampleOutOfRange {
            shape: "A",
            at: 1,
            index: 99_999,
            n: p.a.vertices().len()
        }
    );
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let p = pair(40, true);
    let c = noisy(&true_fmap(&p, 12), 0.2, 3);
    let z = ZoomOut {
        k_start: 12,
        k_final: 40,
        step: 3,
        bijective: true,
        ..ZoomOut::default()
    };
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| z.refine(&p.input(&c)).unwrap())
    };
    let one = run(1);
    for threads in [2, 3, 7, 2] {
        let r = run(threads);
        assert_eq!(one.t_ba, r.t_ba, "{threads} threads");
        assert_eq!(one.c_ab, r.c_ab, "{threads} threads");
    }
}

#[test]
fn parameter_errors() {
    let p = pair(30, true);
    let c = true_fmap(&p, 20);
    let r = |z: ZoomOut| z.refine(&p.input(&c)).unwrap_err();
    assert_eq!(
        r(ZoomOut {
            k_start: 20,
            k_final: 50,
            step: 5,
            ..ZoomOut::default()
        }),
        Error::NotEnoughEigenpairs {
            shape: "A",
            needed: 50,
            available: 30
        }
    );
    assert!(matches!(
        r(ZoomOut {
            k_start: 25,
            k_final: 30,
            step: 5,
            ..ZoomOut::default()
        }),
        Error::InvalidParameter(_)
    ));
    assert!(matches!(
        r(ZoomOut {
            k_start: 10,
            k_final: 30,
            step: 0,
            ..ZoomOut::default()
        }),
        Error::InvalidParameter(_)
    ));
    assert_eq!(
        ZoomOut {
            k_start: 10,
            k_final: 21,
            step: 5,
            ..ZoomOut::default()
        }
        .schedule(),
        vec![15, 20, 21]
    );
    let big = DMatrix::<f64>::zeros(40, 40);
    assert_eq!(
        Icp::default().refine(&p.input(&big)).unwrap_err(),
        Error::NotEnoughEigenpairs {
            shape: "A",
            needed: 40,
            available: 30
        }
    );
}

/// Every refiner of this crate, in its variants, passes the exported
/// conformance check; a refiner that breaks the contract fails it.
#[test]
fn refiners_pass_the_exported_conformance_check() {
    use fmaps_refine::conformance;
    let zo = |adjoint, bijective| ZoomOut {
        k_start: 20,
        k_final: 50,
        step: 5,
        adjoint,
        bijective,
        ..ZoomOut::default()
    };
    let refiners: Vec<Box<dyn Refiner>> = vec![
        Box::new(Icp::default()),
        Box::new(Icp {
            adjoint: true,
            ..Icp::default()
        }),
        Box::new(zo(false, false)),
        Box::new(zo(true, false)),
        Box::new(zo(false, true)),
        Box::new(discrete("bijective-zoomout", 20, 50, 5)),
        Box::new(discrete("discrete", 20, 50, 5)),
    ];
    for r in &refiners {
        conformance::check(r.as_ref()).unwrap_or_else(|e| panic!("{e}"));
    }

    /// ZoomOut that then shifts every vertex of the map by one.
    #[derive(Debug)]
    struct OffByOne(ZoomOut);
    impl Refiner for OffByOne {
        fn name(&self) -> String {
            "off-by-one".into()
        }
        fn refine(&self, input: &RefineInput<'_>) -> fmaps_refine::Result<fmaps_refine::Refined> {
            let mut r = self.0.refine(input)?;
            let n = input.basis_a.n();
            r.t_ba.iter_mut().for_each(|x| *x = (*x + 1) % n);
            Ok(r)
        }
        fn k_needed(&self) -> usize {
            self.0.k_needed()
        }
    }
    let e = conformance::check(&OffByOne(zo(false, false))).unwrap_err();
    assert_eq!(e.check, "identity self-map", "{e}");
}

fn discrete(preset: &str, k_start: usize, k_final: usize, step: usize) -> fmaps_refine::DiscreteOp {
    fmaps_refine::DiscreteOp {
        k_start,
        k_final,
        step,
        ..fmaps_refine::DiscreteOp::preset(preset).unwrap()
    }
}

/// Discrete optimisation: the `zoomout` preset (orthogonality term only)
/// is ZoomOut and the coupling term alone is ZoomOut with the adjoint
/// conversion, computed independently (own embeddings and searches);
/// the exact map is a fixed point of every preset; bijective ZoomOut
/// returns maps that are much closer to inverse to each other on a noisy
/// start, and every preset reduces the error of the noisy map.
#[test]
fn discrete_optimisation_presets() {
    let p = pair(60, true);
    let c = noisy(&true_fmap(&p, 20), 0.15, 7);
    let zo = ZoomOut {
        k_start: 20,
        k_final: 60,
        step: 4,
        ..ZoomOut::default()
    }
    .refine(&p.input(&c))
    .unwrap();
    let dz = discrete("zoomout", 20, 60, 4).refine(&p.input(&c)).unwrap();
    assert_eq!(zo.t_ba, dz.t_ba);
    assert_eq!(dz.c_ab.shape(), (60, 60));
    let adjoint = ZoomOut {
        k_start: 20,
        k_final: 60,
        step: 4,
        adjoint: true,
        ..ZoomOut::default()
    }
    .refine(&p.input(&c))
    .unwrap();
    let coupling = fmaps_refine::DiscreteOp {
        weights: fmaps_refine::DiscreteWeights {
            coupling: 1.0,
            bijectivity: 0.0,
            orthogonality: 0.0,
            laplacian: 0.0,
        },
        ..discrete("zoomout", 20, 60, 4)
    };
    let dc = coupling.refine(&p.input(&c)).unwrap();
    assert_eq!(adjoint.t_ba, dc.t_ba);
    assert_eq!(dz.report.iterations.len(), 10);
    // Two searches per size plus the two first conversions.
    assert_eq!(dz.report.nn_searches, 22);

    let exact = pair(60, false);
    let c_exact = true_fmap(&exact, 60);
    for preset in ["zoomout", "bijective-zoomout", "discrete"] {
        let r = discrete(preset, 20, 60, 4)
            .refine(&RefineInput::new(&c_exact, &exact.basis_a, &exact.basis_b))
            .unwrap();
        assert_eq!(r.t_ba, exact.t_ba, "{preset}");
    }

    let before = fmap_error(&p, &c);
    for preset in ["bijective-zoomout", "discrete"] {
        let r = discrete(preset, 20, 60, 4).refine(&p.input(&c)).unwrap();
        let e = error(&p, &r.t_ba);
        assert!(e < 0.5 * before, "{preset}: before {before}, after {e}");
    }
    assert!(fmaps_refine::DiscreteOp::preset("nope").is_err());
    let bad = fmaps_refine::DiscreteOp {
        inner: 0,
        ..discrete("discrete", 20, 60, 4)
    };
    assert!(bad.refine(&p.input(&c)).is_err());
}

fn geometry(m: &TriMesh) -> fmaps_refine::ShapeGeometry<'_> {
    fmaps_refine::ShapeGeometry {
        vertices: m.vertices(),
        faces: m.faces(),
    }
}

#[test]
fn the_repair_keeps_an_exact_map_and_repairs_a_noisy_one() {
    use fmaps_refine::Repair;
    let p = pair(60, true);
    // Identity on a self-map.
    let id = DMatrix::<f64>::identity(20, 20);
    let r = Repair::default()
        .refine(
            &RefineInput::new(&id, &p.basis_a, &p.basis_a)
                .with_geometry(geometry(&p.a), geometry(&p.a)),
        )
        .unwrap();
    assert!(r.t_ba.iter().enumerate().all(|(y, &x)| x == y));
    assert_eq!(r.c_ab.shape(), (20, 20));
    // A noisy map of the nearly isometric, renumbered pair: repaired below
    // half the error and (permutation equivariance) to the true
    // renumbering wherever the map is right.
    let c = noisy(&true_fmap(&p, 20), 0.15, 7);
    let before = fmap_error(&p, &c);
    let r = Repair::default()
        .refine(&p.input(&c).with_geometry(geometry(&p.a), geometry(&p.b)))
        .unwrap();
    let after = error(&p, &r.t_ba);
    assert!(after < 0.5 * before, "before {before}, after {after}");
    // More bijective than the nearest-neighbour conversion of the same C.
    let hit = |t: &[usize]| {
        let mut s = t.to_vec();
        s.sort_unstable();
        s.dedup();
        s.len()
    };
    let nn = point_map_from_fmap(&c, &p.basis_a, &p.basis_b).unwrap();
    assert!(hit(&r.t_ba) > hit(&nn), "{} vs {}", hit(&r.t_ba), hit(&nn));
    // Without the geometry it refuses rather than guessing.
    assert!(Repair::default().refine(&p.input(&c)).is_err());
    // Geometry that does not belong to the bases is refused.
    let tiny = fmaps_shapes::icosphere(1.0, 1);
    assert!(
        Repair::default()
            .refine(&p.input(&c).with_geometry(geometry(&tiny), geometry(&p.b)))
            .is_err()
    );
}

/// A fast Smooth Shells configuration for small test meshes.
fn shells() -> fmaps_refine::SmoothShells {
    fmaps_refine::SmoothShells {
        k_max: 40,
        levels: 12,
        samples: 700,
        init_samples: 400,
        proposals: 12,
        ..Default::default()
    }
}

/// `a` with its vertices moved by `place` and renumbered (seed `seed`);
/// `turn_faces` reverses the faces (for a mirror image, to keep them
/// outward). Returns the copy and, per copy vertex, its vertex of `a`.
fn renumbered_copy(
    a: &TriMesh,
    seed: u64,
    turn_faces: bool,
    place: impl Fn([f64; 3]) -> [f64; 3],
) -> (TriMesh, Vec<usize>) {
    let (perm, inv) = permutation(a.n_vertices(), seed);
    let vb: Vec<[f64; 3]> = perm.iter().map(|&o| place(a.vertices()[o])).collect();
    let fb: Vec<[usize; 3]> = a
        .faces()
        .iter()
        .map(|t| {
            if turn_faces {
                [inv[t[0]], inv[t[2]], inv[t[1]]]
            } else {
                [inv[t[0]], inv[t[1]], inv[t[2]]]
            }
        })
        .collect();
    (TriMesh::new(vb, fb).unwrap(), perm)
}

#[test]
fn smooth_shells_finds_the_identity_and_a_rotated_renumbered_copy() {
    use fmaps_shapes::{Pose, creature};
    let a = creature(3, &Pose::walking());
    let n = a.n_vertices();
    // B: A turned by 110 degrees about a tilted axis, moved, renumbered.
    let axis = nalgebra::Vector3::new(0.3, 1.0, -0.4).normalize();
    let rot = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), 1.92);
    let (b, perm) = renumbered_copy(&a, 99, false, |p| {
        let p = rot * nalgebra::Vector3::from(p);
        [p[0] + 3.0, p[1] - 1.0, p[2] + 0.5]
    });
    let k = shells().k_max + 9;
    let (ba, bb) = (basis(&a, k), basis(&b, k));
    let id = DMatrix::<f64>::identity(20, 20);
    // A shape to itself: exactly the identity.
    let r = shells()
        .refine(&RefineInput::new(&id, &ba, &ba).with_geometry(geometry(&a), geometry(&a)))
        .unwrap();
    assert!(r.t_ba.iter().enumerate().all(|(y, &x)| x == y));
    // The moved copy: the rigid step turns it back, the alignment finds
    // the renumbering (the input map, the identity, is wrong for it and
    // only one proposal among others).
    let r = shells()
        .refine(&RefineInput::new(&id, &ba, &bb).with_geometry(geometry(&a), geometry(&b)))
        .unwrap();
    let right = r.t_ba.iter().zip(&perm).filter(|(x, y)| x == y).count();
    assert!(
        right as f64 > 0.99 * n as f64,
        "{right} of {n} vertices right"
    );
    assert_eq!(r.c_ab.shape(), (49, 49));
    // Screening all eight rigid orientations finds it as well.
    let screened = fmaps_refine::SmoothShells {
        screen: 8,
        ..shells()
    };
    let r = screened
        .refine(&RefineInput::new(&id, &ba, &bb).with_geometry(geometry(&a), geometry(&b)))
        .unwrap();
    let right = r.t_ba.iter().zip(&perm).filter(|(x, y)| x == y).count();
    assert!(
        right as f64 > 0.99 * n as f64,
        "screened: {right} of {n} vertices right"
    );
    // It needs the geometry, bases large enough for its shells, geometry
    // that belongs to the bases.
    assert!(shells().refine(&RefineInput::new(&id, &ba, &bb)).is_err());
    let small = basis(&a, 30);
    assert!(matches!(
        shells()
            .refine(&RefineInput::new(&id, &small, &bb).with_geometry(geometry(&a), geometry(&b))),
        Err(Error::NotEnoughEigenpairs { needed: 49, .. })
    ));
    let tiny = fmaps_shapes::icosphere(1.0, 1);
    assert!(
        shells()
            .refine(&RefineInput::new(&id, &ba, &bb).with_geometry(geometry(&tiny), geometry(&b)))
            .is_err()
    );
}

#[test]
fn smooth_shells_reflects_for_a_mirrored_copy_and_the_orientation_score_tells() {
    use fmaps_shapes::{Pose, creature};
    // B: the mirror image (x -> -x, faces turned to stay outward) of an
    // asymmetric creature, renumbered. The true map reverses orientation.
    let a = creature(3, &Pose::walking());
    let n = a.n_vertices();
    let (b, perm) = renumbered_copy(&a, 7, true, |p| [-p[0], p[1], p[2]]);
    let k = shells().k_max + 9;
    let (ba, bb) = (basis(&a, k), basis(&b, k));
    let id = DMatrix::<f64>::identity(20, 20);
    let run = |reflect: bool| {
        let r = fmaps_refine::SmoothShells {
            reflect,
            ..shells()
        }
        .refine(&RefineInput::new(&id, &ba, &bb).with_geometry(geometry(&a), geometry(&b)))
        .unwrap();
        let right = r.t_ba.iter().zip(&perm).filter(|(x, y)| x == y).count();
        let score = fmaps_refine::orientation_score(
            &r.t_ba,
            b.vertices(),
            b.faces(),
            a.vertices(),
            a.faces(),
        )
        .unwrap();
        (right, score)
    };
    // Declared mirrored: the reflection is found, and it reverses
    // orientation.
    let (right, score) = run(true);
    assert!(right as f64 > 0.95 * n as f64, "{right} of {n} right");
    assert!(score < -0.9, "orientation score {score}");
    // Not declared: no orientation-preserving map is the reflection; the
    // map found preserves orientation, which is what tells a mirrored
    // copy (its true map scores -1) from the map returned.
    let (right, score) = run(false);
    assert!((right as f64) < 0.5 * n as f64, "{right} of {n} right");
    assert!(score > 0.5, "orientation score {score}");
}

/// A guess of the first point map (the pipeline passes its conversion of
/// C) changes how fast the first search runs, never the result: ZoomOut
/// and ICP give the same maps, C and iteration reports with the exact
/// conversion, a wrong guess, out-of-range entries or a guess of the
/// wrong length as without one.
#[test]
fn a_guess_of_the_first_map_changes_nothing() {
    let p = pair(40, true);
    let c = noisy(&true_fmap(&p, 40), 0.1, 7);
    let n = p.t_ba.len();
    let exact = point_map_from_fmap(
        &c.view((0, 0), (20, 20)).into_owned(),
        &p.basis_a,
        &p.basis_b,
    )
    .unwrap();
    let shifted: Vec<usize> = exact.iter().map(|&t| (t + 5) % n).collect();
    let wild: Vec<usize> = (0..n).map(|i| if i % 2 == 0 { n + i } else { i }).collect();
    let short = vec![0usize; n / 2];
    fn geometry(m: &TriMesh) -> fmaps_refine::ShapeGeometry<'_> {
        fmaps_refine::ShapeGeometry {
            vertices: m.vertices(),
            faces: m.faces(),
        }
    }
    let refiners: [Box<dyn Refiner>; 2] = [Box::new(zoomout(20, 40)), Box::new(Icp::default())];
    for r in &refiners {
        let c0 = if r.name().starts_with("zoomout") {
            c.clone()
        } else {
            c.view((0, 0), (20, 20)).into_owned()
        };
        let plain = r.refine(&p.input(&c0)).unwrap();
        for guess in [&exact, &shifted, &wild, &short] {
            let g = r
                .refine(
                    &p.input(&c0)
                        .with_geometry(geometry(&p.a), geometry(&p.b))
                        .with_guess(guess),
                )
                .unwrap();
            assert_eq!(g.t_ba, plain.t_ba, "{}", r.name());
            assert_eq!(g.c_ab, plain.c_ab, "{}", r.name());
            let changed = |x: &fmaps_refine::Refined| -> Vec<usize> {
                x.report.iterations.iter().map(|i| i.changed).collect()
            };
            assert_eq!(changed(&g), changed(&plain), "{}", r.name());
        }
    }
}
