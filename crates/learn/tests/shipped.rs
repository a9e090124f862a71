//! The model shipped with the crate (`models/faust-unsupervised.npz`):
//! it loads, says how it was made, and gives the features it gave when it
//! was shipped on a generated shape (the creature at rest, 642 vertices).
//! A change to the file, to the operators or to the network's passes
//! that moves the features shows here.

#![cfg(feature = "shipped-model")]

use fmaps_learn::model::{Architecture, Input, Model};

#[test]
fn the_shipped_model_loads_with_its_provenance() {
    let m = Model::shipped().unwrap();
    assert_eq!(
        m.architecture(),
        Architecture {
            inputs: 128,
            width: 128,
            blocks: 4,
            outputs: 256
        }
    );
    assert_eq!(m.preprocessing.input, Input::Wks);
    assert_eq!(m.preprocessing.eigenpairs, 128);
    let p = &m.provenance;
    assert_eq!(p["steps"], "4000");
    for key in [
        "recipe",
        "command",
        "commit",
        "cpu",
        "data",
        "final_losses",
        "shapes",
    ] {
        assert!(p.contains_key(key), "provenance without {key}");
    }
    // Trained on the FAUST training shapes only.
    let shapes: Vec<&str> = p["shapes"].split(' ').collect();
    assert_eq!(shapes.len(), 80);
    assert!(shapes.iter().all(|s| {
        s.strip_prefix("tr_reg_")
            .and_then(|n| n.parse::<u32>().ok())
            .is_some_and(|n| n < 80)
    }));
}

/// Features of vertices 0, 100, 321, 641 (rows), features 0, 17, 100, 255
/// (columns), computed by this crate when the model was shipped.
const STORED: [[f64; 4]; 4] = [
    [
        3.041535806192748e-1,
        -2.7699427339449856e-3,
        8.181864422883571e-1,
        4.1866353572341836e-2,
    ],
    [
        4.4034687947581885e-1,
        1.2392849953383249e-1,
        5.279193987452757e-1,
        4.969697392822948e-1,
    ],
    [
        2.985495888123598e-1,
        4.6616865748724157e-1,
        1.058813674571317e-1,
        2.9231764710043084e-1,
    ],
    [
        3.846388680232057e-1,
        3.7649423740959564e-1,
        -9.845967709489416e-2,
        3.5153580485495724e-2,
    ],
];

#[test]
fn the_shipped_model_reproduces_its_stored_features() {
    let m = Model::shipped().unwrap();
    let mesh = fmaps_shapes::creature_pair(3).source;
    let f = m.features(&mesh).unwrap();
    assert_eq!(f.shape(), (642, 256));
    for (r, &v) in [0usize, 100, 321, 641].iter().enumerate() {
        for (c, &j) in [0usize, 17, 100, 255].iter().enumerate() {
            // The eigensolver's and the kernels' rounding differ between
            // CPUs by far less than this; features are of order 1.
            assert!(
                (f[(v, j)] - STORED[r][c]).abs() < 1e-7,
                "vertex {v} feature {j}: {} stored {}",
                f[(v, j)],
                STORED[r][c]
            );
        }
    }
}
