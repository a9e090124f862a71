//! No reader panics on arbitrary or mutated input; write-then-read is exact.

use fmaps_mesh_io::*;
use proptest::prelude::*;

fn valid_files() -> Vec<(Format, Vec<u8>)> {
    let m = generate::torus(2.0, 0.5, 4, 3);
    let mut out = Vec::new();
    let mut off = Vec::new();
    write_off(&mut off, &m).unwrap();
    out.push((Format::Off, off));
    let mut obj = Vec::new();
    write_obj(&mut obj, &m).unwrap();
    out.push((Format::Obj, obj));
    let mut ply = Vec::new();
    write_ply(&mut ply, &m).unwrap();
    out.push((Format::Ply, ply));
    let ascii_ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    out.push((Format::Ply, ascii_ply.as_bytes().to_vec()));
    let be_hdr = "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n";
    let mut be = be_hdr.as_bytes().to_vec();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
        for c in p {
            be.extend_from_slice(&c.to_be_bytes());
        }
    }
    be.push(3);
    for i in [0u32, 1, 2] {
        be.extend_from_slice(&i.to_be_bytes());
    }
    out.push((Format::Ply, be));
    out
}

fn all_parsers(data: &[u8]) {
    for f in [Format::Off, Format::Obj, Format::Ply] {
        let _ = parse_mesh(data, f);
    }
    let _ = parse_index_list(data, ".vts");
}

fn mesh_strategy() -> impl Strategy<Value = TriMesh> {
    (1usize..20).prop_flat_map(|nv| {
        (
            prop::collection::vec(
                prop::array::uniform3(
                    prop::num::f64::NORMAL | prop::num::f64::ZERO | prop::num::f64::SUBNORMAL,
                ),
                nv,
            ),
            prop::collection::vec(prop::array::uniform3(0..nv), 1..30),
        )
            .prop_map(|(v, f)| TriMesh::new(v, f).unwrap())
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(data in prop::collection::vec(any::<u8>(), 0..2000)) {
        all_parsers(&data);
    }

    #[test]
    fn random_text_never_panics(text in "(OFF|ply|v|f|format|element|property|end_header|[0-9 .\\-\n#e]){0,200}") {
        all_parsers(text.as_bytes());
    }

    #[test]
    fn mutated_files_never_panic(
        which in 0usize..5,
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 1..8),
        cut in any::<prop::sample::Index>(),
    ) {
        let files = valid_files();
        let (format, mut data) = files[which].clone();
        for (at, byte, kind) in edits {
            let i = at.index(data.len());
            match kind {
                0 => data[i] = byte,
                1 => data.insert(i, byte),
                _ => { data.remove(i); }
            }
        }
        let _ = parse_mesh(&data, format);
        let n = cut.index(data.len() + 1);
        let _ = parse_mesh(&data[..n], format);
        all_parsers(&data);
    }

    #[test]
    fn write_then_read_is_exact(m in mesh_strategy()) {
        let mut off = Vec::new();
        write_off(&mut off, &m).unwrap();
        prop_assert_eq!(&parse_off(&off).unwrap(), &m);
        let mut ply = Vec::new();
        write_ply(&mut ply, &m).unwrap();
        prop_assert_eq!(&parse_ply(&ply).unwrap(), &m);
        let mut obj = Vec::new();
        write_obj(&mut obj, &m).unwrap();
        prop_assert_eq!(&parse_obj(&obj).unwrap(), &m);
    }

    #[test]
    fn index_lists_round_trip(idx in prop::collection::vec(0usize..1_000_000, 0..100)) {
        let mut out = Vec::new();
        write_index_list(&mut out, &idx).unwrap();
        prop_assert_eq!(parse_index_list(&out, ".vts").unwrap(), idx);
    }
}
