//! The HTML viewer in a real browser: `fmaps render error --html` on a
//! generated pair, opened by headless Chromium (the distribution's
//! package; software WebGL). The page must load without console errors,
//! draw both shapes (screenshots that are not blank and differ between
//! the transfer and error views) and pick: a click on A selects a vertex
//! and marks its image on B (the identity map here, so the same index).
//!
//! Chromium is `$FMAPS_CHROMIUM`, else `chromium` or `chromium-browser`
//! on the PATH. Without it the test says it was skipped, unless
//! `FMAPS_REQUIRE_BROWSER=1` (CI installs Chromium and sets it).

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{fmaps, tmpdir};

fn chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("FMAPS_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    for dir in std::env::split_paths(&path) {
        for name in ["chromium", "chromium-browser"] {
            let p = dir.join(name);
            if p.is_file() {
                return Some(p);
            }
        }
    }
    None
}

/// Runs headless Chromium on `url` with `extra` (--dump-dom, --screenshot)
/// and returns (stdout, the console messages it logged).
fn browse(chrome: &Path, profile: &Path, url: &str, extra: &[&str]) -> (String, Vec<String>) {
    let out = Command::new(chrome)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--enable-logging=stderr",
            "--v=0",
            "--window-size=800,400",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .output()
        .expect("chromium runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    // Console messages, without the software renderer's performance notes.
    let console = stderr
        .lines()
        .filter(|l| l.contains(":CONSOLE") && !l.contains("GL Driver Message"))
        .map(str::to_string)
        .collect();
    (String::from_utf8_lossy(&out.stdout).into_owned(), console)
}

/// The value of attribute `name` of the status element in a dumped DOM.
fn status_attr(dom: &str, name: &str) -> Option<String> {
    let start = dom.find("id=\"status\"")?;
    let tag = &dom[start..start + dom[start..].find('>')?];
    let key = format!("{name}=\"");
    let at = tag.find(&key)? + key.len();
    Some(tag[at..at + tag[at..].find('"')?].to_string())
}

fn decode_png(path: &Path) -> (usize, usize, Vec<[u8; 3]>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(path).expect("a screenshot"),
    ));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let px = buf[..info.buffer_size()]
        .chunks_exact(channels)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    (info.width as usize, info.height as usize, px)
}

#[test]
fn the_viewer_draws_both_shapes_and_picks_in_a_real_browser() {
    let Some(chrome) = chromium() else {
        assert!(
            std::env::var("FMAPS_REQUIRE_BROWSER").as_deref() != Ok("1"),
            "FMAPS_REQUIRE_BROWSER=1 but no chromium was found (set FMAPS_CHROMIUM)"
        );
        eprintln!("skipped: no chromium on the PATH (the HTML viewer was not opened)");
        return;
    };
    let dir = tmpdir("viewer");
    // A: an ellipsoid; B: the same mesh bent; the identity map, exact truth.
    let a = fmaps::shapes::icosphere(1.0, 3);
    let bent: Vec<[f64; 3]> = a
        .vertices()
        .iter()
        .map(|p| [p[0] * 0.6 + 0.3 * p[1] * p[1], p[1] * 1.4, p[2] * 0.8])
        .collect();
    let b = fmaps::mesh_io::TriMesh::new(bent, a.faces().to_vec()).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("a.off"), &a).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("b.off"), &b).unwrap();
    let n = a.n_vertices();
    let id: Vec<usize> = (0..n).collect();
    fmaps::mesh_io::write_vts(dir.join("a.vts"), &id).unwrap();
    fmaps::mesh_io::write_map(dir.join("id.map"), &id).unwrap();
    let out = fmaps()
        .current_dir(&dir)
        .args(["render", "error", "--source", "a.off", "--target", "b.off"])
        .args([
            "--map",
            "id.map",
            "--gt-source",
            "a.vts",
            "--gt-target",
            "a.vts",
        ])
        .args(["--geodesic", "dijkstra", "--html", "view.html"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // --html alone writes the page, not the PNG.
    assert!(!dir.join("error.png").exists());
    let page = std::fs::read_to_string(dir.join("view.html")).unwrap();
    assert!(
        !page.contains("http://") && !page.contains("https://"),
        "the page must not load anything"
    );
    let url = format!("file://{}", dir.join("view.html").display());
    let profile = dir.join("profile");

    // Loads, draws, and a click near the middle of A's half picks a vertex
    // whose image (the identity) is marked on B.
    let (dom, console) = browse(
        &chrome,
        &profile,
        &format!("{url}#mode=error&click=200,150"),
        &["--dump-dom"],
    );
    assert!(console.is_empty(), "console messages: {console:#?}");
    assert_eq!(
        status_attr(&dom, "data-state").as_deref(),
        Some("ready"),
        "{dom}"
    );
    assert_eq!(status_attr(&dom, "data-mode").as_deref(), Some("error"));
    let click = status_attr(&dom, "data-click").expect("the click was handled");
    let picked: usize = click
        .parse()
        .unwrap_or_else(|_| panic!("the click missed A: {click}"));
    assert!(picked < n);
    assert_eq!(status_attr(&dom, "data-pick-b"), Some(picked.to_string()));
    assert!(dom.contains(&format!("vertex {picked} of A")));
    let errors = &dom[dom.find("<pre id=\"errors\">").unwrap()..];
    assert!(errors.starts_with("<pre id=\"errors\"></pre>"), "{errors}");

    // Screenshots of the two views: both shapes drawn, the views differ.
    let shot = |mode: &str| {
        let png = dir.join(format!("{mode}.png"));
        let (_, console) = browse(
            &chrome,
            &profile,
            &format!("{url}#mode={mode}"),
            &[&format!("--screenshot={}", png.display())],
        );
        assert!(console.is_empty(), "console messages: {console:#?}");
        decode_png(&png)
    };
    let (w, h, color) = shot("color");
    let (w2, h2, error) = shot("error");
    assert_eq!((w, h), (w2, h2));
    // Each half of the canvas (the band between the header and the
    // footer) has many coloured pixels: both shapes are drawn.
    for half in [0..w / 2, w / 2..w] {
        let drawn = (h / 4..3 * h / 4)
            .flat_map(|y| half.clone().map(move |x| y * w + x))
            .filter(|&i| {
                let [r, g, b] = color[i];
                r.abs_diff(g) > 20 || g.abs_diff(b) > 20 || r.abs_diff(b) > 20
            })
            .count();
        assert!(
            drawn > w * h / 100,
            "a half of the transfer view is blank ({drawn} coloured pixels)"
        );
    }
    let differ = color.iter().zip(&error).filter(|(p, q)| p != q).count();
    assert!(
        differ > w * h / 50,
        "the transfer and error views look the same ({differ} pixels differ)"
    );
}
