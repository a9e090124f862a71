//! The `fmaps` binary: output, files, exit codes.

use std::path::PathBuf;

mod common;
use common::{fmaps, grid_fixture, json_of, refused, tmpdir};

#[test]
fn spectrum_of_the_builtin_sphere() {
    let v = json_of(fmaps().args(["spectrum", "--builtin", "sphere", "--k", "9", "--json"]));
    let ev: Vec<f64> = serde_json::from_value(v["eigenvalues"].clone()).unwrap();
    assert_eq!(ev.len(), 9);
    assert!(ev[0].abs() < 1e-9);
    assert!(ev[1..4].iter().all(|x| (x - 2.0).abs() < 1e-3));
    assert!(ev[4..9].iter().all(|x| (x - 6.0).abs() < 1e-2));
    assert!(v["max_residual"].as_f64().unwrap() < 1e-6);
    assert!(v["orthonormality_error"].as_f64().unwrap() < 1e-10);
    assert_eq!(v["backend"], "native");
    // The text report shows the closed form next to each eigenvalue.
    let text = fmaps()
        .args(["spectrum", "--builtin", "sphere", "--k", "4"])
        .output()
        .unwrap();
    let s = String::from_utf8(text.stdout).unwrap();
    assert!(
        s.contains("exact l(l+1)") && s.contains("10242 vertices"),
        "{s}"
    );
}

#[test]
fn spectrum_writes_npy_files() {
    let dir = tmpdir("npy");
    let mesh = dir.join("torus.off");
    fmaps::mesh_io::write_mesh(&mesh, &fmaps::shapes::torus(2.0, 0.5, 20, 10)).unwrap();
    let out = dir.join("basis.npy");
    let st = fmaps()
        .args([
            "spectrum",
            mesh.to_str().unwrap(),
            "--k",
            "12",
            "--out",
            out.to_str().unwrap(),
        ])
        .status()
        .unwrap();
    assert!(st.success());
    let header_len = |p: PathBuf| {
        let b = std::fs::read(&p).unwrap();
        assert_eq!(&b[..6], b"\x93NUMPY", "{}", p.display());
        let h = u16::from_le_bytes([b[8], b[9]]) as usize;
        (
            String::from_utf8(b[10..10 + h].to_vec()).unwrap(),
            b.len() - 10 - h,
        )
    };
    // The shapes as NumPy reads them, and exactly their data after the header.
    let shape = |p: PathBuf| {
        fmaps::mesh_io::npy::parse_f64(&std::fs::read(p).unwrap())
            .unwrap()
            .shape
    };
    let (h, bytes) = header_len(out.clone());
    assert!(h.contains("'<f8'") && bytes == 200 * 12 * 8, "{h}");
    assert_eq!(shape(out.clone()), [200, 12]);
    let (_, bytes) = header_len(dir.join("basis_eigenvalues.npy"));
    assert_eq!(
        (shape(dir.join("basis_eigenvalues.npy")), bytes),
        (vec![12], 12 * 8)
    );
    let (_, bytes) = header_len(dir.join("basis_mass.npy"));
    assert_eq!(
        (shape(dir.join("basis_mass.npy")), bytes),
        (vec![200], 200 * 8)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn info_reports_json_and_text() {
    let dir = tmpdir("info");
    let mesh = dir.join("grid.ply");
    fmaps::mesh_io::write_mesh(&mesh, &fmaps::shapes::grid(1.0, 1.0, 3, 3)).unwrap();
    let out = fmaps()
        .args(["info", mesh.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["n_vertices"], 16);
    assert_eq!(v["boundary_loops"], 1);
    assert_eq!(v["genus"], 0);
    assert_eq!(v["is_clean"], true);
    let text = fmaps()
        .args(["info", mesh.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        String::from_utf8(text.stdout)
            .unwrap()
            .contains("boundary loops 1")
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_input_exits_with_2_and_a_clear_message() {
    let dir = tmpdir("bad");
    let bad = dir.join("bad.off");
    std::fs::write(&bad, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n").unwrap();
    for args in [
        vec!["info", bad.to_str().unwrap()],
        vec!["spectrum", bad.to_str().unwrap(), "--k", "2"],
    ] {
        let out = fmaps().args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2));
        let err = String::from_utf8(out.stderr).unwrap();
        assert!(err.contains("bad.off") && err.contains("line 6"), "{err}");
    }
    let err = refused(["spectrum", "--builtin", "torus", "--k", "999999"]);
    assert!(err.contains("need 1 <= k < n"), "{err}");
    let out = fmaps().args(["spectrum"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2), "usage errors exit with 2");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn geodesic_distances_on_a_flat_grid() {
    let dir = tmpdir("geo");
    let mesh = dir.join("grid.off");
    fmaps::mesh_io::write_mesh(&mesh, &fmaps::shapes::grid(3.0, 2.0, 6, 4)).unwrap();
    // `fmaps geodesic --method METHOD --json --out FILE`: the method named
    // in the JSON, and the distances in the file.
    let run = |method: &str| -> (String, Vec<f64>) {
        let out = dir.join(format!("{method}.txt"));
        let st = fmaps()
            .args(["geodesic", mesh.to_str().unwrap(), "--source", "0"])
            .args(["--method", method, "--json", "--out", out.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(
            st.status.success(),
            "{}",
            String::from_utf8_lossy(&st.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&st.stdout).unwrap();
        let d = std::fs::read_to_string(&out)
            .unwrap()
            .lines()
            .map(|l| l.parse().unwrap())
            .collect();
        (v["method"].as_str().unwrap_or("").to_string(), d)
    };
    let (name, d) = run("exact");
    assert_eq!(name, "exact");
    assert_eq!(d.len(), 35);
    // The far corner (3, 2) is at Euclidean distance sqrt(13).
    assert!((d[34] - 13f64.sqrt()).abs() < 1e-12);
    // The reference scheme gives the same distances.
    let (name, d2) = run("exact-ordered");
    assert_eq!(name, "exact-ordered");
    for (a, b) in d.iter().zip(&d2) {
        assert!((a - b).abs() <= 1e-12 * (1.0 + a));
    }
    let err = refused(["geodesic", mesh.to_str().unwrap(), "--source", "99"]);
    assert!(err.contains("vertex 99 is out of range"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn eval_of_an_identity_and_a_shifted_map() {
    let dir = tmpdir("eval");
    let (_, all) = grid_fixture(&dir);
    let run = |map: &str| -> serde_json::Value {
        let p = |f: &str| dir.join(f).to_str().unwrap().to_string();
        let out = fmaps()
            .args([
                "eval",
                "--source",
                &p("g.off"),
                "--target",
                &p("g.off"),
                "--map",
                &p(map),
            ])
            .args([
                "--gt-source",
                &p("g.vts"),
                "--gt-target",
                &p("g.vts"),
                "--json",
            ])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let id = run("id.map");
    assert_eq!(id["mean_error"], 0.0);
    assert_eq!(id["auc"], 1.0);
    assert_eq!(id["coverage"], 1.0);
    assert_eq!(id["geodesic"], "exact");
    let sh = run("shift.map");
    assert!((sh["mean_error"].as_f64().unwrap() - 0.2).abs() < 1e-12);
    assert!((sh["coverage"].as_f64().unwrap() - 0.8).abs() < 1e-12);
    // A map with the wrong number of lines is an input error (exit 2).
    fmaps::mesh_io::write_map(dir.join("short.map"), &all[..3]).unwrap();
    let p = |f: &str| dir.join(f).to_str().unwrap().to_string();
    let eval = |map: &str, gt: &str| {
        refused([
            "eval",
            "--source",
            &p("g.off"),
            "--target",
            &p("g.off"),
            "--map",
            &p(map),
            "--gt-source",
            &p(gt),
            "--gt-target",
            &p(gt),
        ])
    };
    assert!(eval("short.map", "g.vts").contains("3 lines"));
    // Empty ground truth: nothing to measure, an input error (was a
    // perfect score, exit 0).
    std::fs::write(dir.join("empty.vts"), "").unwrap();
    assert!(eval("id.map", "empty.vts").contains("ground truth is empty"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn match_writes_a_one_based_map_and_reports_stages() {
    let dir = tmpdir("match");
    // The built-in creature matched to itself: every map entry is a valid
    // 1-based index. (A rotationally symmetric torus would be refused: its
    // descriptors leave C undetermined.)
    let m = fmaps::shapes::creature_pair(3).source;
    let mesh = dir.join("t.off");
    fmaps::mesh_io::write_mesh(&mesh, &m).unwrap();
    let map = dir.join("t_t.map");
    let fmap = dir.join("C.txt");
    let s = |p: &PathBuf| p.to_str().unwrap().to_string();
    let v = json_of(
        fmaps()
            .args(["match", &s(&mesh), &s(&mesh), "--out", &s(&map)])
            .args(["--k", "12", "--k-process", "30", "--n-descr", "30"])
            .args(["--refine", "none"])
            .args(["--save-fmap", &s(&fmap), "--json"]),
    );
    for stage in [
        "spectra",
        "descriptors",
        "operators",
        "solve",
        "point_map",
        "total",
    ] {
        assert!(v["seconds"][stage].as_f64().unwrap() >= 0.0, "{stage}");
    }
    // The stages are parts of the total.
    let parts: f64 = ["spectra", "descriptors", "operators", "solve", "point_map"]
        .iter()
        .map(|s| v["seconds"][s].as_f64().unwrap())
        .sum();
    let total = v["seconds"]["total"].as_f64().unwrap();
    assert!(
        total > 0.0 && parts <= total * 1.001 + 1e-6,
        "{parts} > {total}"
    );
    assert!((0.0..=1.0).contains(&v["sparsity"].as_f64().unwrap()));
    let t = fmaps::mesh_io::read_map(&map).unwrap();
    assert_eq!(t.len(), m.n_vertices());
    // A shape matched to itself: the identity almost everywhere (the
    // 12 x 12 map's nearest neighbours may swap a few close vertices).
    let fixed = t.iter().enumerate().filter(|&(i, &x)| i == x).count();
    assert!(
        fixed as f64 >= 0.95 * m.n_vertices() as f64,
        "{fixed} of {} vertices map to themselves",
        m.n_vertices()
    );
    let text = std::fs::read_to_string(&fmap).unwrap();
    assert_eq!(text.lines().count(), 12);
    assert!(text.lines().all(|l| l.split_whitespace().count() == 12));

    // Bad landmark file: exit code 2 naming the file and line.
    let lm = dir.join("lm.txt");
    std::fs::write(&lm, "1 2\n0 5\n").unwrap();
    let out = fmaps()
        .args(["match", &s(&mesh), &s(&mesh), "--landmarks", &s(&lm)])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("lm.txt: line 2"), "{err}");
    // Refinement: ZoomOut to 20 reports its iterations; a malformed
    // schedule is bad usage.
    let v = json_of(
        fmaps()
            .args(["match", &s(&mesh), &s(&mesh), "--json"])
            .args(["--k", "12", "--k-process", "20", "--n-descr", "30"])
            .args(["--zoomout", "8:20:4", "--starts", "none"]),
    );
    assert_eq!(v["refine"]["method"], "zoomout 8:20:4");
    assert_eq!(v["refine"]["iterations"], 3);
    assert_eq!(v["refine"]["final_k"], 20);
    // The map of a shape to itself keeps its orientation, and distances:
    // it is trusted, with no advice.
    assert!(v["orientation"].as_f64().unwrap() > 0.9, "{v}");
    assert_eq!(v["starts"].as_array().unwrap().len(), 0);
    let c = &v["confidence"];
    assert!(c["metric_distortion"].as_f64().unwrap() < 0.1, "{v}");
    assert_eq!(c["likely_wrong"], false);
    assert!(c["advice"].is_null(), "{v}");
    // ZoomOut runs multi-start by default (sizes 8 and 20 besides k, those
    // within the computed basis: here both).
    let v = json_of(
        fmaps()
            .args(["match", &s(&mesh), &s(&mesh), "--json"])
            .args(["--k", "12", "--k-process", "20", "--n-descr", "30"])
            .args(["--zoomout", "8:20:4"]),
    );
    let ks: Vec<u64> = v["starts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["k"].as_u64().unwrap())
        .collect();
    assert_eq!(ks, [12, 8, 20]);
    // Each start reports its scores; the kept one has the lowest area
    // distortion (the default --select).
    let starts = v["starts"].as_array().unwrap();
    let area = |s: &serde_json::Value| s["quality"]["area_distortion"].as_f64().unwrap();
    let kept = starts.iter().find(|s| s["chosen"] == true).unwrap();
    assert!(starts.iter().all(|s| area(kept) <= area(s)), "{v}");
    // Multi-start: one entry per distinct size, exactly one kept.
    let out = fmaps()
        .args(["match", &s(&mesh), &s(&mesh), "--json"])
        .args(["--k", "12", "--k-process", "20", "--n-descr", "30"])
        .args(["--zoomout", "8:20:4", "--starts", "6,10"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let starts = v["starts"].as_array().unwrap();
    let ks: Vec<u64> = starts.iter().map(|s| s["k"].as_u64().unwrap()).collect();
    assert_eq!(ks, [12, 6, 10]);
    let kept = starts.iter().filter(|s| s["chosen"] == true).count();
    assert_eq!(kept, 1, "{v}");
    // By default the starts stop at the middle of the schedule (14) and
    // the kept one goes on; `--select-at none` runs every start to 20.
    let method = |v: &serde_json::Value| v["refine"]["method"].as_str().unwrap().to_string();
    assert!(
        method(&v).contains("zoomout 8:14:4, kept start continued zoomout 14:20:4"),
        "{v}"
    );
    let out = fmaps()
        .args(["match", &s(&mesh), &s(&mesh), "--json"])
        .args(["--k", "12", "--k-process", "20", "--n-descr", "30"])
        .args([
            "--zoomout",
            "8:20:4",
            "--starts",
            "6,10",
            "--select-at",
            "none",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(method(&v), "zoomout 8:20:4", "{v}");
    for bad in ["0", "x", "1.5"] {
        let err = refused(["match", &s(&mesh), &s(&mesh), "--select-at", bad]);
        assert!(err.contains(&format!("--select-at '{bad}'")), "{err}");
    }
    let err = refused(["match", &s(&mesh), &s(&mesh), "--starts", "6,x"]);
    assert!(err.contains("--starts '6,x'"), "{err}");
    let err = refused(["match", &s(&mesh), &s(&mesh), "--restart-below", "0.5"]);
    assert!(err.contains("--restart-below"), "{err}");
    for bad in ["8:20", "0:20:1", "30:20:1", "8:20:x", "20:40:5"] {
        let out = fmaps()
            .args(["match", &s(&mesh), &s(&mesh), "--k", "12", "--zoomout", bad])
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "--zoomout {bad}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("--zoomout"), "{err}");
    }
    // k larger than the basis asked for: bad usage, exit 2. (Without
    // --k-process the basis grows to k.)
    let out = fmaps()
        .args([
            "match",
            &s(&mesh),
            &s(&mesh),
            "--k",
            "300",
            "--k-process",
            "200",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("k_process"), "{err}");
    // k beyond the mesh's vertices: the eigenbasis cannot hold it, exit 2.
    let n = m.n_vertices().to_string();
    let out = fmaps()
        .args(["match", &s(&mesh), &s(&mesh), "--refine", "none", "--k", &n])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
}

#[test]
fn demo_matches_the_builtin_pair_and_writes_pictures() {
    let dir = tmpdir("demo");
    let v = json_of(
        fmaps()
            .args(["demo", "--subdivisions", "3", "--json", "--out"])
            .arg(&dir),
    );
    assert_eq!(v["n_vertices"], 642);
    assert_eq!(v["geodesic"], "exact");
    // The default pipeline improves the initial map of this near-isometric
    // pair, and the result is accurate (errors are fractions of sqrt(area)).
    let (init, fin) = (
        v["mean_error_init"].as_f64().unwrap(),
        v["mean_error"].as_f64().unwrap(),
    );
    assert!(fin < init && fin < 0.02, "{init} -> {fin}");
    assert!(v["orientation"].as_f64().unwrap() > 0.8);
    // The non-isometric pair (two bodies of different builds): the
    // descriptor map is near random there (measured 0.35; random maps
    // score ~0.6); the default repairs it to well under 0.12, a third of
    // the descriptor map's error (measured 0.030).
    let noniso = &v["pairs"][1];
    let (init, fin) = (
        noniso["mean_error_init"].as_f64().unwrap(),
        noniso["mean_error"].as_f64().unwrap(),
    );
    assert!(init > 0.25 && fin < 0.12, "{init} -> {fin}");
    // The learned pipeline beside the default on the bodies only: a map
    // with an exact error (a mean geodesic error is below the diameter,
    // under 2 x sqrt(area) on these bodies).
    assert!(v["pairs"][0]["learned"].is_null());
    let learned = noniso["learned"]["mean_error"].as_f64().unwrap();
    assert!(learned > 0.0 && learned < 2.0, "{learned}");
    for name in [
        "color-transfer.png",
        "error.png",
        "fmap.png",
        "curves.png",
        "noniso-color-transfer.png",
        "noniso-learned-color-transfer.png",
        "noniso-error.png",
    ] {
        let bytes = std::fs::read(dir.join(name)).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{name}");
    }
    let ply = std::fs::read_to_string(dir.join("target.ply")).unwrap();
    assert!(ply.starts_with("ply\nformat ascii 1.0"));
    assert!(ply.contains("element vertex 642"));
    // Out-of-range resolution: bad usage.
    let out = fmaps()
        .args(["demo", "--subdivisions", "9", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn render_subcommands_write_pictures_and_report_checked_numbers() {
    let dir = tmpdir("render");
    let p = |f: &str| dir.join(f).to_str().unwrap().to_string();
    let (m, _) = grid_fixture(&dir);
    let n = m.n_vertices();
    let json = |args: &[&str]| -> serde_json::Value {
        let v = json_of(fmaps().arg("render").args(args).arg("--json"));
        for f in v["written"].as_array().unwrap() {
            let bytes = std::fs::read(f.as_str().unwrap()).unwrap();
            assert!(
                bytes.starts_with(b"\x89PNG") || bytes.starts_with(b"ply"),
                "{f}"
            );
        }
        v
    };
    let failure = |args: &[&str]| -> String {
        let out = fmaps().arg("render").args(args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        String::from_utf8(out.stderr).unwrap()
    };

    // Colour transfer through the identity: both PLY files carry the same colours.
    let v = json(&[
        "transfer",
        &p("g.off"),
        &p("g.off"),
        "--map",
        &p("id.map"),
        "--out",
        &p("t.png"),
        "--ply",
        &p("t"),
    ]);
    assert_eq!(v["written"].as_array().unwrap().len(), 3);
    let colours = |f: &str| -> Vec<String> {
        let text = std::fs::read_to_string(dir.join(f)).unwrap();
        let body = text.split("end_header\n").nth(1).unwrap().to_string();
        body.lines().take(n).map(String::from).collect()
    };
    assert_eq!(colours("t-source.ply"), colours("t-target.ply"));
    json(&[
        "transfer",
        &p("g.off"),
        &p("g.off"),
        "--map",
        &p("shift.map"),
        "--texture",
        "--up",
        "z",
        "--yaw",
        "-30",
        "--out",
        &p("tex.png"),
    ]);

    // Error picture: the same mean as `fmaps eval` gives for this map (0.2).
    let v = json(&[
        "error",
        "--source",
        &p("g.off"),
        "--target",
        &p("g.off"),
        "--map",
        &p("shift.map"),
        "--gt-source",
        &p("g.vts"),
        "--gt-target",
        &p("g.vts"),
        "--out",
        &p("e.png"),
    ]);
    assert!((v["mean_error"].as_f64().unwrap() - 0.2).abs() < 1e-12);
    assert_eq!(v["geodesic"], "exact");

    // Curves from `fmaps eval --json` reports.
    for map in ["id", "shift"] {
        let out = fmaps()
            .args(["eval", "--source", &p("g.off"), "--target", &p("g.off")])
            .args([
                "--map",
                &p(&format!("{map}.map")),
                "--gt-source",
                &p("g.vts"),
            ])
            .args(["--gt-target", &p("g.vts"), "--json"])
            .output()
            .unwrap();
        std::fs::write(dir.join(format!("{map}.json")), out.stdout).unwrap();
    }
    json(&[
        "curves",
        &p("id.json"),
        &p("shift.json"),
        "--out",
        &p("curves.png"),
    ]);
    assert!(
        failure(&["curves", &p("g.off")]).contains("expected the output of `fmaps eval --json`")
    );
    assert!(
        failure(&["curves", &p("id.json"), "--label", "a", "--label", "b"]).contains("2 --label")
    );

    // Matrix heat map: 5 of the 9 entries are below 0.1 in magnitude.
    std::fs::write(dir.join("C.txt"), "1 0 0.05\n0 -1 0.2\n0 0 1\n").unwrap();
    let v = json(&["fmap", &p("C.txt"), "--out", &p("C.png")]);
    assert_eq!((v["rows"].as_u64(), v["cols"].as_u64()), (Some(3), Some(3)));
    assert!((v["sparsity"].as_f64().unwrap() - 5.0 / 9.0).abs() < 1e-15);
    std::fs::write(dir.join("bad.txt"), "1 0\n0 x\n").unwrap();
    assert!(failure(&["fmap", &p("bad.txt")]).contains("bad.txt:2: `x` is not a number"));
    std::fs::write(dir.join("ragged.txt"), "1 0\n0\n").unwrap();
    assert!(failure(&["fmap", &p("ragged.txt")]).contains("ragged.txt:2: 1 entries"));

    // Scalar field: the colour range defaults to the values' range.
    let xs: String = m.vertices().iter().map(|q| format!("{}\n", q[0])).collect();
    std::fs::write(dir.join("x.txt"), &xs).unwrap();
    let v = json(&[
        "scalar",
        &p("g.off"),
        "--values",
        &p("x.txt"),
        "--out",
        &p("x.png"),
    ]);
    assert_eq!(
        (v["vmin"].as_f64(), v["vmax"].as_f64()),
        (Some(0.0), Some(1.0))
    );
    std::fs::write(dir.join("short.txt"), "1\n2\n").unwrap();
    assert!(
        failure(&["scalar", &p("g.off"), "--values", &p("short.txt")])
            .contains("2 values, but the mesh has 25 vertices")
    );

    // Spectral embedding of the unit sphere: the first non-constant
    // eigenvalues are l(l+1) = 2 (up to discretisation).
    let s = fmaps::shapes::icosphere(1.0, 3);
    fmaps::mesh_io::write_mesh(dir.join("s.off"), &s).unwrap();
    let v = json(&["embedding", &p("s.off"), "--out", &p("emb.png")]);
    for e in v["eigenvalues"].as_array().unwrap() {
        assert!((e.as_f64().unwrap() - 2.0).abs() < 0.02, "{e}");
    }
    assert!(failure(&["embedding", &p("s.off"), "--eigs", "1,2"]).contains("three indices"));
    assert!(failure(&["error", "--source", &p("g.off")]).contains("--target"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `fmaps refine`: a given map (the built-in pair's truth with every fifth
/// vertex sent elsewhere) is repaired by ZoomOut; a map of the wrong length
/// is bad input naming the file; the map file cannot be the output.
#[test]
fn refine_repairs_a_given_map() {
    let dir = tmpdir("refine");
    let pair = fmaps::shapes::creature_pair(3);
    fmaps::mesh_io::write_mesh(dir.join("a.off"), &pair.source).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("b.off"), &pair.target).unwrap();
    let n = pair.truth.len();
    let noisy: Vec<usize> = pair
        .truth
        .iter()
        .enumerate()
        .map(|(i, &t)| if i % 5 == 0 { (t + 97) % n } else { t })
        .collect();
    fmaps::mesh_io::write_map(dir.join("init.map"), &noisy).unwrap();
    fmaps::mesh_io::write_map(dir.join("short.map"), &noisy[1..]).unwrap();
    let v = json_of(fmaps().current_dir(&dir).args([
        "refine",
        "a.off",
        "b.off",
        "--init-map",
        "init.map",
        "--k",
        "30",
        "--zoomout",
        "30:60:5",
        "--out",
        "r.map",
        "--json",
    ]));
    assert_eq!(v["refine"]["final_k"], 60);
    let wrong = |t: &[usize]| t.iter().zip(&pair.truth).filter(|(x, y)| x != y).count();
    let r = fmaps::mesh_io::read_map(dir.join("r.map")).unwrap();
    assert!(
        wrong(&r) * 5 < wrong(&noisy),
        "{} wrong before, {} after",
        wrong(&noisy),
        wrong(&r)
    );
    // The Sinkhorn conversion repairs as well, and covers more of the
    // target than nearest neighbours (its plan must reach every vertex).
    let s = json_of(fmaps().current_dir(&dir).args([
        "refine",
        "a.off",
        "b.off",
        "--init-map",
        "init.map",
        "--k",
        "30",
        "--zoomout",
        "30:60:5",
        "--conversion",
        "sinkhorn",
        "--out",
        "s.map",
        "--json",
    ]));
    assert!(s["refine"]["method"].as_str().unwrap().contains("sinkhorn"));
    let rs = fmaps::mesh_io::read_map(dir.join("s.map")).unwrap();
    assert!(
        wrong(&rs) * 5 < wrong(&noisy),
        "sinkhorn: {} wrong",
        wrong(&rs)
    );
    let coverage = |v: &serde_json::Value| v["quality"]["coverage"].as_f64().unwrap();
    assert!(
        coverage(&s) > coverage(&v),
        "coverage: sinkhorn {} vs nearest neighbours {}",
        coverage(&s),
        coverage(&v)
    );
    for (args, says) in [
        (vec!["--init-map", "short.map"], "short.map"),
        (
            vec!["--init-map", "init.map", "--out", "init.map"],
            "overwrite",
        ),
        (
            vec!["--init-map", "init.map", "--k", "20"],
            "schedule starts at 50",
        ),
    ] {
        let out = fmaps()
            .current_dir(&dir)
            .args(["refine", "a.off", "b.off"])
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
