//! No reader panics on arbitrary or mutated input, none allocates more
//! than a bound proportional to its input, and write-then-read is exact.
//!
//! A few hundred cases per property in `cargo test`; `cargo xtask fuzz`
//! runs 10,000 (`FMAPS_FUZZ_CASES`).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use fmaps_mesh_io::*;
use proptest::prelude::*;

/// The system allocator, counting the bytes each thread holds and its
/// peak, so that a parse's allocation can be bounded.
struct Counting;

thread_local! {
    static HELD: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

fn account(delta: isize) {
    // `try_with`: the thread's counters may already be gone at its exit.
    let _ = HELD.try_with(|h| {
        let now = h.get() + delta;
        h.set(now);
        let _ = PEAK.try_with(|p| p.set(p.get().max(now)));
    });
}

// SAFETY: every call is forwarded to `System` unchanged; only counters
// of plain integers are updated besides.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        account(layout.size() as isize);
        // SAFETY: the caller's contract is passed on to `System`.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        account(-(layout.size() as isize));
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        account(new_size as isize - layout.size() as isize);
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// The most bytes `f` holds at once beyond what was held before it.
fn peak_of<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let base = HELD.with(Cell::get);
    PEAK.with(|p| p.set(base));
    let r = f();
    (r, (PEAK.with(Cell::get) - base).max(0) as usize)
}

/// Allocation allowed for parsing `len` bytes: the densest encodings
/// (binary PLY with one-byte indices: 256 bytes give a 253-triangle fan
/// of 24 bytes each, doubled by vector growth) stay under 64 bytes of
/// output per input byte; 64 KiB covers the fixed costs.
fn allocation_bound(len: usize) -> usize {
    64 * len + (64 << 10)
}

fn cases() -> u32 {
    std::env::var("FMAPS_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(256)
}

fn valid_files() -> Vec<(Format, Vec<u8>)> {
    let m = fmaps_shapes::torus(2.0, 0.5, 4, 3);
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
    // Little endian with uchar indices and an extra element and property.
    let le_hdr = "ply\nformat binary_little_endian 1.0\ncomment x\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nproperty uchar red\nelement face 1\nproperty list uchar uchar vertex_indices\nelement edge 1\nproperty int a\nend_header\n";
    let mut le = le_hdr.as_bytes().to_vec();
    for p in [[0f64, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
        for c in p {
            le.extend_from_slice(&c.to_le_bytes());
        }
        le.push(7);
    }
    le.extend_from_slice(&[3, 0, 1, 2]);
    le.extend_from_slice(&5i32.to_le_bytes());
    out.push((Format::Ply, le));
    out
}

/// Valid correspondence and landmark files, to mutate.
fn valid_lists() -> Vec<Vec<u8>> {
    vec![
        b"1\n2\n3\n# comment\n\n10\n".to_vec(),
        b"1 2\n3\n  4   5  # pair\n".to_vec(),
    ]
}

/// Every parser of the crate on `data`: none may panic, each must stay
/// within [`allocation_bound`].
fn all_parsers(data: &[u8]) {
    let bound = allocation_bound(data.len());
    for f in [Format::Off, Format::Obj, Format::Ply] {
        let (_, peak) = peak_of(|| parse_mesh(data, f));
        assert!(
            peak <= bound,
            "{f:?}: {peak} bytes for {} input bytes",
            data.len()
        );
    }
    for kind in [".vts", ".map"] {
        let (_, peak) = peak_of(|| parse_index_list(data, kind));
        assert!(
            peak <= bound,
            "{kind}: {peak} bytes for {} input bytes",
            data.len()
        );
    }
    let (_, peak) = peak_of(|| parse_landmarks(data));
    assert!(
        peak <= bound,
        "landmarks: {peak} bytes for {} input bytes",
        data.len()
    );
    let (_, peak) = peak_of(|| fmaps_mesh_io::basis::parse_basis(data));
    assert!(
        peak <= bound,
        "basis cache: {peak} bytes for {} input bytes",
        data.len()
    );
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
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    #[test]
    fn basis_files_with_random_sizes_never_panic(n in any::<u64>(), k in any::<u64>(), tail in prop::collection::vec(any::<u8>(), 0..400)) {
        let mut data = b"FMAPS-BASIS-1\n".to_vec();
        data.extend_from_slice(&3u32.to_le_bytes());
        data.extend_from_slice(b"key");
        data.extend_from_slice(&n.to_le_bytes());
        data.extend_from_slice(&k.to_le_bytes());
        data.extend_from_slice(&tail);
        all_parsers(&data);
    }

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
        which in 0usize..6,
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
    fn mutated_lists_never_panic(
        which in 0usize..2,
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 1..8),
    ) {
        let mut data = valid_lists()[which].clone();
        for (at, byte, kind) in edits {
            let i = at.index(data.len().max(1)).min(data.len().saturating_sub(1));
            match kind {
                0 if !data.is_empty() => data[i] = byte,
                1 => data.insert(i, byte),
                _ if !data.is_empty() => { data.remove(i); }
                _ => {}
            }
        }
        all_parsers(&data);
    }

    /// Header counts far beyond the data allocate nothing near them.
    #[test]
    fn huge_declared_counts_stay_bounded(nv in 0u64..u64::MAX, nf in 0u64..u64::MAX, binary in any::<bool>()) {
        let off = format!("OFF\n{nv} {nf} 0\n0 0 0\n");
        all_parsers(off.as_bytes());
        let fmt = if binary { "binary_little_endian" } else { "ascii" };
        let ply = format!("ply\nformat {fmt} 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\nelement face {nf}\nproperty list uint int vertex_indices\nend_header\n0 0 0\n");
        all_parsers(ply.as_bytes());
    }

    #[test]
    fn landmarks_round_trip(pairs in prop::collection::vec((0usize..1_000_000, 0usize..1_000_000), 0..50)) {
        let text: String = pairs.iter().map(|(a, b)| format!("{} {}\n", a + 1, b + 1)).collect();
        prop_assert_eq!(parse_landmarks(text.as_bytes()).unwrap().pairs, pairs);
    }

    #[test]
    fn index_lists_round_trip(idx in prop::collection::vec(0usize..1_000_000, 0..100)) {
        let mut out = Vec::new();
        write_index_list(&mut out, &idx).unwrap();
        prop_assert_eq!(parse_index_list(&out, ".vts").unwrap(), idx);
    }
}
