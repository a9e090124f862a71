//! A small network trained on one generated pair with known ground truth
//! (the creature at rest and walking, renumbered): the unsupervised losses
//! fall, and the map of nearest learned features beats the untrained
//! network's on that pair. Test-time adaptation, the same losses on the
//! pair to be matched, does the same on a copy of the model.

use fmaps_learn::adapt::{Adaptation, adapt};
use fmaps_learn::model::{Architecture, Model, Preprocessing};
use fmaps_learn::train::{Recipe, TrainShape, Trainer};
use nalgebra::DMatrix;

fn normalized(f: &DMatrix<f64>) -> DMatrix<f64> {
    let mut g = f.clone();
    for mut r in g.row_iter_mut() {
        let n = r.norm().max(1e-12);
        r /= n;
    }
    g
}

/// Mean distance on the target, over √area, between the vertex of most
/// similar features and the true vertex.
fn map_error(model: &Model, pair: &fmaps_shapes::MeshPair) -> f64 {
    let fa = normalized(&model.features(&pair.source).unwrap());
    let fb = normalized(&model.features(&pair.target).unwrap());
    let sim = &fa * fb.transpose();
    let vb = pair.target.vertices();
    let total: f64 = (0..sim.nrows())
        .map(|i| {
            let j = sim.row(i).transpose().argmax().0;
            let (p, q) = (vb[j], vb[pair.truth[i]]);
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .sum();
    total / sim.nrows() as f64 / pair.target.area().sqrt()
}

#[test]
fn training_on_one_pair_fits_it() {
    let pair = fmaps_shapes::creature_pair(3);
    let arch = Architecture {
        inputs: 16,
        width: 16,
        blocks: 2,
        outputs: 48,
    };
    let pre = Preprocessing {
        eigenpairs: 30,
        ..Preprocessing::default()
    };
    // More features than eigenpairs (as 256 and 200 in the reference
    // recipe: the layer's least squares is determined); no dropout (half
    // the units of a width-16 network dropped at every step leaves it
    // nothing stable to fit).
    let mut recipe = Recipe::default();
    recipe.steps = 400;
    recipe.fmap_eigenpairs = 20;
    recipe.coupling_samples = Some(300);
    recipe.lr = 5e-3;
    recipe.lr_min = 5e-4;
    recipe.dropout = false;
    let model = Model::new(arch, pre, 5);
    let shapes: Vec<TrainShape> = [("rest", &pair.source), ("walking", &pair.target)]
        .iter()
        .map(|(n, m)| TrainShape::new(n, m, &model, &recipe).unwrap())
        .collect();
    let before = map_error(&model, &pair);
    let mut t = Trainer::new(model, recipe, vec!["rest".into(), "walking".into()]).unwrap();
    while !t.finished() {
        t.step(&shapes).unwrap();
    }
    let mean = |r: &[fmaps_learn::train::StepRecord]| {
        r.iter().map(|s| s.losses.total).sum::<f64>() / r.len() as f64
    };
    let (first, last) = (
        mean(&t.history[..10]),
        mean(&t.history[t.history.len() - 10..]),
    );
    let after = map_error(&t.model, &pair);
    eprintln!("loss {first:.3} -> {last:.3}; map error {before:.4} -> {after:.4}");
    // Measured: loss 63 -> 8, error 0.21 -> 0.025 (an untrained network's
    // map is near random on this creature); over six seeds of weights and
    // draws at most 14 and 0.073, so the bounds hold whatever the
    // rounding of the CPU's kernels.
    assert!(last < 0.5 * first, "loss {first} -> {last}");
    assert!(after < 0.5 * before, "map error {before} -> {after}");
}

#[test]
fn adaptation_fits_the_pair_on_a_copy() {
    let pair = fmaps_shapes::creature_pair(3);
    let arch = Architecture {
        inputs: 16,
        width: 16,
        blocks: 2,
        outputs: 48,
    };
    let pre = Preprocessing {
        eigenpairs: 30,
        ..Preprocessing::default()
    };
    let model = Model::new(arch, pre, 5);
    let mut adaptation = Adaptation::default();
    adaptation.steps = 250;
    adaptation.lr = 3e-3;
    adaptation.recipe.fmap_eigenpairs = 20;
    adaptation.recipe.coupling_samples = Some(300);
    let x = TrainShape::new("rest", &pair.source, &model, &adaptation.recipe).unwrap();
    let y = TrainShape::new("walking", &pair.target, &model, &adaptation.recipe).unwrap();
    let before = map_error(&model, &pair);
    let kept: Vec<Vec<f64>> = model
        .net
        .params()
        .iter()
        .map(|p| p.values.to_vec())
        .collect();
    let adapted = adapt(&model, &x, &y, &adaptation).unwrap();
    let unchanged: Vec<Vec<f64>> = model
        .net
        .params()
        .iter()
        .map(|p| p.values.to_vec())
        .collect();
    assert_eq!(kept, unchanged, "the model given is not changed");
    let l = &adapted.losses;
    assert_eq!(l.len(), 250);
    let mean = |r: &[fmaps_learn::train::LossValues]| {
        r.iter().map(|v| v.total).sum::<f64>() / r.len() as f64
    };
    let (first, last) = (mean(&l[..10]), mean(&l[l.len() - 10..]));
    let after = map_error(&adapted.model, &pair);
    eprintln!("adaptation: loss {first:.3} -> {last:.3}; map error {before:.4} -> {after:.4}");
    // The same losses as training without dropout at a constant rate:
    // the bounds of the training test above.
    assert!(last < 0.5 * first, "loss {first} -> {last}");
    assert!(after < 0.5 * before, "map error {before} -> {after}");
}
