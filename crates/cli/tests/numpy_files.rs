//! NumPy files wherever a matrix goes in or out of the CLI: maps (0-based
//! in NumPy, 1-based in text), C, a user's own descriptors, scalar fields,
//! eigenbases; the same numbers as the text formats, and bad files
//! refused with exit code 2 naming the file.

mod common;

use std::path::Path;

use common::{fmaps, tmpdir};
use fmaps::mesh_io::{arrays, npy, npz};

fn ok(dir: &Path, args: &[&str]) -> String {
    let o = fmaps().current_dir(dir).args(args).output().unwrap();
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn refused(dir: &Path, args: &[&str], says: &str) {
    let o = fmaps().current_dir(dir).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert!(err.contains(says), "{args:?}: {err}");
}

/// An .npy file by hand, as NumPy writes format 1.0 (C order).
fn raw_npy(descr: &str, shape: &str, data: &[u8]) -> Vec<u8> {
    let mut h = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + h.len() + 1) % 64 != 0 {
        h.push(' ');
    }
    h.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(h.len() as u16).to_le_bytes());
    out.extend_from_slice(h.as_bytes());
    out.extend_from_slice(data);
    out
}

#[test]
fn numpy_files_carry_the_same_numbers_as_the_text_formats() {
    let dir = tmpdir("numpy");
    let pair = fmaps::shapes::creature_pair(3);
    fmaps::mesh_io::write_mesh(dir.join("a.off"), &pair.source).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("b.off"), &pair.target).unwrap();
    let (na, nb) = (pair.source.n_vertices(), pair.target.n_vertices());
    let small = [
        "--refine",
        "none",
        "-k",
        "12",
        "--k-process",
        "30",
        "--n-descr",
        "30",
    ];
    let run_match = |out: &str, fmap: &str, extra: &[&str]| {
        let mut args = vec!["match", "a.off", "b.off", "--out", out, "--save-fmap", fmap];
        args.extend(small);
        args.extend(extra);
        ok(&dir, &args);
    };
    run_match("m.map", "c.txt", &[]);
    run_match("m.npy", "c.npy", &[]);
    run_match("m.npz", "c.npz", &[]);
    let text_map = fmaps::mesh_io::read_map(dir.join("m.map")).unwrap();
    assert_eq!(arrays::read_indices(&dir.join("m.npy")).unwrap(), text_map);
    assert_eq!(arrays::read_indices(&dir.join("m.npz")).unwrap(), text_map);
    // The .npy map is int64 and 0-based: entry i is map[i] itself.
    let raw = npy::parse_i64(&std::fs::read(dir.join("m.npy")).unwrap()).unwrap();
    assert_eq!(
        raw.data,
        text_map.iter().map(|&i| i as i64).collect::<Vec<_>>()
    );
    let c_text: Vec<f64> = std::fs::read_to_string(dir.join("c.txt"))
        .unwrap()
        .split_whitespace()
        .map(|s| s.parse().unwrap())
        .collect();
    let (r, k, c) = arrays::read_matrix(&dir.join("c.npy")).unwrap();
    assert_eq!((r, k), (12, 12));
    // Row-major text against column-major values: 17 digits round-trip.
    for i in 0..12 {
        for j in 0..12 {
            assert_eq!(c[j * 12 + i], c_text[i * 12 + j]);
        }
    }
    assert_eq!(arrays::read_matrix(&dir.join("c.npz")).unwrap().2, c);

    // Maps in: eval, refine and render read the .npy map as the .map.
    std::fs::write(
        dir.join("id_a.vts"),
        (1..=na).map(|i| format!("{i}\n")).collect::<String>(),
    )
    .unwrap();
    let gt_b = pair
        .truth
        .iter()
        .map(|&i| format!("{}\n", i + 1))
        .collect::<String>();
    std::fs::write(dir.join("gt_b.vts"), gt_b).unwrap();
    let eval = |map: &str| {
        ok(
            &dir,
            &[
                "eval",
                "--source",
                "a.off",
                "--target",
                "b.off",
                "--map",
                map,
                "--gt-source",
                "id_a.vts",
                "--gt-target",
                "gt_b.vts",
                "--geodesic",
                "dijkstra",
                "--json",
            ],
        )
    };
    let (e_text, e_npy) = (eval("m.map"), eval("m.npy"));
    let mean =
        |s: &str| serde_json::from_str::<serde_json::Value>(s).unwrap()["mean_error"].clone();
    assert_eq!(mean(&e_text), mean(&e_npy));
    for (init, out) in [("m.map", "r1.map"), ("m.npy", "r2.map")] {
        ok(
            &dir,
            &[
                "refine",
                "a.off",
                "b.off",
                "--init-map",
                init,
                "--refine",
                "icp",
                "-k",
                "12",
                "--out",
                out,
            ],
        );
    }
    assert_eq!(
        fmaps::mesh_io::read_map(dir.join("r1.map")).unwrap(),
        fmaps::mesh_io::read_map(dir.join("r2.map")).unwrap()
    );

    // Own descriptors: the same matrix as .npy (float32, C order) and as
    // text gives the same map; on a shape against itself, its coordinates
    // as descriptors give the identity.
    let coords = |m: &fmaps::mesh_io::TriMesh| -> Vec<[f64; 3]> { m.vertices().to_vec() };
    let write_descr = |name: &str, v: &[[f64; 3]]| {
        let data: Vec<u8> = v
            .iter()
            .flatten()
            .flat_map(|&x| (x as f32).to_le_bytes())
            .collect();
        std::fs::write(
            dir.join(format!("{name}.npy")),
            raw_npy("<f4", &format!("({}, 3)", v.len()), &data),
        )
        .unwrap();
        let text: String = v
            .iter()
            .map(|p| format!("{} {} {}\n", p[0] as f32, p[1] as f32, p[2] as f32))
            .collect();
        std::fs::write(dir.join(format!("{name}.txt")), text).unwrap();
    };
    write_descr("da", &coords(&pair.source));
    write_descr("db", &coords(&pair.target));
    run_match(
        "d1.map",
        "d1.txt",
        &["--descr-source", "da.npy", "--descr-target", "db.npy"],
    );
    run_match(
        "d2.map",
        "d2.txt",
        &["--descr-source", "da.txt", "--descr-target", "db.txt"],
    );
    assert_eq!(
        fmaps::mesh_io::read_map(dir.join("d1.map")).unwrap(),
        fmaps::mesh_io::read_map(dir.join("d2.map")).unwrap()
    );
    let mut args = vec![
        "match",
        "a.off",
        "a.off",
        "--out",
        "self.npy",
        "--descr-source",
        "da.npy",
        "--descr-target",
        "da.npy",
    ];
    args.extend(small);
    ok(&dir, &args);
    let selfmap = arrays::read_indices(&dir.join("self.npy")).unwrap();
    let fixed = selfmap.iter().enumerate().filter(|(i, j)| i == *j).count();
    assert!(fixed * 100 >= 99 * na, "{fixed} of {na} vertices kept");

    // A scalar field as NumPy (NaN allowed, drawn grey).
    let values: Vec<u8> = (0..na)
        .flat_map(|i| if i == 0 { f64::NAN } else { i as f64 }.to_le_bytes())
        .collect();
    std::fs::write(
        dir.join("v.npy"),
        raw_npy("<f8", &format!("({na},)"), &values),
    )
    .unwrap();
    ok(
        &dir,
        &[
            "render", "scalar", "a.off", "--values", "v.npy", "--out", "v.png",
        ],
    );

    // An eigenbasis as one .npz archive np.load reads.
    ok(
        &dir,
        &["spectrum", "a.off", "--k", "6", "--out", "basis.npz"],
    );
    let bytes = std::fs::read(dir.join("basis.npz")).unwrap();
    let names: Vec<String> = npz::read_archive(&bytes)
        .unwrap()
        .into_iter()
        .map(|e| e.name)
        .collect();
    assert_eq!(names, ["eigenvectors.npy", "eigenvalues.npy", "mass.npy"]);
    let _ = nb;
}

#[test]
fn bad_numpy_files_are_refused_naming_the_file() {
    let dir = tmpdir("numpy-bad");
    let pair = fmaps::shapes::creature_pair(3);
    fmaps::mesh_io::write_mesh(dir.join("a.off"), &pair.source).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("b.off"), &pair.target).unwrap();
    let n = pair.source.n_vertices();
    let zeros = |bytes: usize| vec![0u8; bytes];
    let files: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "trunc.npy",
            raw_npy("<i8", &format!("({n},)"), &zeros(8 * n - 3)),
            "bytes of data",
        ),
        (
            "bool.npy",
            raw_npy("|b1", &format!("({n},)"), &zeros(n)),
            "booleans",
        ),
        (
            "pickle.npy",
            raw_npy("|O", &format!("({n},)"), &zeros(8 * n)),
            "pickle",
        ),
        (
            "frac.npy",
            raw_npy(
                "<f8",
                "(2,)",
                &[0.5f64.to_le_bytes(), 1f64.to_le_bytes()].concat(),
            ),
            "not an integer index",
        ),
        (
            "neg.npy",
            raw_npy("<i4", "(1,)", &(-1i32).to_le_bytes()),
            "negative",
        ),
        (
            "big.npy",
            raw_npy(
                "<i4",
                &format!("({n},)"),
                &(0..n as i32)
                    .map(|_| 99_999)
                    .flat_map(i32::to_le_bytes)
                    .collect::<Vec<_>>(),
            ),
            "outside 0..",
        ),
        (
            "shape.npy",
            raw_npy("<i4", "(2, 2)", &zeros(16)),
            "shape [2, 2]",
        ),
        (
            "garbage.npy",
            b"not numpy at all".to_vec(),
            "not a NumPy .npy array",
        ),
    ];
    for (name, bytes, says) in &files {
        std::fs::write(dir.join(name), bytes).unwrap();
        refused(
            &dir,
            &[
                "refine",
                "a.off",
                "b.off",
                "--init-map",
                name,
                "--out",
                "o.map",
            ],
            name,
        );
        refused(
            &dir,
            &[
                "refine",
                "a.off",
                "b.off",
                "--init-map",
                name,
                "--out",
                "o.map",
            ],
            says,
        );
        assert!(!dir.join("o.map").exists());
    }
    // Descriptors: a wrong row count, different columns.
    std::fs::write(dir.join("d3.npy"), raw_npy("<f8", "(3, 2)", &zeros(48))).unwrap();
    refused(
        &dir,
        &[
            "match",
            "a.off",
            "b.off",
            "--descr-source",
            "d3.npy",
            "--descr-target",
            "d3.npy",
        ],
        "d3.npy: 3 rows",
    );
    let nb = pair.target.n_vertices();
    std::fs::write(
        dir.join("da.npy"),
        raw_npy("<f8", &format!("({n}, 2)"), &zeros(16 * n)),
    )
    .unwrap();
    std::fs::write(
        dir.join("db.npy"),
        raw_npy("<f8", &format!("({nb}, 3)"), &zeros(24 * nb)),
    )
    .unwrap();
    refused(
        &dir,
        &[
            "match",
            "a.off",
            "b.off",
            "--descr-source",
            "da.npy",
            "--descr-target",
            "db.npy",
        ],
        "must correspond column by column",
    );
    refused(
        &dir,
        &["match", "a.off", "b.off", "--descr-source", "da.npy"],
        "--descr-target",
    );
}
