//! ZoomOut's and ICP's searches through the ball clusters (no matrix
//! tiles: each image `Φ_A Cᵀ` computed in the clusters' order, the
//! queries checked once) give the same maps as the searches without
//! clusters (ZoomOut one way, bijective and on samples, ICP). The
//! clusters are made only without tiles and with `FMAPS_NO_BALLS` unset,
//! both read from the environment: the test runs
//! this binary's ignored `zoomout_maps` twice as child processes, with
//! `FMAPS_NO_AMX=1` and with `FMAPS_NO_AMX=1 FMAPS_NO_BALLS=1`, and
//! compares the maps they print.

use fmaps_refine::RefineInput;
use fmaps_refine::{Icp, Refiner, Subsample, ZoomOut};
use nalgebra::DMatrix;

mod common;
use common::{basis, bumpy};

/// The maps of this binary's `zoomout_maps` run in a child process with
/// `env` set.
fn child_maps(env: &[(&str, &str)]) -> String {
    let mut cmd = std::process::Command::new(std::env::current_exe().unwrap());
    cmd.args([
        "--exact",
        "zoomout_maps",
        "--ignored",
        "--nocapture",
        "--test-threads",
        "1",
    ]);
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "child failed: {text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // (The harness's "test zoomout_maps ... " may precede the first.)
    text.lines()
        .filter_map(|l| l.find("maps ").map(|at| &l[at..]))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn zoomout_with_and_without_clusters_gives_the_same_maps() {
    let with = child_maps(&[("FMAPS_NO_AMX", "1")]);
    let without = child_maps(&[("FMAPS_NO_AMX", "1"), ("FMAPS_NO_BALLS", "1")]);
    assert!(with.contains("clusters: yes"), "{with}");
    assert!(without.contains("clusters: no"), "{without}");
    assert_eq!(with.lines().count(), 4, "{with}");
    let strip = |s: &str| s.replace("clusters: yes", "").replace("clusters: no", "");
    assert_eq!(strip(&with), strip(&without));
}

/// ZoomOut one way, bijective and on samples, and ICP, on a pair of
/// bumpy tori;
/// prints each
/// map (and the final C's bits) on one line, and whether the searches
/// ran on clusters. Run by the test above in a child process.
#[test]
#[ignore = "run by zoomout_with_and_without_clusters_gives_the_same_maps"]
fn zoomout_maps() {
    let (a, b) = (bumpy(0.08), bumpy(0.12));
    let (basis_a, basis_b) = (basis(&a, 40), basis(&b, 40));
    let rows = DMatrix::from_fn(a.n_vertices(), 40, |i, j| basis_a.eigenvectors[(i, j)]);
    let clusters = fmaps_nearest::Partition::for_balls(
        fmaps_nearest::view(&rows),
        fmaps_nearest::BallsRequest::new(1024),
    )
    .is_some();
    // An initial map with errors (the identity's leading block, bent).
    let c0 = DMatrix::from_fn(10, 10, |i, j| {
        (if i == j { 1.0 } else { 0.0 }) + 0.1 * ((3 * i + j) as f64).sin()
    });
    let runs = [
        ("zoomout", false),
        ("zoomout", true),
        ("zoomout-samples", false),
        ("icp", false),
    ];
    for (name, bijective) in runs {
        let zo = ZoomOut {
            k_start: 10,
            k_final: 40,
            step: 3,
            bijective,
            ..ZoomOut::default()
        };
        let r = if name == "icp" {
            // At k = 40 (its clusters from 33 dimensions), from the first
            // ZoomOut's map.
            let start = zo
                .refine(&RefineInput::new(&c0, &basis_a, &basis_b))
                .unwrap();
            Icp::default()
                .refine(&RefineInput::new(&start.c_ab, &basis_a, &basis_b))
                .unwrap()
        } else if name == "zoomout-samples" {
            // Iterations on 1100 samples per shape (their own clusters),
            // then one on every vertex and the final search (all rows'
            // clusters).
            let sampled = ZoomOut {
                subsample: Some(Subsample::farthest(a.vertices(), b.vertices(), 1100)),
                full_iterations: 1,
                ..zo
            };
            sampled
                .refine(&RefineInput::new(&c0, &basis_a, &basis_b))
                .unwrap()
        } else {
            zo.refine(&RefineInput::new(&c0, &basis_a, &basis_b))
                .unwrap()
        };
        // The iterations did move the map (the comparison is not trivial).
        let moved = r
            .report
            .iterations
            .iter()
            .map(|it| it.changed)
            .sum::<usize>();
        assert!(moved > 20, "{name} bijective: {bijective}: {moved} changes");
        let c_bits: Vec<String> = r
            .c_ab
            .iter()
            .map(|v| format!("{:x}", v.to_bits()))
            .collect();
        println!(
            "maps {name} bijective: {bijective} clusters: {} t_ba: {:?} c_ab: {}",
            if clusters { "yes" } else { "no" },
            r.t_ba,
            c_bits.join(",")
        );
    }
}
