//! A corpus of nasty inputs, generated here (no data committed), through
//! every subcommand: each run must exit 0, 1 or 2 as docs/cli.md's
//! "Errors and exit codes" says, never print "panicked at", name the
//! offending file when it rejects one (exit 2), finish within a time limit,
//! and leave output files untouched (and no temporaries) when it fails.
//!
//! `cargo xtask fuzz` also runs randomly mutated variants of the valid
//! meshes (`FMAPS_FUZZ_CASES` / 20 of them; 10 in `cargo test`).

mod common;

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::{TmpDir, fmaps, tmpdir};
use fmaps::mesh_io::{TriMesh, write_obj, write_off, write_ply};
use fmaps::shapes::{disjoint_union, icosphere, translated};

/// A run over this is a hang.
const LIMIT: Duration = Duration::from_secs(120);

fn off_bytes(m: &TriMesh) -> Vec<u8> {
    let mut v = Vec::new();
    write_off(&mut v, m).unwrap();
    v
}

/// The nasty meshes: (file name, content). The good mesh `good.off` is
/// the partner and reference of every pair command.
fn mesh_corpus() -> Vec<(String, Vec<u8>)> {
    let s = icosphere(1.0, 1);
    let good = off_bytes(&s);
    let mut c: Vec<(String, Vec<u8>)> = Vec::new();
    let mut add = |name: &str, bytes: Vec<u8>| c.push((name.to_string(), bytes));
    add("empty.off", Vec::new());
    add("empty.ply", Vec::new());
    add("empty.obj", Vec::new());
    let mut bom = b"\xEF\xBB\xBF".to_vec();
    let mut obj = Vec::new();
    write_obj(&mut obj, &s).unwrap();
    bom.extend_from_slice(&obj);
    add("bom.obj", bom);
    let mut bom_off = b"\xEF\xBB\xBF".to_vec();
    bom_off.extend_from_slice(&good);
    add("bom.off", bom_off);
    add(
        "cr_only.off",
        good.iter()
            .map(|&b| if b == b'\n' { b'\r' } else { b })
            .collect(),
    );
    add(
        "crlf.off",
        String::from_utf8(good.clone())
            .unwrap()
            .replace('\n', "\r\n")
            .into_bytes(),
    );
    add(
        "oneline.off",
        b"OFF 3 1 0 0 0 0 1 0 0 0 1 0 3 0 1 2\n".to_vec(),
    );
    add(
        "extra_faces.off",
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n".to_vec(),
    );
    add(
        "extra_faces.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n".to_vec(),
    );
    let mut ply = Vec::new();
    write_ply(&mut ply, &s).unwrap();
    add("truncated.ply", ply[..ply.len() * 2 / 3].to_vec());
    let mut long = ply.clone();
    long.extend_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8]);
    add("trailing.ply", long);
    add(
        "no_end_header.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\n".to_vec(),
    );
    add(
        "float_indices.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar float vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n".to_vec(),
    );
    add(
        "nan.off",
        b"OFF\n3 1 0\nnan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n".to_vec(),
    );
    add(
        "inf.off",
        b"OFF\n3 1 0\n1e309 0 0\n1 0 0\n0 1 0\n3 0 1 2\n".to_vec(),
    );
    add(
        "huge_count.off",
        b"OFF\n99999999999999 99999999999999 0\n0 0 0\n".to_vec(),
    );
    add(
        "huge_count.ply",
        b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nelement face 4000000000\nproperty list uint uint vertex_indices\nend_header\n\0\0\0\0".to_vec(),
    );
    add(
        "neg_index.off",
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n".to_vec(),
    );
    add(
        "out_of_range.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n".to_vec(),
    );
    add("no_faces.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n".to_vec());
    let mut x = 0x2545F4914F6CDD1Du64;
    let garbage: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect();
    add("garbage.off", garbage.clone());
    add("garbage.ply", garbage);
    // Valid files, odd geometry.
    let (v, f) = s.clone().into_parts();
    let mut vi = v.clone();
    vi.extend([[5.0, 5.0, 5.0]; 3]);
    add(
        "isolated.off",
        off_bytes(&TriMesh::new(vi, f.clone()).unwrap()),
    );
    add(
        "collinear.off",
        off_bytes(
            &TriMesh::new(
                (0..20).map(|i| [i as f64, 0.0, 0.0]).collect(),
                (0..18).map(|i| [i, i + 1, i + 2]).collect(),
            )
            .unwrap(),
        ),
    );
    add(
        "huge_coords.off",
        off_bytes(
            &TriMesh::new(v.iter().map(|p| p.map(|c| c * 1e300)).collect(), f.clone()).unwrap(),
        ),
    );
    add(
        "tiny_coords.off",
        off_bytes(
            &TriMesh::new(v.iter().map(|p| p.map(|c| c * 1e-300)).collect(), f.clone()).unwrap(),
        ),
    );
    add(
        "degenerate.off",
        off_bytes(
            &TriMesh::new(v.clone(), f.iter().map(|t| [t[0], t[0], t[1]]).collect()).unwrap(),
        ),
    );
    add(
        "disconnected.off",
        off_bytes(&disjoint_union(
            &s,
            &translated(&s, [3.0, 0.0, 0.0]).unwrap(),
        )),
    );
    add("tetra.off", off_bytes(&icosphere(1.0, 0)));
    add("mesh.txt", good.clone());
    add("good_copy.off", good);
    c
}

/// Runs `fmaps args` in `dir` with a time limit: (exit code, stderr).
fn run(dir: &Path, args: &[&str]) -> (i32, String) {
    let mut child = fmaps()
        .current_dir(dir)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if t.elapsed() > LIMIT {
            child.kill().ok();
            panic!("fmaps {args:?}: still running after {LIMIT:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let out = child.wait_with_output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const SENTINEL: &[u8] = b"sentinel: must survive a failed command\n";

/// Runs one command whose outputs are `outputs` (pre-filled with a
/// sentinel) and whose offending input is `culprit` (`a|b`: either);
/// checks the promises.
fn check(dir: &Path, args: &[&str], outputs: &[&str], culprit: &str) -> i32 {
    for o in outputs {
        std::fs::write(dir.join(o), SENTINEL).unwrap();
    }
    let before = listing(dir);
    let (code, err) = run(dir, args);
    assert!(matches!(code, 0..=2), "fmaps {args:?}: exit {code}\n{err}");
    assert!(!err.contains("panicked at"), "fmaps {args:?}: {err}");
    assert_eq!(
        listing(dir),
        before,
        "fmaps {args:?}: files appeared or vanished"
    );
    if code != 0 {
        assert!(err.starts_with("error: "), "fmaps {args:?}: {err}");
        for o in outputs {
            assert_eq!(
                std::fs::read(dir.join(o)).unwrap(),
                SENTINEL,
                "fmaps {args:?} failed (exit {code}) but changed {o}"
            );
        }
    }
    if code == 2 && !culprit.is_empty() {
        assert!(
            culprit.split('|').any(|c| err.contains(c)),
            "fmaps {args:?}: the message does not name {culprit}: {err}"
        );
    }
    code
}

fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Small problem sizes for the 42-vertex corpus meshes.
const SMALL: [&str; 6] = ["--k", "5", "--k-process", "10", "--n-descr", "5"];

/// Every subcommand that reads one mesh, and `match` and `eval` with the
/// nasty mesh on either side.
fn through_every_subcommand(dir: &Path, name: &str) -> Vec<(String, i32)> {
    let mut codes = Vec::new();
    // eval may reject the map or ground truth for the mesh's size.
    let eval_culprits = format!("{name}|id.map|g.vts");
    let mut go = |label: &str, args: Vec<&str>, outs: &[&str]| {
        let culprit = if label == "eval" || label == "refine-target" {
            &eval_culprits
        } else {
            name
        };
        let code = check(dir, &args, outs, culprit);
        codes.push((format!("{label} {name}"), code));
    };
    go("info", vec!["info", name], &[]);
    go(
        "spectrum",
        vec!["spectrum", name, "--k", "5", "--out", "basis.npy"],
        &["basis.npy", "basis_eigenvalues.npy", "basis_mass.npy"],
    );
    let mut m = vec![
        "match",
        name,
        "good.off",
        "--out",
        "o.map",
        "--save-fmap",
        "C.txt",
    ];
    m.extend(SMALL);
    go("match-source", m, &["o.map", "C.txt"]);
    let mut m = vec![
        "match", "good.off", name, "--out", "o.map", "--refine", "zoomout",
    ];
    m.extend(SMALL);
    m.extend(["--zoomout", "5:8:1"]);
    go("match-target", m, &["o.map"]);
    go(
        "geodesic",
        vec!["geodesic", name, "--source", "0", "--out", "d.txt"],
        &["d.txt"],
    );
    go(
        "geodesic-heat",
        vec![
            "geodesic", name, "--source", "0", "--method", "heat", "--out", "d.txt",
        ],
        &["d.txt"],
    );
    go(
        "eval",
        vec![
            "eval",
            "--source",
            "good.off",
            "--target",
            name,
            "--map",
            "id.map",
            "--gt-source",
            "g.vts",
            "--gt-target",
            "g.vts",
        ],
        &[],
    );
    go(
        "refine-target",
        vec![
            "refine",
            "good.off",
            name,
            "--init-map",
            "id.map",
            "--k",
            "5",
            "--zoomout",
            "5:8:1",
            "--out",
            "o.map",
        ],
        &["o.map"],
    );
    go(
        "render-embedding",
        vec![
            "render",
            "embedding",
            name,
            "--out",
            "e.png",
            "--width",
            "32",
            "--height",
            "32",
        ],
        &["e.png"],
    );
    codes
}

/// The corpus directory: the nasty meshes, good.off with the identity
/// map and ground truth.
fn corpus_dir(tag: &str) -> TmpDir {
    let dir = tmpdir(tag);
    for (name, bytes) in mesh_corpus() {
        std::fs::write(dir.join(name), bytes).unwrap();
    }
    let s = icosphere(1.0, 1);
    std::fs::write(dir.join("good.off"), off_bytes(&s)).unwrap();
    let all: Vec<usize> = (0..s.n_vertices()).collect();
    fmaps::mesh_io::write_map(dir.join("id.map"), &all).unwrap();
    fmaps::mesh_io::write_vts(dir.join("g.vts"), &all).unwrap();
    std::fs::create_dir_all(dir.join("folder.off")).unwrap();
    dir
}

#[test]
fn nasty_meshes_through_every_subcommand() {
    let dir = corpus_dir("corpus-meshes");
    let mut names: Vec<String> = mesh_corpus().into_iter().map(|(n, _)| n).collect();
    names.extend(["missing.off".to_string(), "folder.off".to_string()]);
    let mut all = Vec::new();
    for name in &names {
        all.extend(through_every_subcommand(&dir, name));
    }
    let code_of = |label: &str| all.iter().find(|(l, _)| l == label).map(|x| x.1);
    // Files that are not meshes are bad input for every subcommand.
    for bad in [
        "empty.off",
        "empty.ply",
        "empty.obj",
        "oneline.off",
        "extra_faces.off",
        "extra_faces.ply",
        "truncated.ply",
        "trailing.ply",
        "no_end_header.ply",
        "float_indices.ply",
        "nan.off",
        "inf.off",
        "huge_count.off",
        "huge_count.ply",
        "neg_index.off",
        "out_of_range.obj",
        "no_faces.obj",
        "garbage.off",
        "garbage.ply",
        "mesh.txt",
        "missing.off",
        "folder.off",
    ] {
        for cmd in [
            "info",
            "spectrum",
            "match-source",
            "match-target",
            "geodesic",
            "geodesic-heat",
            "eval",
            "refine-target",
            "render-embedding",
        ] {
            assert_eq!(code_of(&format!("{cmd} {bad}")), Some(2), "{cmd} {bad}");
        }
    }
    // Readable after all: a BOM, CR or CRLF line ends, a copy.
    for ok in [
        "bom.obj",
        "bom.off",
        "cr_only.off",
        "crlf.off",
        "good_copy.off",
    ] {
        for cmd in ["info", "spectrum", "match-source", "geodesic", "eval"] {
            assert_eq!(code_of(&format!("{cmd} {ok}")), Some(0), "{cmd} {ok}");
        }
    }
    // Valid files whose geometry a stage cannot use: the same exit code
    // from `spectrum` and `match`.
    for odd in ["isolated.off", "collinear.off", "degenerate.off"] {
        let s = code_of(&format!("spectrum {odd}"));
        assert_eq!(s, Some(2), "spectrum {odd}");
        assert_eq!(code_of(&format!("match-source {odd}")), s, "match {odd}");
    }
    // Units do not matter to `match`: meshes in 1e300 or 1e-300 units are
    // matched like any (`spectrum` keeps the units: its eigenvalues
    // would overflow, bad input).
    for units in ["huge_coords.off", "tiny_coords.off"] {
        assert_eq!(
            code_of(&format!("match-source {units}")),
            Some(0),
            "{units}"
        );
        assert_eq!(
            code_of(&format!("match-target {units}")),
            Some(0),
            "{units}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The heat method and exact geodesics agree that the far component of a
/// disconnected target is unreachable.
#[test]
fn heat_and_exact_agree_on_unreachable_vertices() {
    let dir = corpus_dir("corpus-heat");
    let mut unreachable = Vec::new();
    for method in ["exact", "heat", "dijkstra"] {
        let out = fmaps()
            .current_dir(&dir)
            .args([
                "geodesic",
                "disconnected.off",
                "--source",
                "0",
                "--json",
                "--method",
                method,
            ])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        unreachable.push(v["unreachable"].as_u64().unwrap());
    }
    assert_eq!(unreachable, [42, 42, 42]);
    std::fs::remove_dir_all(&dir).ok();
}

/// Options and side files a user can get wrong: exit 2 with the reason,
/// outputs untouched.
#[test]
fn nasty_options_and_side_files() {
    let dir = corpus_dir("corpus-options");
    let w = |name: &str, text: &str| std::fs::write(dir.join(name), text).unwrap();
    w("lm_zero.txt", "0\n");
    w("lm_neg.txt", "1 -1\n");
    w("lm_text.txt", "a b\n");
    w("lm_three.txt", "1 2 3\n");
    w("lm_range.txt", "# ok\n1 2\n999999 1\n");
    w("lm_huge.txt", "18446744073709551616\n");
    w("lm_bom.txt", "\u{feff}1 2\n");
    w("short.map", "1\n2\n");
    w("zero.map", &"0\n".repeat(42));
    w("range.map", &"43\n".repeat(42));
    w("text.map", &"x\n".repeat(42));
    w("empty.vts", "");
    let wide: String = (0..1000).map(|i| format!("{} ", i % 3)).collect::<String>() + "\n";
    w("wide.txt", &wide);
    w("ragged.txt", "1 2\n3\n");
    let base = ["match", "good.off", "good_copy.off", "--out", "o.map"];
    let cases: Vec<(Vec<&str>, i32, &str)> = vec![
        (vec!["--landmarks", "lm_zero.txt"], 2, "lm_zero.txt: line 1"),
        (vec!["--landmarks", "lm_neg.txt"], 2, "lm_neg.txt"),
        (vec!["--landmarks", "lm_text.txt"], 2, "lm_text.txt"),
        (vec!["--landmarks", "lm_three.txt"], 2, "lm_three.txt"),
        (
            vec!["--landmarks", "lm_range.txt"],
            2,
            "lm_range.txt: line 3",
        ),
        (vec!["--landmarks", "lm_huge.txt"], 2, "lm_huge.txt"),
        (vec!["--landmarks", "missing.txt"], 2, "missing.txt"),
        (vec!["--landmarks", "lm_bom.txt"], 0, ""),
        // One step from 5 straight to 30: valid, and START + STEP saturates.
        (vec!["--zoomout", "5:30:18446744073709551615"], 0, ""),
        (vec!["--zoomout", "5:3:1"], 2, "--zoomout"),
        (vec!["--starts", "0"], 2, "--starts"),
        (vec!["--starts", ","], 2, "--starts"),
        (vec!["--n-descr", "18446744073709551615"], 2, "--n-descr"),
        (vec!["--k", "0"], 2, ""),
        (vec!["--k", "18446744073709551615"], 2, ""),
        (vec!["--w-orient", "nan"], 2, ""),
        (vec!["--w-lap", "-1"], 2, "weights must be >= 0"),
        (vec!["--w-descr", "inf"], 2, "weights must be >= 0"),
        (
            vec![
                "--w-descr",
                "0",
                "--w-lap",
                "0",
                "--w-dcomm",
                "0",
                "--w-orient",
                "0",
            ],
            2,
            "positive sum",
        ),
        (vec!["--w-dcomm", "0.5"], 0, ""),
    ];
    for (extra, want, says) in cases {
        let mut args: Vec<&str> = base.to_vec();
        args.extend(SMALL);
        args.extend(extra.iter().copied());
        let code = check(&dir, &args, &["o.map"], "");
        assert_eq!(code, want, "{args:?}");
        if !says.is_empty() {
            let (_, err) = run(&dir, &args);
            assert!(err.contains(says), "{args:?}: {err}");
        }
    }
    let eval = |map: &str, gt: &str| {
        vec![
            "eval",
            "--source",
            "good.off",
            "--target",
            "good.off",
            "--map",
            map,
            "--gt-source",
            gt,
            "--gt-target",
            gt,
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>()
    };
    for (map, gt) in [
        ("short.map", "g.vts"),
        ("zero.map", "g.vts"),
        ("range.map", "g.vts"),
        ("text.map", "g.vts"),
        ("id.map", "empty.vts"),
    ] {
        let args = eval(map, gt);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let culprit = if gt == "empty.vts" { gt } else { map };
        assert_eq!(check(&dir, &args, &[], culprit), 2, "{args:?}");
    }
    // Threads beyond 4 per core are refused at once.
    for t in ["100000", "18446744073709551615"] {
        assert_eq!(
            check(
                &dir,
                &["--threads", t, "info", "good.off"],
                &[],
                "--threads"
            ),
            2
        );
    }
    // Pictures: a matrix wider than the picture, a ragged one, eigenfunction
    // indices beyond any mesh, outputs that are inputs.
    let png = ["--out", "p.png"];
    for (args, want) in [
        (vec!["render", "fmap", "wide.txt"], 0),
        (vec!["render", "fmap", "ragged.txt"], 2),
        (
            vec![
                "render",
                "embedding",
                "good.off",
                "--eigs",
                "1,2,18446744073709551615",
            ],
            2,
        ),
        (
            vec!["render", "embedding", "good.off", "--eigs", "1,2,41"],
            2,
        ),
    ] {
        let mut a = args.clone();
        a.extend(png);
        assert_eq!(check(&dir, &a, &["p.png"], ""), want, "{a:?}");
    }
    for args in [
        vec!["render", "fmap", "wide.txt", "--out", "wide.txt"],
        vec!["render", "embedding", "good.off", "--out", "good.off"],
        vec![
            "render",
            "transfer",
            "good.off",
            "good_copy.off",
            "--map",
            "id.map",
            "--out",
            "id.map",
        ],
        vec![
            "render", "scalar", "good.off", "--values", "id.map", "--out", "id.map",
        ],
    ] {
        assert_eq!(check(&dir, &args, &[], "overwrite"), 2, "{args:?}");
    }
    assert_eq!(
        check(
            &dir,
            &["demo", "--subdivisions", "2", "--out", "d"],
            &[],
            ""
        ),
        2
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Randomly mutated valid meshes through `info` and `match` (more with
/// `cargo xtask fuzz`).
#[test]
fn mutated_meshes_through_info_and_match() {
    let dir = corpus_dir("corpus-mutated");
    let cases: usize = std::env::var("FMAPS_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .map_or(10, |c| (c / 20).max(1));
    let s = icosphere(1.0, 1);
    let mut ply = Vec::new();
    write_ply(&mut ply, &s).unwrap();
    let seeds = [(off_bytes(&s), "off"), (ply, "ply")];
    let mut x = 0x9E3779B97F4A7C15u64;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for i in 0..cases {
        let (seed, ext) = &seeds[i % 2];
        let mut data = seed.clone();
        for _ in 0..1 + next() % 4 {
            let at = (next() as usize) % data.len();
            match next() % 3 {
                0 => data[at] = next() as u8,
                1 => data.insert(at, b"0123456789 -.e\n"[(next() % 15) as usize]),
                _ => {
                    data.remove(at);
                }
            }
        }
        let name = format!("m{i}.{ext}");
        std::fs::write(dir.join(&name), &data).unwrap();
        check(&dir, &["info", &name], &[], &name);
        let mut m = vec!["match", name.as_str(), "good.off", "--out", "o.map"];
        m.extend(SMALL);
        check(&dir, &m, &["o.map"], &name);
        std::fs::remove_file(dir.join(&name)).unwrap();
    }
    std::fs::remove_dir_all(&dir).ok();
}
