//! Tidy tests: the rules of ARCHITECTURE.md that a machine can check, so
//! that the document stays true. Each names the files that break a rule.

use std::fs;
use std::path::{Path, PathBuf};

use fmaps_tests::workspace_root;

/// The files below `dir` that `keep` accepts (by path and file name), as
/// paths relative to the root with `/` separators, sorted. Build output,
/// git's folder, Python caches and hidden folders other than `.ci` are
/// not entered.
fn files_below(dir: &Path, keep: &dyn Fn(&Path, &str) -> bool) -> Vec<String> {
    fn walk(dir: &Path, keep: &dyn Fn(&Path, &str) -> bool, out: &mut Vec<PathBuf>) {
        let Ok(entries) = fs::read_dir(dir) else {
            return;
        };
        for e in entries.flatten() {
            let p = e.path();
            let name = e.file_name().to_string_lossy().into_owned();
            if p.is_dir() {
                let hidden = name.starts_with('.') && name != ".ci";
                if !(hidden || name == "target" || name == "__pycache__") {
                    walk(&p, keep, out);
                }
            } else if keep(&p, &name) {
                out.push(p);
            }
        }
    }
    let root = workspace_root();
    let mut files = Vec::new();
    walk(dir, keep, &mut files);
    let mut rel: Vec<String> = files
        .iter()
        .map(|p| {
            p.strip_prefix(&root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/")
        })
        .collect();
    rel.sort();
    // A walker that finds nothing would let every tidy rule pass.
    assert!(
        !rel.is_empty(),
        "no file found below {}: the tidy rules would check nothing",
        dir.display()
    );
    rel
}

/// Every `.rs` file of the workspace (crates, xtask, tests), as paths
/// relative to the root with `/` separators, sorted.
fn rust_files() -> Vec<String> {
    let root = workspace_root();
    let mut files = Vec::new();
    for top in ["crates", "xtask", "tests"] {
        files.extend(files_below(&root.join(top), &|p, _| {
            p.extension().is_some_and(|x| x == "rs")
        }));
    }
    files.sort();
    files
}

fn read(rel: &str) -> String {
    fs::read_to_string(workspace_root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The folders under `crates/`.
fn crate_dirs() -> Vec<String> {
    let mut dirs: Vec<String> = fs::read_dir(workspace_root().join("crates"))
        .unwrap()
        .flatten()
        .filter(|e| e.path().join("Cargo.toml").exists())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    dirs.sort();
    dirs
}

/// A line without its `//` comment and the contents of its string
/// literals (rough, but enough for keywords).
fn code_of(line: &str) -> String {
    let mut out = String::new();
    let mut in_str = false;
    let mut prev = ' ';
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        if in_str {
            if c == '"' && prev != '\\' {
                in_str = false;
            }
        } else if c == '"' {
            in_str = true;
        } else if c == '/' && chars.peek() == Some(&'/') {
            break;
        } else {
            out.push(c);
        }
        prev = if prev == '\\' && c == '\\' { ' ' } else { c };
    }
    out
}

/// Where `unsafe` may appear: the nearest-neighbour crate (AMX tiles,
/// target-feature kernels, the strided row view), the dispatch layer
/// (calls of target-feature functions after the CPU check) and its wedge
/// kernel, the ARPACK
/// binding, and the parsers' fuzz test (a counting global allocator).
const UNSAFE_ALLOWED: [&str; 5] = [
    "crates/nearest/",
    "crates/simd/src/lib.rs",
    "crates/simd/src/wedge.rs",
    "crates/eigensolve/src/arpack.rs",
    "crates/mesh-io/tests/proptest.rs",
];

/// The lines of `text` that use the `unsafe` keyword (blocks, functions,
/// impls, traits, extern blocks).
fn unsafe_lines(text: &str) -> Vec<usize> {
    let kw = concat!("un", "safe");
    text.lines()
        .enumerate()
        .filter(|(_, l)| {
            let code = code_of(l);
            code.match_indices(kw).any(|(i, _)| {
                let before = code[..i].chars().last();
                let after = code[i + kw.len()..].trim_start();
                !before.is_some_and(|c| c.is_alphanumeric() || c == '_')
                    && ["{", "fn", "impl", "trait", "extern"]
                        .iter()
                        .any(|t| after.starts_with(t))
            })
        })
        .map(|(i, _)| i + 1)
        .collect()
}

#[test]
fn unsafe_code_only_where_allowed() {
    let mut bad = Vec::new();
    for f in rust_files() {
        if UNSAFE_ALLOWED.iter().any(|a| f.starts_with(a)) {
            continue;
        }
        for line in unsafe_lines(&read(&f)) {
            bad.push(format!("{f}:{line}"));
        }
    }
    assert!(
        bad.is_empty(),
        "`unsafe` outside fmaps-nearest, fmaps-simd and the ARPACK binding (ARCHITECTURE.md, \"Unsafe code\"): {bad:?}"
    );
}

#[test]
fn the_unsafe_detector_sees_blocks_and_ignores_comments_and_strings() {
    let kw = concat!("un", "safe");
    let text = format!(
        "let a = {kw} {{ f() }};\n// {kw} {{ in a comment }}\nlet s = \"{kw} {{\";\n{kw} impl Send for X {{}}\nlet {kw}_name = 1;\n"
    );
    assert_eq!(unsafe_lines(&text), vec![1, 4]);
}

#[test]
fn crates_outside_the_allowed_ones_forbid_unsafe_code() {
    let mut bad: Vec<String> = Vec::new();
    for root in ["xtask/src/main.rs", "tests/src/lib.rs"] {
        if !read(root).contains("#![forbid(unsafe_code)]") {
            bad.push(format!("{root} lacks #![forbid(unsafe_code)]"));
        }
    }
    for dir in crate_dirs() {
        if dir == "nearest" || dir == "simd" {
            continue;
        }
        // The ARPACK binding, and PyO3's generated code (which allows
        // `unsafe` locally: `forbid` would reject it).
        let attr = if dir == "eigensolve" || dir == "python" {
            "#![deny(unsafe_code)]"
        } else {
            "#![forbid(unsafe_code)]"
        };
        for root in ["src/lib.rs", "src/main.rs"] {
            let rel = format!("crates/{dir}/{root}");
            if workspace_root().join(&rel).exists() && !read(&rel).contains(attr) {
                bad.push(format!("{rel} lacks {attr}"));
            }
        }
    }
    assert!(bad.is_empty(), "{bad:?}");
}

/// `[package] name = "..."` of a manifest.
fn package_name(manifest: &str) -> Option<String> {
    let pkg = manifest.split("[package]").nth(1)?;
    let line = pkg.lines().find(|l| l.trim_start().starts_with("name"))?;
    Some(line.split('"').nth(1)?.to_string())
}

#[test]
fn folder_names_are_package_names() {
    let mut bad = Vec::new();
    for dir in crate_dirs() {
        let name = package_name(&read(&format!("crates/{dir}/Cargo.toml"))).unwrap_or_default();
        let want = if dir == "fmaps" {
            "fmaps".to_string()
        } else {
            format!("fmaps-{dir}")
        };
        if name != want {
            bad.push(format!(
                "crates/{dir} publishes as {name:?}, expected {want:?}"
            ));
        }
    }
    assert!(bad.is_empty(), "{bad:?}");
}

#[test]
fn manifests_follow_the_workspace_conventions() {
    let mut bad = Vec::new();
    let mut manifests: Vec<String> = crate_dirs()
        .iter()
        .map(|d| format!("crates/{d}/Cargo.toml"))
        .collect();
    manifests.extend(["xtask/Cargo.toml".into(), "tests/Cargo.toml".into()]);
    for m in manifests {
        let text = read(&m);
        if !text.contains("[lints]\nworkspace = true") {
            bad.push(format!("{m}: no `[lints] workspace = true`"));
        }
        let published = !text.contains("publish = false");
        if published {
            let dir = m.trim_end_matches("Cargo.toml");
            if !text.contains("include = [") {
                bad.push(format!("{m}: published but sets no `include`"));
            }
            if workspace_root().join(dir).join("examples").is_dir()
                && !text.contains("\"examples/**/*.rs\"")
            {
                bad.push(format!("{m}: has examples/ that `include` leaves out"));
            }
            for f in ["README.md", "LICENSE-MIT", "LICENSE-APACHE"] {
                if !workspace_root().join(dir).join(f).exists() {
                    bad.push(format!("{m}: published without {f}"));
                }
            }
        }
    }
    assert!(bad.is_empty(), "{bad:?}");
}

/// The dependency names of a manifest's `[*dependencies]` tables, each
/// with whether it is taken from `[workspace.dependencies]`.
fn dependencies(manifest: &str) -> Vec<(String, bool)> {
    let mut out = Vec::new();
    let mut in_deps = false;
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            in_deps = line.ends_with("dependencies]");
            continue;
        }
        if !in_deps || line.starts_with('#') {
            continue;
        }
        if let Some((key, value)) = line.split_once('=') {
            let name = key.trim().split('.').next().unwrap_or("").to_string();
            let workspace = key.contains(".workspace") || value.contains("workspace = true");
            out.push((name, workspace));
        }
    }
    out
}

/// A dependency of more than one package comes from
/// `[workspace.dependencies]` (one version for all); the exceptions are
/// path-only development dependencies that must stay off the registry
/// (mesh-io's tests on fmaps-shapes, which builds on mesh-io; eval's tests
/// on itself with a feature).
#[test]
fn shared_dependencies_come_from_the_workspace() {
    const PATH_ONLY: [(&str, &str); 2] = [
        ("crates/mesh-io/Cargo.toml", "fmaps-shapes"),
        ("crates/eval/Cargo.toml", "fmaps-eval"),
    ];
    let mut manifests: Vec<String> = crate_dirs()
        .iter()
        .map(|d| format!("crates/{d}/Cargo.toml"))
        .collect();
    manifests.extend(["xtask/Cargo.toml".into(), "tests/Cargo.toml".into()]);
    let mut users: std::collections::BTreeMap<String, Vec<(String, bool)>> = Default::default();
    for m in &manifests {
        for (name, workspace) in dependencies(&read(m)) {
            users.entry(name).or_default().push((m.clone(), workspace));
        }
    }
    assert!(
        users.contains_key("rayon"),
        "the manifest reader found nothing"
    );
    let mut bad = Vec::new();
    for (name, uses) in &users {
        if uses.len() < 2 {
            continue;
        }
        for (m, workspace) in uses {
            if !workspace && !PATH_ONLY.contains(&(m.as_str(), name.as_str())) {
                bad.push(format!("{m}: {name} (used by {} packages)", uses.len()));
            }
        }
    }
    assert!(bad.is_empty(), "not from [workspace.dependencies]: {bad:?}");
}

#[test]
fn library_code_names_no_path_outside_the_repository() {
    let mut bad = Vec::new();
    for f in rust_files() {
        if !(f.starts_with("crates/") && f.contains("/src/")) {
            continue;
        }
        for (i, line) in read(&f).lines().enumerate() {
            if ["../shared", "/work/", "/home/", "/root/", "C:\\"]
                .iter()
                .any(|p| line.contains(p))
            {
                bad.push(format!("{f}:{}", i + 1));
            }
        }
    }
    assert!(bad.is_empty(), "paths outside the repository: {bad:?}");
}

/// Lines a source file may have without saying why at its top.
const LONG_FILE: usize = 800;

#[test]
fn long_files_say_why_at_their_top() {
    let mut bad = Vec::new();
    for f in rust_files() {
        let text = read(&f);
        let n = text.lines().count();
        let says_why = text.lines().take(40).any(|l| l.contains("tidy: long file"));
        if n > LONG_FILE && !says_why {
            bad.push(format!("{f} ({n} lines)"));
        }
    }
    assert!(
        bad.is_empty(),
        "files over {LONG_FILE} lines without a `tidy: long file` reason in their first 40 lines: {bad:?}"
    );
}

#[test]
fn architecture_md_names_every_crate() {
    let doc = read("ARCHITECTURE.md");
    let mut bad = Vec::new();
    for dir in crate_dirs() {
        let name = package_name(&read(&format!("crates/{dir}/Cargo.toml"))).unwrap_or_default();
        // The layout block lists `dir/` under `crates/` with the package.
        let listed = doc.lines().any(|l| {
            l.trim_start().starts_with(&format!("{dir}/")) && l.contains(&format!("`{name}`"))
        });
        if !listed {
            bad.push(format!("crates/{dir} ({name})"));
        }
    }
    assert!(bad.is_empty(), "ARCHITECTURE.md does not describe {bad:?}");
}

#[test]
fn code_comments_carry_no_benchmark_timings() {
    // Figures go stale in comments; they belong in docs/benchmarks.md or docs/tuning.md.
    let mut bad = Vec::new();
    for f in rust_files() {
        if !(f.starts_with("crates/") && f.contains("/src/")) {
            continue;
        }
        for (i, line) in read(&f).lines().enumerate() {
            let t = line.trim_start();
            if !(t.starts_with("//")) {
                continue;
            }
            let timing = t
                .split_whitespace()
                .collect::<Vec<_>>()
                .windows(2)
                .any(|w| {
                    w[0].trim_matches(|c: char| !c.is_ascii_digit() && c != '.')
                        .parse::<f64>()
                        .is_ok()
                        && [
                            "s", "ms", "s,", "ms,", "s)", "ms)", "s;", "ms;", "s.", "ms.",
                        ]
                        .contains(&w[1])
                });
            if timing {
                bad.push(format!("{f}:{}", i + 1));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "timings in code comments (move them to docs/benchmarks.md or docs/tuning.md): {bad:?}"
    );
}

/// Every text file a user or contributor reads (sources, manifests, docs,
/// scripts, CI), as paths relative to the root: what the repository says
/// about itself.
fn text_files() -> Vec<String> {
    files_below(&workspace_root(), &|p, name| {
        let ext = p.extension().map(|x| x.to_string_lossy().into_owned());
        matches!(
            ext.as_deref(),
            Some("rs" | "md" | "toml" | "py" | "pyi" | "sh" | "txt" | "json" | "yml" | "yaml")
        ) || name == "run"
    })
}

/// Phrases that narrate how the software was made rather than what it is
/// and does: numbered steps of the work, tracker numbers, records kept.
/// Built from pieces so that this file does not match itself.
fn process_phrases(line: &str) -> Option<String> {
    let l = line.to_lowercase();
    let numbered = |word: &str| {
        l.match_indices(word).any(|(i, _)| {
            let before = l[..i].chars().next_back();
            let after = l[i + word.len()..].chars().next();
            !before.is_some_and(|c| c.is_alphanumeric())
                && after.is_some_and(|c| c.is_ascii_digit())
        })
    };
    let session = concat!("sess", "ion");
    let issue = concat!("iss", "ue");
    for word in [
        format!("{session} "),
        format!("{session}s "),
        format!("{issue} "),
        format!("{issue}-"),
        format!("{issue} #"),
    ] {
        if numbered(&word) {
            return Some(word.trim().to_string());
        }
    }
    [
        format!("{issue}'s"),
        format!("this {session}"),
        format!("the {session}'s"),
        format!("earlier {session}"),
        concat!("kept for the ", "record").to_string(),
        concat!("for the ", "record").to_string(),
    ]
    .into_iter()
    .find(|phrase| l.contains(phrase))
}

#[test]
fn the_process_detector_sees_work_narration_and_spares_ordinary_words() {
    for bad in [
        concat!("measured in Sess", "ion 45 on the Xeon"),
        concat!("the iss", "ue 20 targets"),
        concat!("see iss", "ue-21"),
        concat!("as the iss", "ue's text asks"),
        concat!("tables kept for the ", "record"),
        concat!("before this ", "session"),
    ] {
        assert!(process_phrases(bad).is_some(), "{bad}");
    }
    for good in [
        "a session of the Python interpreter",
        "the llvm/llvm-project#133568 bug",
        "issues a warning when 2 faces coincide",
        "the session-wide cache",
    ] {
        assert!(process_phrases(good).is_none(), "{good}");
    }
}

#[test]
fn no_work_process_language_anywhere() {
    let files = text_files();
    assert!(
        files.len() > 100 && files.iter().any(|f| f == "README.md"),
        "the walk found {} files",
        files.len()
    );
    let mut bad = Vec::new();
    for f in &files {
        for (i, line) in read(f).lines().enumerate() {
            if let Some(p) = process_phrases(line) {
                bad.push(format!("{f}:{}: \"{p}\"", i + 1));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "the repository speaks about what the software is and does, not how it was made \
         (measurements: docs/benchmarks.md; history: CHANGELOG.md, by version): {bad:#?}"
    );
}

#[test]
fn user_docs_do_not_point_into_the_development_folder() {
    let docs: Vec<String> = text_files()
        .into_iter()
        .filter(|f| {
            f == "README.md"
                || f == "CHANGELOG.md"
                || (f.starts_with("docs/") && f.ends_with(".md"))
                || (f.starts_with("crates/") && f.ends_with("/README.md"))
        })
        .collect();
    assert!(
        docs.len() >= 15,
        "found only {} user-facing documents: {docs:?}",
        docs.len()
    );
    let mut bad = Vec::new();
    for f in &docs {
        for (i, line) in read(f).lines().enumerate() {
            if line.contains(concat!("../sha", "red")) {
                bad.push(format!("{f}:{}", i + 1));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "user-facing docs point into a development folder a user does not have \
         (say FMAPS_DATA, or name the public release): {bad:?}"
    );
}

/// The modules of one crate's `src/` and, per module, the sibling modules
/// it uses: `crate::m` names a top-level module, `super::m` a sibling in a
/// module folder. Comments and inline `mod tests` are left out; `lib.rs`
/// (the root, which declares every module) and test files are not nodes.
fn module_edges(
    src: &str,
) -> std::collections::BTreeMap<String, std::collections::BTreeSet<String>> {
    use std::collections::{BTreeMap, BTreeSet};
    let files: Vec<String> = rust_files()
        .into_iter()
        .filter(|f| f.starts_with(&format!("{src}/")))
        .collect();
    let mut text = BTreeMap::new();
    for f in &files {
        let rel = f[src.len() + 1..]
            .trim_end_matches(".rs")
            .replace('/', "::");
        if rel == "lib" || rel == "main" || rel == "tests" || rel.ends_with("::tests") {
            continue;
        }
        let body = read(f);
        let body = body
            .split("#[cfg(test)]\nmod tests")
            .next()
            .unwrap_or_default()
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        text.insert(rel, body);
    }
    let names_after = |t: &str, prefix: &str| -> BTreeSet<String> {
        t.match_indices(prefix)
            .map(|(i, _)| {
                t[i + prefix.len()..]
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect::<String>()
            })
            .collect()
    };
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (m, t) in &text {
        let top = m.split("::").next().unwrap_or(m).to_string();
        for n in names_after(t, "crate::") {
            if n != top && text.contains_key(&n) {
                edges.entry(top.clone()).or_default().insert(n);
            }
        }
        if let Some((parent, _)) = m.rsplit_once("::") {
            for n in names_after(t, "super::") {
                let sibling = format!("{parent}::{n}");
                if &sibling != m && text.contains_key(&sibling) {
                    edges.entry(m.clone()).or_default().insert(sibling);
                }
            }
        }
    }
    edges
}

/// A cycle of `edges`, if there is one.
fn a_cycle(
    edges: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
) -> Option<Vec<String>> {
    fn visit(
        u: &str,
        edges: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
        state: &mut std::collections::BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(u.to_string(), 1);
        path.push(u.to_string());
        for v in edges.get(u).into_iter().flatten() {
            match state.get(v) {
                Some(1) => {
                    let at = path.iter().position(|p| p == v).unwrap_or(0);
                    let mut cycle = path[at..].to_vec();
                    cycle.push(v.clone());
                    return Some(cycle);
                }
                Some(_) => {}
                None => {
                    if let Some(c) = visit(v, edges, state, path) {
                        return Some(c);
                    }
                }
            }
        }
        state.insert(u.to_string(), 2);
        path.pop();
        None
    }
    let mut state = std::collections::BTreeMap::new();
    for u in edges.keys() {
        if !state.contains_key(u)
            && let Some(c) = visit(u, edges, &mut state, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

#[test]
fn the_cycle_finder_sees_a_circle_and_passes_a_chain() {
    use std::collections::{BTreeMap, BTreeSet};
    let graph = |pairs: &[(&str, &str)]| {
        let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (a, b) in pairs {
            g.entry(a.to_string()).or_default().insert(b.to_string());
        }
        g
    };
    assert_eq!(
        a_cycle(&graph(&[
            ("cpu", "tiles"),
            ("tiles", "rows"),
            ("rows", "cpu")
        ])),
        Some(vec![
            "cpu".into(),
            "tiles".into(),
            "rows".into(),
            "cpu".into()
        ])
    );
    assert_eq!(a_cycle(&graph(&[("a", "b"), ("b", "c"), ("a", "c")])), None);
}

#[test]
fn modules_import_each_other_in_one_direction() {
    let mut bad = Vec::new();
    let mut modules = 0;
    for dir in crate_dirs() {
        let src = format!("crates/{dir}/src");
        let edges = module_edges(&src);
        modules += edges.len();
        if let Some(cycle) = a_cycle(&edges) {
            bad.push(format!("{src}: {}", cycle.join(" -> ")));
        }
    }
    assert!(modules > 20, "only {modules} modules with imports found");
    assert!(
        bad.is_empty(),
        "modules that import each other in a circle (move what both need into a leaf module): {bad:?}"
    );
}
