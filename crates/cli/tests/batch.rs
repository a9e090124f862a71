//! `fmaps batch`: every pair once, resumable, sharded, and batches side
//! by side on one folder.

mod common;

use common::{fmaps, tmpdir};

#[test]
fn batch_matches_every_pair_once_resumes_and_shards() {
    let dir = tmpdir("batch");
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    // Three shapes: the creature, its bent copy, and the copy scaled.
    let pair = fmaps::shapes::creature_pair(3);
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
    fmaps::mesh_io::write_mesh(data.join("rest.off"), &pair.source).unwrap();
    fmaps::mesh_io::write_mesh(data.join("walk.ply"), &pair.target).unwrap();
    fmaps::mesh_io::write_mesh(data.join("big.obj"), &pair.target.scaled(3.0).unwrap()).unwrap();
    let pairs = dir.join("pairs.txt");
    std::fs::write(&pairs, "# name name\nrest walk\n\nwalk big\nrest big\n").unwrap();
    let opts = [
        "--",
        "--refine",
        "none",
        "--k",
        "12",
        "--k-process",
        "30",
        "--n-descr",
        "30",
    ];
    let batch = |out: &std::path::Path, extra: &[&str]| {
        let o = fmaps()
            .args([
                "--threads",
                "2",
                "batch",
                &s(&pairs),
                "--data",
                &s(&data),
                "--out",
                &s(out),
            ])
            .args(extra)
            .args(opts)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let out = dir.join("out");
    let log = batch(&out, &[]);
    assert!(log.contains("3 matched, 0 already done, 0 failed"), "{log}");
    // One basis per shape, each computed once.
    assert_eq!(std::fs::read_dir(out.join("bases")).unwrap().count(), 3);
    let report = std::fs::read_to_string(out.join("report.jsonl")).unwrap();
    let lines: Vec<serde_json::Value> = report
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 3);
    let names: Vec<(&str, &str)> = lines
        .iter()
        .map(|v| (v["source"].as_str().unwrap(), v["target"].as_str().unwrap()))
        .collect();
    assert_eq!(names, [("rest", "walk"), ("walk", "big"), ("rest", "big")]);
    let computed = lines
        .iter()
        .flat_map(|v| [&v["bases"]["source"], &v["bases"]["target"]])
        .filter(|b| b.as_str() == Some("computed"))
        .count();
    assert_eq!(computed, 3);
    // The same map as `fmaps match` with the same options.
    let single = dir.join("single.map");
    let o = fmaps()
        .args([
            "match",
            &s(&data.join("walk.ply")),
            &s(&data.join("big.obj")),
        ])
        .args(["--out", &s(&single)])
        .args(&opts[1..])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |p: std::path::PathBuf| fmaps::mesh_io::read_map(p).unwrap();
    assert_eq!(read(single), read(out.join("walk_big.map")));
    // Killed after two pairs: the third runs again, from cached bases, to
    // the same map.
    let before = read(out.join("rest_big.map"));
    std::fs::remove_file(out.join("rest_big.json")).unwrap();
    let o = fmaps()
        .args(["--threads", "2", "batch", &s(&pairs), "--data", &s(&data)])
        .args(["--out", &s(&out), "--json"])
        .args(opts)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("1 matched, 2 already done"), "{log}");
    // Not a terminal: no progress bar, the one summary line.
    assert_eq!(log.lines().count(), 1, "{log}");
    // --json: the same summary on stdout.
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        (
            &summary["pairs"],
            &summary["matched"],
            &summary["cached"],
            &summary["failed"]
        ),
        (
            &serde_json::json!(3),
            &serde_json::json!(1),
            &serde_json::json!(2),
            &serde_json::json!(0)
        )
    );
    assert_eq!(read(out.join("rest_big.map")), before);
    let again = std::fs::read_to_string(out.join("rest_big.json")).unwrap();
    assert!(
        again.contains(r#""bases":{"source":"cached","target":"cached"}"#),
        "{again}"
    );
    // Two shards: each pair exactly once.
    let sharded = dir.join("sharded");
    batch(&sharded, &["--shard", "1/2"]);
    batch(&sharded, &["--shard", "2/2"]);
    let report = std::fs::read_to_string(sharded.join("report.jsonl")).unwrap();
    assert_eq!(report.lines().count(), 3);
    // A bad pairs line: exit code 2 naming the file and line.
    std::fs::write(&pairs, "rest walk\nrest\n").unwrap();
    let o = fmaps()
        .args(["batch", &s(&pairs), "--data", &s(&data), "--out", &s(&out)])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("pairs.txt: line 2: expected two shape names"),
        "{err}"
    );
}

/// Two batches on one folder at once, one killed midway, then a third to
/// finish: every pair matched once into the report (in the file's order,
/// no line lost, doubled or torn), every map and basis whole and equal to
/// a batch run alone, and no temporary left behind.
#[test]
fn side_by_side_batches_lose_nothing_when_one_is_killed() {
    let dir = tmpdir("batch-side");
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let pair = fmaps::shapes::creature_pair(3);
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
    let shapes = [
        ("rest", pair.source.clone()),
        ("walk", pair.target.clone()),
        ("big", pair.target.scaled(3.0).unwrap()),
        ("small", pair.source.scaled(0.5).unwrap()),
    ];
    for (name, m) in &shapes {
        fmaps::mesh_io::write_mesh(data.join(format!("{name}.off")), m).unwrap();
    }
    let mut names = Vec::new();
    for (a, _) in &shapes {
        for (b, _) in &shapes {
            if a != b {
                names.push((a.to_string(), b.to_string()));
            }
        }
    }
    let pairs = dir.join("pairs.txt");
    let text: String = names.iter().map(|(a, b)| format!("{a} {b}\n")).collect();
    std::fs::write(&pairs, text).unwrap();
    let batch = |out: &std::path::Path| {
        let mut c = fmaps();
        c.args(["--threads", "1", "batch", &s(&pairs), "--data", &s(&data)])
            .args(["--out", &s(out), "--", "--refine", "none", "--k", "12"])
            .args(["--k-process", "30", "--n-descr", "30"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped());
        c
    };
    // The reference: one batch alone.
    let alone = dir.join("alone");
    assert!(batch(&alone).status().unwrap().success());
    let out = dir.join("out");
    let mut first = batch(&out).spawn().unwrap();
    let second = batch(&out).spawn().unwrap();
    // Kill the first once some pair is finished (or it ended already).
    let t = std::time::Instant::now();
    while t.elapsed().as_secs() < 60 {
        let finished = std::fs::read_dir(&out).map_or(0, |d| {
            d.flatten()
                .filter(|e| e.file_name().to_string_lossy().ends_with(".json"))
                .count()
        });
        if finished > 0 || first.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let _ = first.kill();
    let killed = first.wait().unwrap();
    assert!(
        !killed.success(),
        "the first batch ended before it could be killed: the test needs more pairs"
    );
    let o = second.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // A third run finishes what the killed one left.
    let o = batch(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = std::fs::read_to_string(out.join("report.jsonl")).unwrap();
    let got: Vec<(String, String)> = report
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            (
                v["source"].as_str().unwrap().to_string(),
                v["target"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    assert_eq!(got, names, "every pair once, in the file's order");
    let read = |p: std::path::PathBuf| fmaps::mesh_io::read_map(p).unwrap();
    for (a, b) in &names {
        let f = format!("{a}_{b}.map");
        assert_eq!(read(out.join(&f)), read(alone.join(&f)), "{f}");
    }
    for e in std::fs::read_dir(out.join("bases")).unwrap().flatten() {
        let p = e.path();
        assert!(
            fmaps::mesh_io::basis::read_basis(&p).is_ok(),
            "{}: a damaged basis",
            p.display()
        );
    }
    assert_eq!(std::fs::read_dir(out.join("bases")).unwrap().count(), 4);
    // A truncated cache file is recomputed, never trusted: the pair run
    // again reports its bases computed and gives the same map.
    for e in std::fs::read_dir(out.join("bases")).unwrap().flatten() {
        let bytes = std::fs::read(e.path()).unwrap();
        std::fs::write(e.path(), &bytes[..bytes.len() / 2]).unwrap();
    }
    std::fs::remove_file(out.join("rest_walk.json")).unwrap();
    let o = batch(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let again = std::fs::read_to_string(out.join("rest_walk.json")).unwrap();
    assert!(
        again.contains(r#""bases":{"source":"computed","target":"computed"}"#),
        "{again}"
    );
    assert_eq!(
        read(out.join("rest_walk.map")),
        read(alone.join("rest_walk.map"))
    );
    for d in [out.clone(), out.join("bases")] {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let n = e.file_name().to_string_lossy().into_owned();
            assert!(!n.ends_with(".tmp"), "{n} left in {}", d.display());
        }
    }
}
