//! The training loop's tests: finite differences of a whole pair step,
//! determinism and exact resume, augmentation, coordinate inputs,
//! non-finite losses.

use super::*;
use crate::model::{Architecture, Preprocessing};

fn tiny() -> (Model, Recipe) {
    let arch = Architecture {
        inputs: 6,
        width: 6,
        blocks: 1,
        outputs: 5,
    };
    let pre = Preprocessing {
        eigenpairs: 8,
        ..Preprocessing::default()
    };
    let recipe = Recipe {
        steps: 4,
        fmap_eigenpairs: 6,
        coupling_samples: Some(30),
        ..Recipe::default()
    };
    (Model::new(arch, pre, 3), recipe)
}

/// A sphere, twice its size, and an ellipsoid: the shapes of [`shapes`].
fn meshes() -> [TriMesh; 3] {
    let a = fmaps_shapes::icosphere(1.0, 2);
    let b = a.scaled(2.0).unwrap();
    let v: Vec<[f64; 3]> = a
        .vertices()
        .iter()
        .map(|p| [p[0] * 1.3, p[1], p[2] * 0.8])
        .collect();
    let c = TriMesh::new(v, a.faces().to_vec()).unwrap();
    [a, b, c]
}

fn shapes(model: &Model, recipe: &Recipe) -> Vec<TrainShape> {
    ["a", "b", "c"]
        .iter()
        .zip(meshes().iter())
        .map(|(n, m)| TrainShape::new(n, m, model, recipe).unwrap())
        .collect()
}

/// The pair loss's gradient against a central difference of the
/// whole loss (network, layer, every term) along a random direction
/// of all parameters, with the same masks and samples.
#[test]
fn pair_gradient_matches_finite_differences() {
    pair_gradient_check(0.0);
}

/// The same with the Dirichlet term of the soft maps (on sampled centres
/// and targets).
#[test]
fn pair_gradient_with_dirichlet_matches_finite_differences() {
    pair_gradient_check(0.5);
}

/// A pair step with the Dirichlet term needs the shapes' geometry, and
/// records the weighted term in the total.
#[test]
fn dirichlet_needs_the_geometry() {
    let (model, mut recipe) = tiny();
    recipe.weights.dirichlet = 2.0;
    let s = shapes(&model, &recipe);
    let e = pair_loss(&model, &recipe, &s[0], &s[2], &mut SplitMix(1), false).unwrap_err();
    assert!(e.to_string().contains("geometry of a and c"), "{e}");
    let sphere = fmaps_shapes::icosphere(1.0, 2);
    let other = TriMesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 2]]).unwrap();
    let e = s[0].clone().with_geometry(&other).unwrap_err();
    assert!(e.to_string().contains("3 vertices"), "{e}");
    let a = s[0].clone().with_geometry(&sphere).unwrap();
    let (v, _) = pair_loss(&model, &recipe, &a, &a, &mut SplitMix(1), false).unwrap();
    assert!(v.dirichlet > 0.0);
    let sum = v.bijectivity + v.orthogonality + v.laplacian + v.coupling + v.dirichlet;
    assert!((v.total - sum).abs() <= 1e-12 * sum);
}

fn pair_gradient_check(dirichlet: f64) {
    let (model, mut recipe) = tiny();
    recipe.weights.laplacian = 0.01;
    recipe.weights.dirichlet = dirichlet;
    recipe.dirichlet_centres = Some(40);
    let mut s = shapes(&model, &recipe);
    if dirichlet != 0.0 {
        let [a, _, c] = meshes();
        s[0] = s[0].clone().with_geometry(&a).unwrap();
        s[2] = s[2].clone().with_geometry(&c).unwrap();
    }
    let mut dir_rng = SplitMix(17);
    let mut dir = model.clone();
    for p in dir.net.params_mut() {
        p.iter_mut().for_each(|v| *v = dir_rng.symmetric());
    }
    // Diffusion times at 0 sit on the clamp's kink: move them inside.
    let mut base = model.clone();
    for b in &mut base.net.blocks {
        b.diffusion.times.fill(0.01);
    }
    let (_, grad) = pair_loss(&base, &recipe, &s[0], &s[2], &mut SplitMix(9), true).unwrap();
    let mut shifted = |h: f64| {
        let mut m = base.clone();
        for (p, d) in m.net.params_mut().into_iter().zip(dir.net.params_mut()) {
            for (a, b) in p.iter_mut().zip(d.iter()) {
                *a += h * b;
            }
        }
        pair_loss(&m, &recipe, &s[0], &s[2], &mut SplitMix(9), true)
            .unwrap()
            .0
            .total
    };
    // ReLU kinks: a step of 1e-6 along a random direction of every
    // parameter crosses some on this shape (the difference then
    // errs by 1e-3); 1e-7 stays on one side of them.
    let h = 1e-7;
    let numeric = (shifted(h) - shifted(-h)) / (2.0 * h);
    let mut g = grad.clone();
    let analytic: f64 = g
        .groups_mut()
        .into_iter()
        .zip(dir.net.params_mut())
        .map(|(a, b)| a.iter().zip(b.iter()).map(|(x, y)| x * y).sum::<f64>())
        .sum();
    assert!(
        (analytic - numeric).abs() < 1e-6 * analytic.abs().max(1e-3),
        "analytic {analytic}, finite difference {numeric}"
    );
}

/// Augmentation rotates and scales: the Gram matrix of the points is
/// the original's times s², with s in the range; `Y` keeps the y
/// coordinates up to the scale.
#[test]
fn augmentation_is_a_similarity() {
    let x = crate::testing::random(9, 3, 41);
    let mut rng = SplitMix(5);
    for rotation in [Rotation::Any, Rotation::Y, Rotation::None] {
        let a = Augment {
            rotation,
            scale: [0.9, 1.1],
        };
        for _ in 0..20 {
            let y = a.apply(&x, &mut rng);
            let (gx, gy) = (&x * x.transpose(), &y * y.transpose());
            let s2 = gy[(0, 0)] / gx[(0, 0)];
            assert!((0.81..=1.21).contains(&s2), "{s2}");
            assert!((gy - gx * s2).abs().max() < 1e-12);
            if rotation == Rotation::Y {
                let s = s2.sqrt();
                assert!((y.column(1) - x.column(1) * s).abs().max() < 1e-12);
            }
        }
    }
}

/// A coordinate-input network trains (finite losses, a different
/// model) and its file says so.
#[test]
fn coordinate_inputs_train() {
    let arch = Architecture {
        inputs: 3,
        width: 6,
        blocks: 1,
        outputs: 8,
    };
    let pre = Preprocessing {
        input: Input::Xyz,
        eigenpairs: 8,
        ..Preprocessing::default()
    };
    let mut recipe = tiny().1;
    recipe.steps = 2;
    let model = Model::new(arch, pre, 3);
    let s = shapes(&model, &recipe);
    let names: Vec<String> = s.iter().map(|x| x.name.clone()).collect();
    let mut t = Trainer::new(model.clone(), recipe, names).unwrap();
    while !t.finished() {
        assert!(t.step(&s).unwrap().losses.total.is_finite());
    }
    assert_ne!(t.model, model);
    let meta = serde_json::to_string(&t.model.meta()).unwrap();
    assert!(meta.contains("\"input\":\"xyz\""), "{meta}");
}

/// A step whose loss is not finite is an error naming the step and
/// the pair, and leaves the model and the step count as they were.
#[test]
fn non_finite_losses_change_nothing() {
    let (model, recipe) = tiny();
    let mut s = shapes(&model, &recipe);
    let names: Vec<String> = s.iter().map(|x| x.name.clone()).collect();
    for sh in &mut s {
        sh.input[(3, 2)] = f64::NAN;
    }
    let mut t = Trainer::new(model.clone(), recipe, names).unwrap();
    let e = t.step(&s).unwrap_err();
    assert!(matches!(e, Error::NonFinite { step: 1, .. }), "{e}");
    assert!(e.to_string().contains("pair"), "{e}");
    assert_eq!(t.model, model);
    assert_eq!(t.step, 0);
}

/// The same seed gives the same run; a run saved after two steps and
/// resumed gives the model of a run never stopped, bit for bit.
#[test]
fn deterministic_and_resumes_exactly() {
    let (model, recipe) = tiny();
    let s = shapes(&model, &recipe);
    let names: Vec<String> = s.iter().map(|x| x.name.clone()).collect();
    let run = |stop: Option<u64>| {
        let mut t = Trainer::new(model.clone(), recipe.clone(), names.clone()).unwrap();
        while !t.finished() {
            t.step(&s).unwrap();
            if Some(t.step) == stop {
                let dir = std::env::temp_dir().join(format!("fmaps-ckpt-{}", std::process::id()));
                std::fs::create_dir_all(&dir).unwrap();
                let path = dir.join("run.npz");
                t.save(&path).unwrap();
                t = Trainer::load(&path).unwrap();
                std::fs::remove_dir_all(&dir).unwrap();
            }
        }
        t
    };
    let (a, b, c) = (run(None), run(None), run(Some(2)));
    assert_eq!(a.model, b.model);
    assert_eq!(a.model, c.model);
    assert_eq!(a.history, c.history);
    assert_ne!(a.model, model, "training changed nothing");
    // The schedule: lr at the first step, lr_min at the last.
    assert_eq!(a.history[0].lr, recipe.lr);
    assert!((a.history[3].lr - recipe.lr_min).abs() < 1e-15);
}
