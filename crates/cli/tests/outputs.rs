//! The output policy through the command line: devices, FIFOs and links
//! named as outputs are written through and stay what they were; `-` is
//! standard output; one failing output leaves every output as it was;
//! bad output paths and parameters are refused (exit 2) before any work.
//!
//! The special files are made in the test's own folder (`mkfifo`, and
//! `mknod` where the user may create device nodes, e.g. as root); a test
//! that cannot make them says so on standard error, past the harness's
//! capture, and checks the rest.

mod common;

use std::io::{Read, Write};
use std::os::unix::fs::FileTypeExt;
use std::path::Path;
use std::process::Command;

use common::{fmaps, tmpdir};

/// A note printed past the test harness's capture (a skipped check must
/// show in a passing run).
fn note(text: &str) {
    let _ = writeln!(std::io::stderr(), "note: {text}");
}

/// The built-in creature pair at a small resolution in `dir` (a.off,
/// b.off), matched in well under a second; returns the source's vertex
/// count.
fn pair(dir: &Path) -> usize {
    let p = fmaps::shapes::creature_pair(2);
    fmaps::mesh_io::write_mesh(dir.join("a.off"), &p.source).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("b.off"), &p.target).unwrap();
    p.source.n_vertices()
}

/// `fmaps match a.off b.off --refine none -k 20 EXTRA` in `dir`.
fn match_in(dir: &Path, extra: &[&str]) -> std::process::Output {
    fmaps()
        .current_dir(dir)
        .args(["match", "a.off", "b.off", "--refine", "none", "-k", "20"])
        .args(["--k-process", "40"])
        .args(extra)
        .output()
        .unwrap()
}

/// Makes a special file with a system tool (`mkfifo P`, `mknod P c MAJ
/// MIN`); false when the tool or the permission is missing.
fn make(tool: &str, args: &[&str]) -> bool {
    Command::new(tool)
        .args(args)
        .output()
        .is_ok_and(|o| o.status.success())
}

fn is_char_device(p: &Path) -> bool {
    std::fs::symlink_metadata(p).is_ok_and(|m| m.file_type().is_char_device())
}

/// A map written into a FIFO reaches its reader, and the FIFO stays.
#[test]
fn a_fifo_is_written_through() {
    let dir = tmpdir("out-fifo");
    let n = pair(&dir);
    let fifo = dir.join("pipe.map");
    if !make("mkfifo", &[fifo.to_str().unwrap()]) {
        note("a_fifo_is_written_through: skipped, mkfifo is not available here");
        return;
    }
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            let mut s = String::new();
            std::fs::File::open(&fifo)
                .unwrap()
                .read_to_string(&mut s)
                .unwrap();
            s
        })
    };
    let out = match_in(&dir, &["--out", "pipe.map"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got = reader.join().unwrap();
    assert_eq!(got.lines().count(), n, "one line per source vertex");
    assert!(
        std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo(),
        "the FIFO was replaced"
    );
}

/// Device nodes made here (never the machine's `/dev` entries): a null
/// device takes the map (exit 0) and stays a device; a full one fails with
/// exit 1 naming it and the OS error, stays a device, and the other output
/// of the command keeps its old content.
#[test]
fn devices_are_written_through_and_a_full_one_fails_cleanly() {
    let dir = tmpdir("out-dev");
    pair(&dir);
    let (null, full) = (dir.join("null"), dir.join("full"));
    if !(make("mknod", &[null.to_str().unwrap(), "c", "1", "3"])
        && make("mknod", &[full.to_str().unwrap(), "c", "1", "7"]))
    {
        note(
            "devices_are_written_through_and_a_full_one_fails_cleanly: skipped, this user may not create device nodes (mknod)",
        );
        return;
    }
    let out = match_in(&dir, &["--out", "null"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(is_char_device(&null), "the device was replaced");
    std::fs::write(dir.join("C.txt"), "old").unwrap();
    let out = match_in(&dir, &["--out", "full", "--save-fmap", "C.txt"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("full") && err.contains("No space left"),
        "{err}"
    );
    assert!(is_char_device(&full), "the device was replaced");
    assert_eq!(std::fs::read_to_string(dir.join("C.txt")).unwrap(), "old");
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        names.iter().all(|n| !n.ends_with(".tmp")),
        "a temporary was left: {names:?}"
    );
}

/// A link named as the output: the file it points to gets the map, the
/// link stays a link.
#[test]
fn a_link_is_followed_not_replaced() {
    let dir = tmpdir("out-link");
    let n = pair(&dir);
    std::fs::create_dir(dir.join("maps")).unwrap();
    std::os::unix::fs::symlink("maps/real.map", dir.join("link.map")).unwrap();
    let out = match_in(&dir, &["--out", "link.map"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let link = std::fs::symlink_metadata(dir.join("link.map")).unwrap();
    assert!(link.file_type().is_symlink());
    let text = std::fs::read_to_string(dir.join("maps/real.map")).unwrap();
    assert_eq!(text.lines().count(), n);
}

/// `--out -`: the map alone on standard output (the report goes to
/// standard error), the same bytes as the file.
#[test]
fn dash_is_standard_output() {
    let dir = tmpdir("out-dash");
    pair(&dir);
    let out = match_in(&dir, &["--out", "-"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let file = match_in(&dir, &["--out", "file.map"]);
    assert!(file.status.success());
    assert_eq!(out.stdout, std::fs::read(dir.join("file.map")).unwrap());
    assert!(String::from_utf8_lossy(&out.stderr).contains("orientation"));
    // `/dev/stdout` (a link into /proc whose target is not a path): the
    // same, and the link is not touched.
    let dev = match_in(&dir, &["--out", "/dev/stdout"]);
    assert!(
        dev.status.success(),
        "{}",
        String::from_utf8_lossy(&dev.stderr)
    );
    assert_eq!(dev.stdout, out.stdout);
    // Standard output named twice is refused.
    let twice = match_in(&dir, &["--out", "-", "--save-fmap", "-"]);
    assert_eq!(twice.status.code(), Some(2));
}

/// Bad outputs and parameters are refused (exit 2) before anything is
/// written: every output keeps its old content.
#[test]
fn a_bad_output_or_parameter_leaves_every_output() {
    let dir = tmpdir("out-bad");
    pair(&dir);
    std::fs::write(dir.join("keep.map"), "old").unwrap();
    std::fs::create_dir(dir.join("adir")).unwrap();
    // The second output is a directory.
    let out = match_in(&dir, &["--out", "keep.map", "--save-fmap", "adir"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("adir"), "{err}");
    assert_eq!(
        std::fs::read_to_string(dir.join("keep.map")).unwrap(),
        "old"
    );
    // A folder that does not exist.
    let out = match_in(&dir, &["--out", "keep.map", "--save-fmap", "no/C.txt"]);
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(
        std::fs::read_to_string(dir.join("keep.map")).unwrap(),
        "old"
    );
    // Too few samples for the ZoomOut schedule: bad input, not a failure.
    let out = fmaps()
        .current_dir(&*dir)
        .args(["match", "a.off", "b.off", "--out", "keep.map"])
        .args(["--refine", "zoomout", "--zoomout", "10:30:5"])
        .args(["--refine-samples", "1", "--k-process", "40", "-k", "20"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("samples"), "{err}");
    assert_eq!(
        std::fs::read_to_string(dir.join("keep.map")).unwrap(),
        "old"
    );
    // `spectrum --out c.npy` whose third file would be a directory.
    std::fs::write(dir.join("c.npy"), "old").unwrap();
    std::fs::create_dir(dir.join("c_mass.npy")).unwrap();
    let out = fmaps()
        .current_dir(&*dir)
        .args(["spectrum", "a.off", "--k", "3", "--out", "c.npy"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("c_mass.npy"), "{err}");
    assert_eq!(std::fs::read_to_string(dir.join("c.npy")).unwrap(), "old");
    assert!(!dir.join("c_eigenvalues.npy").exists());
}
