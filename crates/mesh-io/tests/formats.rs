//! Reader features and every error path of the readers.

use fmaps_mesh_io::*;

fn tet() -> TriMesh {
    TriMesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ],
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    )
    .unwrap()
}

/// Asserts a parse error at the given location whose message contains `needle`.
#[track_caller]
fn parse_error_at<T: std::fmt::Debug>(r: Result<T>, want: Location, needle: &str) {
    match r {
        Err(Error::Parse {
            location, message, ..
        }) => {
            assert_eq!(location, want, "message: {message}");
            assert!(
                message.contains(needle),
                "'{message}' does not contain '{needle}'"
            );
        }
        other => panic!("expected a parse error at {want}, got {other:?}"),
    }
}

#[test]
fn off_with_comments_blank_lines_and_counts_on_next_line() {
    let text = "# a comment\n\nOFF\n# counts follow\n4 4 0\n0 0 0\n1 0 0 # trailing\n\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
    assert_eq!(parse_off(text.as_bytes()).unwrap(), tet());
}

#[test]
fn off_counts_on_header_line_colours_and_crlf() {
    let text = "COFF 4 4 0\r\n0 0 0 255 0 0 255\r\n1 0 0 0 255 0 255\r\n0 1 0 0 0 255 255\r\n0 0 1 1 1 1 1\r\n3 0 2 1 10 20 30\r\n3 0 1 3\r\n3 0 3 2\r\n3 1 2 3\r\n";
    assert_eq!(parse_off(text.as_bytes()).unwrap(), tet());
}

#[test]
fn off_polygons_are_fan_triangulated() {
    let text = "OFF\n5 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n-1 0.5 0\n5 0 1 2 3 4\n";
    let m = parse_off(text.as_bytes()).unwrap();
    assert_eq!(m.faces(), &[[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
}

#[test]
fn off_errors_name_the_line() {
    let p = |s: &str| parse_off(s.as_bytes());
    parse_error_at(p("PLY\n"), Location::Line(1), "expected the 'OFF' header");
    parse_error_at(p("4OFF\n"), Location::Line(1), "unsupported OFF variant");
    parse_error_at(p("OFF\nx 1 0\n"), Location::Line(2), "vertex count 'x'");
    parse_error_at(p("OFF\n-3 1 0\n"), Location::Line(2), "vertex count '-3'");
    parse_error_at(
        p("OFF\n3 1 0\n0 0 0\n1 0\n"),
        Location::Line(4),
        "fewer than 3 coordinates",
    );
    parse_error_at(
        p("OFF\n3 1 0\n0 0 0\n1 0 nan\n0 1 0\n3 0 1 2\n"),
        Location::Line(4),
        "non-finite",
    );
    parse_error_at(
        p("OFF\n3 1 0\n0 0 0\n1 0 inf\n"),
        Location::Line(4),
        "non-finite",
    );
    parse_error_at(
        p("OFF\n3 1 0\n0 0 0\n1 0 a\n"),
        Location::Line(4),
        "not a number",
    );
    parse_error_at(
        p("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"),
        Location::Line(6),
        "refers to vertex 3",
    );
    parse_error_at(
        p("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n"),
        Location::Line(6),
        "negative vertex index -1",
    );
    parse_error_at(
        p("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n"),
        Location::Line(6),
        "needs at least 3",
    );
    parse_error_at(
        p("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n"),
        Location::Line(6),
        "declares 4 vertices but lists 3",
    );
    parse_error_at(
        p("OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
        Location::End,
        "face 1 of 2",
    );
    parse_error_at(p("OFF\n3 1 0\n0 0 0\n"), Location::End, "vertex 1 of 3");
    parse_error_at(p(""), Location::End, "OFF header");
    parse_error_at(
        parse_off(b"OFF\n3 1 0\n0 0 \xff\n"),
        Location::Line(3),
        "UTF-8",
    );
    assert!(matches!(
        p("OFF\n0 0 0\n"),
        Err(Error::InvalidMesh {
            problem: MeshProblem::Empty { .. },
            ..
        })
    ));
}

fn ply_header(format: &str, vprops: &str, flist: &str, nv: usize, nf: usize) -> String {
    format!(
        "ply\nformat {format} 1.0\ncomment test\nelement vertex {nv}\n{vprops}element face {nf}\nproperty list {flist} vertex_indices\nend_header\n"
    )
}

#[test]
fn ply_ascii_with_extra_properties_and_elements() {
    let text = "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty list uchar int extra\nelement face 4\nproperty uchar flags\nproperty list uchar int vertex_indices\nelement edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n0 0 0 255 2 7 7\n1 0 0 0 0\n0 1 0 1 1 9\n0 0 1 3 0\n0 3 0 2 1\n1 3 0 1 3\n0 3 0 3 2\n0 3 1 2 3\n0 1\n";
    assert_eq!(parse_ply(text.as_bytes()).unwrap(), tet());
}

fn binary_ply(le: bool, coord_double: bool, list: (&str, &str)) -> Vec<u8> {
    let m = tet();
    let vprops = if coord_double {
        "property double x\nproperty double y\nproperty double z\nproperty uchar red\n"
    } else {
        "property float x\nproperty float y\nproperty float z\nproperty uchar red\n"
    };
    let fmt = if le {
        "binary_little_endian"
    } else {
        "binary_big_endian"
    };
    let mut out = ply_header(fmt, vprops, &format!("{} {}", list.0, list.1), 4, 4).into_bytes();
    let put = |out: &mut Vec<u8>, b: &[u8]| {
        let mut b = b.to_vec();
        if !le {
            b.reverse();
        }
        out.extend_from_slice(&b);
    };
    for p in m.vertices() {
        for &c in p {
            if coord_double {
                put(&mut out, &c.to_le_bytes());
            } else {
                put(&mut out, &(c as f32).to_le_bytes());
            }
        }
        out.push(200);
    }
    for f in m.faces() {
        match list.0 {
            "uchar" => out.push(3),
            _ => put(&mut out, &3i32.to_le_bytes()),
        }
        for &i in f {
            match list.1 {
                "int" => put(&mut out, &(i as i32).to_le_bytes()),
                "uint" => put(&mut out, &(i as u32).to_le_bytes()),
                _ => put(&mut out, &(i as u16).to_le_bytes()),
            }
        }
    }
    out
}

#[test]
fn ply_binary_both_endians_float_and_double() {
    for le in [true, false] {
        for dbl in [true, false] {
            for list in [("uchar", "int"), ("int", "uint"), ("uchar", "ushort")] {
                let data = binary_ply(le, dbl, list);
                assert_eq!(
                    parse_ply(&data).unwrap(),
                    tet(),
                    "le={le} double={dbl} list={list:?}"
                );
            }
        }
    }
}

#[test]
fn ply_errors_name_line_or_byte() {
    let vp = "property float x\nproperty float y\nproperty float z\n";
    let hdr = ply_header("ascii", vp, "uchar int", 3, 1);
    let hdr_lines = hdr.lines().count();
    let p = |s: String| parse_ply(s.as_bytes());
    parse_error_at(p("plx\n".into()), Location::Line(1), "expected 'ply'");
    parse_error_at(
        p("ply\nformat ascii 2.0\n".into()),
        Location::Line(2),
        "unsupported PLY version",
    );
    parse_error_at(
        p("ply\nformat utf8 1.0\n".into()),
        Location::Line(2),
        "unknown PLY format",
    );
    parse_error_at(
        p("ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\n".into()),
        Location::Line(4),
        "unknown type",
    );
    parse_error_at(
        p("ply\nformat ascii 1.0\nelement vertex 1\n".into()),
        Location::End,
        "no 'end_header'",
    );
    parse_error_at(p("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".into()), Location::Line(3), "no scalar property 'y'");
    parse_error_at(p("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n".into()), Location::Line(1), "no 'face' element");
    parse_error_at(
        p("ply\nformat ascii 1.0\nproperty float x\n".into()),
        Location::Line(3),
        "property before any element",
    );
    parse_error_at(
        p(
            "ply\nformat ascii 1.0\nelement face 1\nproperty list float int vertex_indices\n"
                .into(),
        ),
        Location::Line(4),
        "not an integer type",
    );
    parse_error_at(
        p("ply\nformat ascii 1.0\nelement vertex x\n".into()),
        Location::Line(3),
        "count 'x'",
    );
    parse_error_at(
        p("ply\nformat ascii 1.0\nbogus line\n".into()),
        Location::Line(3),
        "unknown header keyword",
    );
    parse_error_at(p("ply\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".into()), Location::Line(2), "no 'format' line");
    parse_error_at(p("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar float vertex_indices\nend_header\n".into()), Location::Line(7), "integer type");
    let l = |k: usize| Location::Line(hdr_lines + k);
    parse_error_at(
        p(format!("{hdr}0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n")),
        l(4),
        "refers to vertex 3",
    );
    parse_error_at(
        p(format!("{hdr}0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n")),
        l(4),
        "negative vertex index",
    );
    parse_error_at(
        p(format!("{hdr}0 0 0\n1 0 0\n0 1 0\n2 0 1\n")),
        l(4),
        "needs at least 3",
    );
    parse_error_at(
        p(format!("{hdr}0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n")),
        l(2),
        "non-finite",
    );
    parse_error_at(
        p(format!("{hdr}0 0 0\n1 0\n0 1 0\n3 0 1 2\n")),
        l(2),
        "fewer values",
    );
    parse_error_at(
        p(format!("{hdr}0 0 0 5\n1 0 0\n0 1 0\n3 0 1 2\n")),
        l(1),
        "more values",
    );
    parse_error_at(
        p(format!("{hdr}0 0 0\n1 0 0\n0 1 0\n3 0 1.5 2\n")),
        l(4),
        "not an integer",
    );
    parse_error_at(
        p(format!("{hdr}0 0 0\n1 0 0\n")),
        Location::End,
        "truncated",
    );

    let data = binary_ply(true, true, ("uchar", "int"));
    let body = data.len() - (4 * 25 + 4 * 13);
    // Cut inside the third face: the error is at the byte where data ends.
    let cut = body + 4 * 25 + 2 * 13 + 5;
    parse_error_at(parse_ply(&data[..cut]), Location::Byte(cut), "truncated");
    let mut bad = data.clone();
    let idx_at = body + 4 * 25 + 1;
    bad[idx_at..idx_at + 4].copy_from_slice(&7i32.to_le_bytes());
    parse_error_at(
        parse_ply(&bad),
        Location::Byte(idx_at),
        "refers to vertex 7",
    );
    let mut nan = data.clone();
    nan[body + 8..body + 16].copy_from_slice(&f64::NAN.to_le_bytes());
    parse_error_at(parse_ply(&nan), Location::Byte(body), "non-finite");
}

#[test]
fn obj_geometry_with_texture_normal_and_negative_indices() {
    let text = "# cube corner\nmtllib x.mtl\no thing\nv 0 0 0\nv 1 0 0\nv 0 1 0 0.5 0.5 0.5\nv 0 0 1\nvt 0 0\nvn 0 0 1\ng side\nusemtl m\nf 1/1/1 3/1/1 2/1/1\nf 1//1 2//1 4//1\nf -4 -1 -2\ns off\nf 2/1 3/1 4/1\nl 1 2\n";
    assert_eq!(parse_obj(text.as_bytes()).unwrap(), tet());
}

#[test]
fn obj_errors_name_the_line() {
    let p = |s: &str| parse_obj(s.as_bytes());
    parse_error_at(
        p("v 0 0 0\nv 1 0 0\nv 0 1\n"),
        Location::Line(3),
        "fewer than 3 coordinates",
    );
    parse_error_at(p("v 0 0 0\nv 1 0 inf\n"), Location::Line(2), "non-finite");
    parse_error_at(
        p("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n"),
        Location::Line(4),
        "refers to vertex 4",
    );
    parse_error_at(
        p("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"),
        Location::Line(4),
        "refers to vertex 0",
    );
    parse_error_at(
        p("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n"),
        Location::Line(4),
        "refers to vertex -4",
    );
    parse_error_at(
        p("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n"),
        Location::Line(4),
        "needs at least 3",
    );
    parse_error_at(
        p("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 x 2\n"),
        Location::Line(4),
        "not a vertex reference",
    );
    assert!(matches!(p("v 0 0 0\n"), Err(Error::InvalidMesh { .. })));
}

/// tobj is an independent OBJ parser: the triangles must have the same
/// corner positions (tobj renumbers vertices, so indices are not compared).
#[test]
fn obj_agrees_with_tobj_on_geometry() {
    let m = fmaps_shapes::torus(2.0, 0.5, 7, 5);
    let mut bytes = Vec::new();
    write_obj(&mut bytes, &m).unwrap();
    let ours = parse_obj(&bytes).unwrap();
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj_buf(&mut bytes.as_slice(), &opts, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .unwrap();
    let tm = &models[0].mesh;
    assert_eq!(tm.indices.len(), 3 * ours.n_faces());
    for (fi, f) in ours.faces().iter().enumerate() {
        for k in 0..3 {
            let ti = tm.indices[3 * fi + k] as usize;
            let tp = [
                tm.positions[3 * ti],
                tm.positions[3 * ti + 1],
                tm.positions[3 * ti + 2],
            ];
            let op = ours.vertices()[f[k]];
            for c in 0..3 {
                assert!((tp[c] as f64 - op[c]).abs() <= 1e-6 * (1.0 + op[c].abs()));
            }
        }
    }
}

#[test]
fn index_lists_are_one_based_on_disk() {
    assert_eq!(
        parse_index_list(b"1\n5\n\n3\n", ".vts").unwrap(),
        vec![0, 4, 2]
    );
    let e = |s: &str, line: usize, needle: &str| {
        parse_error_at(
            parse_index_list(s.as_bytes(), ".map").map(|_| tet()),
            Location::Line(line),
            needle,
        )
    };
    e("1\n0\n", 2, "not a 1-based index");
    e("1\n-2\n", 2, "not a 1-based index");
    e("1\n2 3\n", 2, "one vertex index per line");
    e("1.5\n", 1, "not an integer");
    let idx = parse_index_list(b"1\n2\n9\n", ".map").unwrap();
    match check_indices(&idx, 5, None) {
        Err(Error::IndexOutOfRange {
            line: 3,
            index: 9,
            n_vertices: 5,
            ..
        }) => {}
        other => panic!("{other:?}"),
    }
    let mut out = Vec::new();
    write_index_list(&mut out, &[0, 4, 2]).unwrap();
    // usize::MAX has no 1-based form: an error naming the entry, no panic.
    let e = write_index_list(&mut Vec::new(), &[3, usize::MAX]).unwrap_err();
    assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
    assert!(e.to_string().contains("entry 1"), "{e}");
    assert!(check_indices(&[usize::MAX], 5, None).is_err());
    assert_eq!(out, b"1\n5\n3\n");
}

#[test]
fn file_errors_name_the_file() {
    let dir = std::env::temp_dir().join(format!("fmaps-mesh-io-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.off");
    std::fs::write(&bad, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").unwrap();
    let msg = read_mesh(&bad).unwrap_err().to_string();
    assert!(
        msg.contains("bad.off") && msg.contains("line 6") && msg.contains("refers to vertex 7"),
        "{msg}"
    );
    let missing = read_mesh(dir.join("missing.ply")).unwrap_err();
    assert!(matches!(missing, Error::Io { .. }) && missing.to_string().contains("missing.ply"));
    let unknown = read_mesh(dir.join("mesh.stl")).unwrap_err();
    assert!(matches!(unknown, Error::UnknownFormat { .. }) && unknown.to_string().contains(".stl"));
    let map = dir.join("a_b.map");
    std::fs::write(&map, "1\n0\n").unwrap();
    let msg = read_map(&map).unwrap_err().to_string();
    assert!(msg.contains("a_b.map") && msg.contains("line 2"), "{msg}");

    let m = fmaps_shapes::icosphere(1.0, 1);
    for ext in ["off", "ply", "obj"] {
        let p = dir.join(format!("ico.{ext}"));
        write_mesh(&p, &m).unwrap();
        assert_eq!(read_mesh(&p).unwrap(), m, "{ext}");
    }
    write_map(dir.join("x.map"), &[3, 0, 1]).unwrap();
    assert_eq!(read_map(dir.join("x.map")).unwrap(), vec![3, 0, 1]);
    write_vts(dir.join("x.vts"), &[2, 2]).unwrap();
    assert_eq!(read_vts(dir.join("x.vts")).unwrap(), vec![2, 2]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn trimesh_new_rejects_invalid_arrays() {
    let e = TriMesh::new(vec![[0.0, f64::NAN, 0.0]], vec![[0, 0, 0]]).unwrap_err();
    assert!(matches!(
        e,
        Error::InvalidMesh {
            problem: MeshProblem::NonFiniteVertex { vertex: 0, .. },
            ..
        }
    ));
    let e = TriMesh::new(vec![[0.0; 3]; 3], vec![[0, 1, 3]]).unwrap_err();
    assert!(matches!(
        e,
        Error::InvalidMesh {
            problem: MeshProblem::FaceIndexOutOfRange {
                face: 0,
                index: 3,
                n_vertices: 3
            },
            ..
        }
    ));
    let e = TriMesh::new(vec![], vec![]).unwrap_err();
    assert!(matches!(
        e,
        Error::InvalidMesh {
            problem: MeshProblem::Empty { .. },
            ..
        }
    ));
}

/// Silent misreads: a UTF-8 byte-order mark is not
/// content (an OBJ used to lose its first vertex), carriage-return-only
/// line breaks are line breaks, and faces beyond the OFF header's count
/// are an error naming the line instead of being dropped.
#[test]
fn bom_cr_only_and_extra_faces() {
    let obj = "\u{feff}v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    assert_eq!(parse_obj(obj.as_bytes()).unwrap(), tet());
    let off = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
    assert_eq!(
        parse_off(format!("\u{feff}{off}").as_bytes()).unwrap(),
        tet()
    );
    assert_eq!(
        parse_off(off.replace('\n', "\r").as_bytes()).unwrap(),
        tet()
    );
    assert_eq!(
        parse_off(off.replace('\n', "\r\n").as_bytes()).unwrap(),
        tet()
    );
    parse_error_at(
        parse_off(format!("{off}3 0 1 2\n").as_bytes()),
        Location::Line(11),
        "more data after the 4 faces",
    );
    let mut ply = Vec::new();
    write_ply(&mut ply, &tet()).unwrap();
    let mut with_bom = b"\xEF\xBB\xBF".to_vec();
    with_bom.extend_from_slice(&ply);
    assert_eq!(parse_ply(&with_bom).unwrap(), tet());
    let map = b"\xEF\xBB\xBF3\n1\n2\n";
    assert_eq!(parse_index_list(map, ".map").unwrap(), vec![2, 0, 1]);
}

/// Data after the declared PLY elements is an error (a wrong count would
/// drop faces silently); a whole OFF on one line says what is wrong.
#[test]
fn extra_ply_faces_and_one_line_off() {
    let hdr = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    let body = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    assert!(parse_ply(format!("{hdr}{body}\n  \n").as_bytes()).is_ok());
    parse_error_at(
        parse_ply(format!("{hdr}{body}3 0 2 1\n").as_bytes()),
        Location::Line(14),
        "more data after the 2 elements",
    );
    let mut bin = Vec::new();
    write_ply(&mut bin, &tet()).unwrap();
    let n = bin.len();
    bin.extend_from_slice(&[3, 0, 0, 0, 0]);
    parse_error_at(
        parse_ply(&bin),
        Location::Byte(n),
        "5 more bytes after the 2 elements",
    );
    parse_error_at(
        parse_off(b"OFF 3 1 0 0 0 0 1 0 0 0 1 0 3 0 1 2\n"),
        Location::Line(1),
        "on a line of its own",
    );
}

/// Inputs are read up to a bound: a regular file over it is refused before
/// reading, a device that never ends after the bound.
#[test]
fn reads_are_bounded() {
    let dir = std::env::temp_dir().join(format!("fmaps-bounded-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("big.off");
    std::fs::write(&p, vec![b' '; 5000]).unwrap();
    assert!(matches!(
        read_bounded(&p, 4999),
        Err(Error::TooLarge { limit: 4999, .. })
    ));
    assert_eq!(read_bounded(&p, 5000).unwrap().len(), 5000);
    let zero = std::path::Path::new("/dev/zero");
    if zero.exists() {
        let e = read_bounded(zero, 1 << 20).unwrap_err();
        assert!(
            e.to_string()
                .contains("/dev/zero: larger than 1048576 bytes"),
            "{e}"
        );
    } else {
        use std::io::Write as _;
        let _ = writeln!(
            std::io::stderr(),
            "note: no /dev/zero here; the device case was skipped"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Landmark files: pairs or single indices, 1-based, errors with the line;
/// out-of-range pairs named by line and 1-based index.
#[test]
fn landmark_files() {
    let l = parse_landmarks(b"# a comment\n1 2\n\n5\n").unwrap();
    assert_eq!(l.pairs, vec![(0, 1), (4, 4)]);
    assert_eq!(l.lines, vec![2, 4]);
    parse_error_at(
        parse_landmarks(b"1 2\n0\n"),
        Location::Line(2),
        "'0' is not a 1-based",
    );
    parse_error_at(
        parse_landmarks(b"1 2 3\n"),
        Location::Line(1),
        "one or two vertex indices",
    );
    parse_error_at(parse_landmarks(b"x\n"), Location::Line(1), "'x'");
    let e = l.check(5, 4, None).unwrap_err();
    assert!(
        matches!(
            e,
            Error::IndexOutOfRange {
                line: 4,
                index: 5,
                n_vertices: 4,
                ..
            }
        ),
        "{e}"
    );
    assert!(l.check(5, 5, None).is_ok());
}

/// The coloured PLY reads back to the same geometry, bit for bit, extreme
/// coordinates included; the colours are on the vertex lines; a colour
/// count that is not the vertex count is an error.
#[test]
fn colored_ply_round_trips_the_geometry() {
    let specials = [0.0, -0.0, 1e300, -1e-300, 5e-324, 0.1, -7.25, 1.0 / 3.0];
    let vertices: Vec<[f64; 3]> = (0..24)
        .map(|i| {
            [
                specials[i % 8],
                specials[(i * 3 + 1) % 8] * i as f64,
                -(i as f64) / 7.0,
            ]
        })
        .collect();
    let faces: Vec<[usize; 3]> = (0..22).map(|i| [i, i + 1, i + 2]).collect();
    let mesh = TriMesh::new(vertices.clone(), faces.clone()).unwrap();
    let colors: Vec<[u8; 3]> = (0..24u8).map(|i| [i, 255 - i, i * 10]).collect();
    let mut bytes = Vec::new();
    write_colored_ply(&mut bytes, &mesh, &colors).unwrap();
    let m = parse_ply(&bytes).unwrap();
    assert_eq!(m.faces(), &faces[..]);
    for (a, b) in m.vertices().iter().zip(&vertices) {
        for c in 0..3 {
            assert_eq!(a[c].to_bits(), b[c].to_bits(), "{a:?} vs {b:?}");
        }
    }
    let text = String::from_utf8(bytes).unwrap();
    let body = text.split("end_header\n").nth(1).unwrap();
    for (line, c) in body.lines().zip(&colors) {
        let v: Vec<&str> = line.split(' ').collect();
        assert_eq!(v[3..], [c[0], c[1], c[2]].map(|x| x.to_string()));
    }
    let e = write_colored_ply(&mut Vec::new(), &mesh, &colors[1..]).unwrap_err();
    assert!(
        e.to_string().contains("23 vertex colours for 24 vertices"),
        "{e}"
    );
}
