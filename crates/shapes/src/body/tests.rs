//! Tests of the body generator.

use super::*;

fn mean_relative_edge_change(a: &TriMesh, b: &TriMesh) -> f64 {
    let (va, vb) = (a.vertices(), b.vertices());
    let len = |v: &[[f64; 3]], i: usize, j: usize| dot(sub(v[i], v[j]), sub(v[i], v[j])).sqrt();
    let mut sum = 0.0;
    let mut n = 0;
    for t in a.faces() {
        for (i, j) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            sum += (len(vb, i, j) / len(va, i, j) - 1.0).abs();
            n += 1;
        }
    }
    sum / n as f64
}

#[test]
fn the_average_build_at_rest_is_the_template() {
    let body = Body::template();
    let rest = body.rest_mesh(0.08, [0.2, 0.4, 0.6]).unwrap();
    let same = body
        .deform(&rest, &Build::average(), &BodyPose::rest())
        .unwrap();
    for (p, q) in rest.vertices().iter().zip(same.vertices()) {
        assert!(dot(sub(*p, *q), sub(*p, *q)).sqrt() < 1e-12);
    }
    // Every vertex lies on the implicit surface.
    assert!(
        rest.vertices()
            .iter()
            .all(|&p| body.implicit(p).abs() < 1e-9)
    );
}

#[test]
fn shapes_are_closed_connected_genus_zero_and_remeshed_independently() {
    let body = Body::template();
    let a = body
        .shape(&Build::random(1), &BodyPose::walking(), 0.05, 1)
        .unwrap();
    let b = body
        .shape(&Build::random(2), &BodyPose::crouching(), 0.047, 2)
        .unwrap();
    for s in [&a, &b] {
        let r = s.mesh.validate();
        assert!(r.is_closed_manifold() && r.is_clean(), "{r:?}");
        assert_eq!(r.genus, Some(0));
        assert_eq!(r.connected_components, 1);
    }
    assert_ne!(a.mesh.n_vertices(), b.mesh.n_vertices());
}

#[test]
fn poses_are_near_isometric_and_builds_are_not() {
    let body = Body::template();
    let rest = body.rest_mesh(0.06, [0.5; 3]).unwrap();
    let build = Build::random(5);
    let at_rest = body.deform(&rest, &build, &BodyPose::rest()).unwrap();
    let crouch = body.deform(&rest, &build, &BodyPose::crouching()).unwrap();
    // Skinning stretches the skin at bent joints (hips and knees bent
    // by about a radian here): a few percent on average, like the
    // pose changes of FAUST's registrations.
    let iso = mean_relative_edge_change(&at_rest, &crouch);
    assert!(iso < 0.08, "a pose changes edge lengths by {iso}");
    let other = body
        .deform(&rest, &Build::random(6), &BodyPose::rest())
        .unwrap();
    let noniso = mean_relative_edge_change(&at_rest, &other);
    assert!(
        noniso > 2.0 * iso,
        "another build changes edge lengths by {noniso}, a pose by {iso}"
    );
    // And the pose really moves the body: the ankles travel.
    let moved = at_rest
        .vertices()
        .iter()
        .zip(crouch.vertices())
        .filter(|(p, q)| dot(sub(**p, **q), sub(**p, **q)) > 0.01)
        .count();
    assert!(moved > rest.n_vertices() / 5, "{moved} vertices moved");
}

#[test]
fn the_template_is_nearly_but_not_exactly_symmetric() {
    let body = Body::template();
    let rest = body.rest_mesh(0.05, [0.5; 3]).unwrap();
    let off: Vec<f64> = rest
        .vertices()
        .iter()
        .map(|&p| body.implicit(mirrored(p)).abs())
        .collect();
    let max = off.iter().copied().fold(0.0, f64::max);
    // A few millimetres on a body 1.9 units tall: flips stay plausible.
    assert!(max > 0.003 && max < 0.03, "largest mirror mismatch {max}");
}

#[test]
fn skinning_weights_are_a_partition_of_unity() {
    let body = Body::template();
    let rest = body.rest_mesh(0.08, [0.1; 3]).unwrap();
    for &p in rest.vertices() {
        let w = body.weights(p);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!(w.iter().all(|&x| (0.0..=1.0).contains(&x)));
    }
}

#[test]
fn ground_truth_points_land_within_a_grid_cell() {
    let body = Body::template();
    let template = body.rest_mesh(0.06, [0.5; 3]).unwrap();
    let shape = body
        .shape(&Build::random(3), &BodyPose::reaching(), 0.047, 9)
        .unwrap();
    let nearest = nearest_vertices(template.vertices(), &shape.rest);
    for (p, &j) in template.vertices().iter().zip(&nearest) {
        let d = sub(*p, shape.rest[j]);
        // Within a grid cell (1.5 spacings: a coarse grid rounds the
        // tips of tail and hands off a little).
        assert!(
            dot(d, d).sqrt() < 1.5 * 0.047,
            "{p:?} is {} from its vertex",
            dot(d, d).sqrt()
        );
    }
    // Brute force agrees with a direct check on a few points.
    assert_eq!(
        nearest_vertices(&shape.rest[..3], &shape.rest),
        vec![0, 1, 2]
    );
}

/// The tree-bounded search returns what a plain scan returns, ties to the
/// smallest index included: points on a lattice (many equidistant vertices),
/// duplicated vertices, and points far outside the cloud.
#[test]
fn nearest_vertices_equal_a_plain_scan_with_ties() {
    let scan = |points: &[[f64; 3]], vertices: &[[f64; 3]]| -> Vec<usize> {
        points
            .iter()
            .map(|p| {
                let mut best = (f64::INFINITY, 0);
                for (j, v) in vertices.iter().enumerate() {
                    let d = sub(*p, *v);
                    if dot(d, d) < best.0 {
                        best = (dot(d, d), j);
                    }
                }
                best.1
            })
            .collect()
    };
    let mut vertices = Vec::new();
    for i in 0..9 {
        for j in 0..9 {
            for k in 0..9 {
                vertices.push([i as f64 * 0.25, j as f64 * 0.25, k as f64 * 0.25]);
            }
        }
    }
    // Every lattice point twice: the first copy must win.
    vertices.extend(vertices.clone());
    let mut points = Vec::new();
    for i in 0..17 {
        for j in 0..5 {
            // Cell centres and face centres: up to eight equidistant vertices.
            points.push([i as f64 * 0.125, j as f64 * 0.125 + 0.0625, 1.0]);
        }
    }
    points.push([10.0, -3.0, 7.5]);
    points.push([-1e6, 1e6, 0.0]);
    let got = nearest_vertices(&points, &vertices);
    assert_eq!(got, scan(&points, &vertices));
    assert!(got.iter().all(|&j| j < vertices.len() / 2));
    assert_eq!(nearest_vertices(&points[..2], &[]), vec![0, 0]);
}

#[test]
fn a_larger_belly_grows_the_body_without_folding_it() {
    let body = Body::template();
    let rest = body.rest_mesh(0.05, [0.3; 3]).unwrap();
    let mut build = Build::average();
    build.belly = 1.8;
    let big = body.deform(&rest, &build, &BodyPose::rest()).unwrap();
    let (va, vb) = (rest.vertices(), big.vertices());
    let normal = |v: &[[f64; 3]], t: &[usize; 3]| {
        fmaps_mesh_io::vec3::cross(sub(v[t[1]], v[t[0]]), sub(v[t[2]], v[t[0]]))
    };
    // No face turns over: each keeps its orientation.
    for t in rest.faces() {
        assert!(
            dot(normal(va, t), normal(vb, t)) > 0.0,
            "face {t:?} folds: {:?} -> {:?}",
            t.map(|i| va[i]),
            t.map(|i| vb[i])
        );
    }
    // The belly grows (more area), the back and the limbs do not move.
    assert!(
        big.area() > 1.03 * rest.area(),
        "{} {}",
        big.area(),
        rest.area()
    );
    for (p, q) in va.iter().zip(vb) {
        if p[1] < -0.2 || p[1] > 0.8 || p[2] < -0.15 {
            assert!(dot(sub(*p, *q), sub(*p, *q)).sqrt() < 1e-3, "{p:?} moved");
        }
    }
}

#[test]
fn every_species_is_a_clean_closed_surface_far_from_the_others() {
    use species::{SPECIES, species_shape};
    let body = Body::template();
    let shapes: Vec<GeneratedShape> = (0..SPECIES.len())
        .map(|s| species_shape(&body, s, 1, 0.07).unwrap())
        .collect();
    for (s, shape) in SPECIES.iter().zip(&shapes) {
        let r = shape.mesh.validate();
        assert!(r.is_closed_manifold() && r.is_clean(), "{}: {r:?}", s.name);
        assert_eq!(r.genus, Some(0), "{}", s.name);
        assert_eq!(r.connected_components, 1, "{}", s.name);
    }
    // Across species, edges change far more than between two poses of one
    // body (see poses_are_near_isometric_and_builds_are_not).
    let rest = body.rest_mesh(0.07, [0.5; 3]).unwrap();
    let posed: Vec<TriMesh> = SPECIES
        .iter()
        .map(|s| body.deform(&rest, &(s.build)(), &(s.posture)()).unwrap())
        .collect();
    for i in 0..posed.len() {
        for j in i + 1..posed.len() {
            let change = mean_relative_edge_change(&posed[i], &posed[j]);
            assert!(
                change > 0.05,
                "{} {}: {change}",
                SPECIES[i].name,
                SPECIES[j].name
            );
        }
    }
    assert!(species_shape(&body, SPECIES.len(), 0, 0.07).is_err());
    assert!(species_shape(&body, 0, 2, 0.07).is_err());
}
