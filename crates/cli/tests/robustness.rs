//! What a careless or hostile user feeds the CLI: units,
//! typed sizes, outputs that must not clobber anything, inputs too small.

mod common;
use common::{fmaps, json_of, refused, run_in, tmpdir};

/// The built-in pair at `subdivisions`, written as a.off and b.off.
fn write_pair(dir: &std::path::Path, subdivisions: u32) -> fmaps::shapes::MeshPair {
    let pair = fmaps::shapes::creature_pair(subdivisions);
    fmaps::mesh_io::write_mesh(dir.join("a.off"), &pair.source).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("b.off"), &pair.target).unwrap();
    pair
}

/// `fmaps match` gives the same map when the target is in other units
/// (coordinates x1000), and `--json` says the shapes were normalized to
/// unit area and what their areas were.
#[test]
fn match_does_not_depend_on_the_units() {
    let dir = tmpdir("units");
    let pair = write_pair(&dir, 3);
    let big = pair.target.scaled(1000.0).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("b1000.off"), &big).unwrap();
    let run = |target: &str, out: &str| -> serde_json::Value {
        json_of(fmaps().current_dir(&dir).args([
            "match",
            "a.off",
            target,
            "--k",
            "20",
            "--k-process",
            "50",
            "--n-descr",
            "30",
            "--refine",
            "zoomout",
            "--zoomout",
            "20:50:5",
            "--starts",
            "none",
            "--threads",
            "1",
            "--json",
            "--out",
            out,
        ]))
    };
    let (j1, j2) = (run("b.off", "m1.map"), run("b1000.off", "m2.map"));
    let m1 = fmaps::mesh_io::read_map(dir.join("m1.map")).unwrap();
    let m2 = fmaps::mesh_io::read_map(dir.join("m2.map")).unwrap();
    assert_eq!(m1, m2);
    assert_eq!(j2["area_normalized"], true);
    let (a1, a2) = (
        j1["input_areas"]["target"].as_f64().unwrap(),
        j2["input_areas"]["target"].as_f64().unwrap(),
    );
    assert!((a2 / a1 - 1e6).abs() < 1e-6 * 1e6, "{a1} {a2}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Sizes a user can type are bounded by what the input makes sensible,
/// with exit code 2 and a reason, never a panic or a runaway allocation:
/// descriptor samples beyond 4 x the eigenpairs
/// they come from, descriptor matrices beyond 2 GB (landmarks), threads
/// beyond 4 per core; a ZoomOut step that would overflow just ends the
/// schedule.
#[test]
fn typed_sizes_are_bounded() {
    let dir = tmpdir("bounds");
    let pair = write_pair(&dir, 2);
    let n = pair.source.n_vertices();
    // 20000 landmark lines: 1 + 20000 descriptor families.
    let lines: String = (0..20000)
        .map(|i| format!("{} {}\n", i % n + 1, i % n + 1))
        .collect();
    std::fs::write(dir.join("lm.txt"), lines).unwrap();
    let m = [
        "match",
        "a.off",
        "b.off",
        "--k",
        "10",
        "--k-process",
        "20",
        "--threads",
        "1",
    ];
    let run = |extra: &[&str]| run_in(&dir, &m, extra);
    for (extra, needle) in [
        (vec!["--n-descr", "18446744073709551615"], "only repeat"),
        (vec!["--n-descr", "100000"], "only repeat"),
        (vec!["--n-descr", "50", "--landmarks", "lm.txt"], "GB"),
    ] {
        let (code, err) = run(&extra);
        assert_eq!(code, Some(2), "{extra:?}: {err}");
        assert!(
            err.contains(needle) && !err.contains("panicked"),
            "{extra:?}: {err}"
        );
    }
    let (code, err) = run(&["--n-descr", "10", "--zoomout", "10:30:18446744073709551615"]);
    assert_eq!(code, Some(0), "{err}");
    let a = dir.join("a.off");
    let err = refused(["--threads", "100000", "info", a.to_str().unwrap()]);
    assert!(err.contains("per core"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Outputs never overwrite an input or each other, and a command that
/// fails leaves every previous output as it was, with no temporary file
/// behind.
#[test]
fn outputs_are_atomic_and_never_clobber_inputs() {
    let dir = tmpdir("atomic");
    write_pair(&dir, 2);
    let a_before = std::fs::read(dir.join("a.off")).unwrap();
    std::fs::write(dir.join("keep.map"), "old content\n").unwrap();
    let m = [
        "match",
        "a.off",
        "b.off",
        "--k",
        "10",
        "--k-process",
        "20",
        "--n-descr",
        "10",
    ];
    let run = |extra: &[&str]| run_in(&dir, &m, extra);
    let (code, err) = run(&["--out", "a.off"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("overwrite the input"), "{err}");
    let (code, err) = run(&["--out", "x.map", "--save-fmap", "./x.map"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("two outputs"), "{err}");
    // The second output cannot be written (its folder does not exist):
    // refused before any work, the first stays as it was.
    let (code, err) = run(&["--out", "keep.map", "--save-fmap", "no/such/dir/C.txt"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("does not exist"), "{err}");
    assert_eq!(
        std::fs::read_to_string(dir.join("keep.map")).unwrap(),
        "old content\n"
    );
    assert_eq!(std::fs::read(dir.join("a.off")).unwrap(), a_before);
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        ["a.off", "b.off", "keep.map"],
        "temporaries left behind"
    );
    // Both written when both can be.
    let (code, err) = run(&["--out", "keep.map", "--save-fmap", "C.txt"]);
    assert_eq!(code, Some(0), "{err}");
    assert_ne!(
        std::fs::read_to_string(dir.join("keep.map")).unwrap(),
        "old content\n"
    );
    assert!(dir.join("C.txt").exists());
    // geodesic and spectrum refuse to overwrite their input too.
    for args in [
        vec!["geodesic", "a.off", "--source", "0", "--out", "a.off"],
        vec!["spectrum", "a.off", "--k", "5", "--out", "a.off"],
    ] {
        let out = fmaps().current_dir(&dir).args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
    }
    assert_eq!(std::fs::read(dir.join("a.off")).unwrap(), a_before);
    std::fs::remove_dir_all(&dir).ok();
}

/// Meshes too small for the asked eigenpairs are bad input (exit 2, as in
/// `fmaps spectrum`), and the reason is printed once.
#[test]
fn match_on_too_small_meshes_is_bad_input_said_once() {
    let dir = tmpdir("small");
    let m = fmaps::shapes::icosphere(1.0, 0);
    fmaps::mesh_io::write_mesh(dir.join("s.off"), &m).unwrap();
    let out = fmaps()
        .current_dir(&dir)
        .args(["match", "s.off", "s.off", "--k", "3", "--k-process", "20"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert_eq!(
        err.matches("cannot compute 20 eigenpairs").count(),
        1,
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A clean blob matched onto a clean icosphere: the sphere's descriptors
/// are constant, C is undetermined. Exit 1 with the reason and what to
/// try, the old output kept.
#[test]
fn an_undetermined_functional_map_is_refused() {
    use fmaps::shapes::icosphere;
    let dir = tmpdir("undetermined");
    let s = icosphere(1.0, 3);
    let (v, f) = s.clone().into_parts();
    let blob: Vec<[f64; 3]> = v
        .iter()
        .map(|p| {
            let bump = 1.0 + 0.3 * (-4.0 * ((p[0] - 0.6).powi(2) + (p[1] - 0.5).powi(2))).exp();
            [1.3 * p[0] * bump, p[1] * bump, 0.8 * p[2]]
        })
        .collect();
    let blob = fmaps::mesh_io::TriMesh::new(blob, f).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("blob.off"), &blob).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("sphere.off"), &s).unwrap();
    std::fs::write(dir.join("keep.map"), "old\n").unwrap();
    for (a, b) in [("blob.off", "sphere.off"), ("sphere.off", "blob.off")] {
        let out = fmaps()
            .current_dir(&dir)
            .args(["match", a, b, "--k", "10", "--k-process", "20"])
            .args(["--out", "keep.map", "--save-fmap", "C.txt"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{a} -> {b}: {err}");
        assert!(
            err.contains("undetermined") && err.contains("Try landmarks"),
            "{err}"
        );
        assert_eq!(
            std::fs::read_to_string(dir.join("keep.map")).unwrap(),
            "old\n"
        );
        assert!(!dir.join("C.txt").exists());
    }
    std::fs::remove_dir_all(&dir).ok();
}
