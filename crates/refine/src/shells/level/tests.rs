//! Tests of the alignment levels (`level.rs`).
use super::*;
use faer::Mat;

#[test]
fn shell_weights_are_a_sigmoid_cut_at_k() {
    let w = shell_weights(30);
    assert_eq!(w.len(), 39);
    assert!((w[29] - 0.5).abs() < 1e-12, "1/2 at eigenfunction k");
    assert!((w[38] - 0.01).abs() < 1e-9, "1% at k + 9");
    assert!(w[0] > 0.9999);
    assert!(w.windows(2).all(|p| p[0] > p[1]));
    let w = shell_weights(4);
    assert_eq!(w.len(), 7);
    assert!((w[3] - 0.5).abs() < 1e-12 && (w[6] - 0.01).abs() < 1e-9);
    assert_eq!(shell_weights(1), vec![1.0]);
}

/// Each query's nearest data row by brute force.
fn brute(data: &Mat<f64>, queries: &Mat<f64>) -> Vec<usize> {
    let params = NnParams::with_strategy(fmaps_nearest::NnStrategy::Brute);
    nearest_rows(data.as_ref(), queries.as_ref(), None, &params).unwrap()
}

/// A product embedding of a Fibonacci sphere (`n` evenly spread
/// points, turned by `shift` about the axis): the points, the normals
/// times `normals`, then smooth "spectral" features of amplitude `amp`
/// along `dir`.
fn sphere_embedding(
    n: usize,
    cols: usize,
    shift: f64,
    normals: f64,
    amp: f64,
    dir: [f64; 3],
) -> Mat<f64> {
    Mat::from_fn(n, cols, |i, c| {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let t = i as f64 * 2.399_963_229_728_653 + shift;
        let r = (1.0 - z * z).sqrt();
        let p = [r * t.cos(), r * t.sin(), z];
        match c {
            0..3 => p[c],
            3..6 => normals * p[c - 3],
            _ => {
                let along = dir[0] * p[0] + dir[1] * p[1] + dir[2] * p[2];
                amp * ((c - 5) as f64 * along + shift).sin()
            }
        }
    })
}

/// The final point map's search on many rows (the ball search where
/// it pays) answers as brute force does: rows of a product embedding
/// of a sphere (points, normals, smooth "spectral" features), queries
/// from a perturbed copy.
#[test]
fn the_search_on_every_vertex_agrees_with_brute_force() {
    let n = BALLS_FROM_ROWS + 904;
    let embed = |shift| sphere_embedding(n, 3 + 3 + 20, shift, 0.3, 0.2, [1.0, 0.5, 0.0]);
    let (data, queries) = (embed(0.0), embed(0.013));
    let want = brute(&data, &queries);
    // k-means clusters of the rows, and cells of farthest points on
    // the surface (as `Samples::all` makes them).
    let points: Vec<[f64; 3]> = (0..n)
        .map(|i| [data[(i, 0)], data[(i, 1)], data[(i, 2)]])
        .collect();
    let cells = super::super::posed::surface_cells(&points, crate::search_cells(n));
    for cells in [None, Some(cells.as_slice())] {
        let params = search_params(data.as_ref(), cells, false);
        if params.strategy != fmaps_nearest::NnStrategy::Balls {
            eprintln!(
                "skipped (cells: {}): the ball search is not chosen on this CPU (matrix tiles, \
                 k-means clusters below PartitionParams::tiled_from_rows rows) or with FMAPS_NO_BALLS; \
                 brute force alone was compared with itself",
                cells.is_some()
            );
        }
        let got = nearest_rows(data.as_ref(), queries.as_ref(), None, &params).unwrap();
        assert_eq!(got, want, "cells: {}", cells.is_some());
    }
}

/// The search among samples with guesses (the alignment levels): the
/// ball search over the samples' cells from
/// [`HINTED_BALLS_FROM_COLS`] columns, brute force below and without
/// guesses; every choice answers as brute force does, whatever the
/// guesses (right, wrong or out of range).
#[test]
fn the_search_among_samples_with_guesses_agrees_with_brute_force() {
    let n = 2000;
    let embed = |cols, shift| sphere_embedding(n, cols, shift, 0.04, 0.1, [1.0, 0.5, -0.3]);
    let e = embed(3, 0.0);
    let points: Vec<[f64; 3]> = (0..n).map(|i| [e[(i, 0)], e[(i, 1)], e[(i, 2)]]).collect();
    let cells = super::super::posed::surface_cells(
        &points,
        n.div_ceil(fmaps_nearest::PartitionParams::default().ball_size),
    );
    for cols in [HINTED_BALLS_FROM_COLS - 1, HINTED_BALLS_FROM_COLS, 197] {
        let (data, queries) = (embed(cols, 0.0), embed(cols, 0.011));
        let want = brute(&data, &queries);
        // A third right, a third another row, a third out of range.
        let hints: Vec<usize> = (0..n)
            .map(|i| match i % 3 {
                0 => want[i],
                1 => (want[i] + 17 * i) % n,
                _ => n + i,
            })
            .collect();
        for hinted in [false, true] {
            let params = search_params(data.as_ref(), Some(&cells), hinted);
            let balls = params.strategy == fmaps_nearest::NnStrategy::Balls;
            let expected = hinted && cols >= HINTED_BALLS_FROM_COLS;
            if expected && !balls {
                eprintln!(
                    "skipped: the ball search is not chosen on this CPU (matrix tiles) or \
                     with FMAPS_NO_BALLS; brute force alone was compared with itself"
                );
            } else {
                assert_eq!(balls, expected, "{cols} columns, guesses: {hinted}");
            }
            let hint = hinted.then_some(hints.as_slice());
            let got = nearest_rows(data.as_ref(), queries.as_ref(), hint, &params).unwrap();
            assert_eq!(got, want, "{cols} columns, guesses: {hinted}");
        }
    }
}
