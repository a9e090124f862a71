//! `fmaps train` from the command line: a run stopped and started again
//! continues from its checkpoint and writes the model a run never stopped
//! writes; a checkpoint of another run, a model file of another version,
//! a bad mesh and bad options are refused with exit 2.

mod common;

use std::path::Path;

use common::{fmaps, tmpdir};

/// The creature in two poses (642 vertices each) in `dir`.
fn shapes(dir: &Path) {
    let p = fmaps::shapes::creature_pair(3);
    fmaps::mesh_io::write_mesh(dir.join("rest.off"), &p.source).unwrap();
    fmaps::mesh_io::write_mesh(dir.join("walking.off"), &p.target).unwrap();
}

/// A small network and a short run.
const SMALL: [&str; 14] = [
    "--width",
    "8",
    "--blocks",
    "1",
    "--outputs",
    "24",
    "--inputs-wks",
    "8",
    "--eigenpairs",
    "24",
    "--fmap-k",
    "16",
    "--coupling-samples",
    "200",
];

fn train(dir: &Path, out: &str, extra: &[&str]) -> std::process::Output {
    fmaps()
        .current_dir(dir)
        .args([
            "--threads",
            "1",
            "train",
            "rest.off",
            "walking.off",
            "--out",
            out,
        ])
        .args(SMALL)
        .args(["--steps", "6", "--save-every", "2"])
        .args(extra)
        .output()
        .unwrap()
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn stopped_runs_resume_to_the_same_model() {
    let dir = tmpdir("train-resume");
    shapes(&dir);
    let whole = train(&dir, "whole.npz", &["--curve", "whole.png"]);
    assert!(whole.status.success(), "{}", stderr(&whole));
    assert!(dir.join("whole.png").is_file());
    // Three sittings of two steps each.
    for sitting in 0..3 {
        let o = train(&dir, "parts.npz", &["--stop-after", "2"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = stderr(&o);
        if sitting > 0 {
            assert!(
                text.contains(&format!(
                    "resuming parts.checkpoint.npz at step {}",
                    2 * sitting
                )),
                "{text}"
            );
        }
        if sitting < 2 {
            assert!(text.contains("run the same command again"), "{text}");
            assert!(!dir.join("parts.npz").exists());
        }
    }
    let a = fmaps::learn::model::Model::load(dir.join("whole.npz")).unwrap();
    let b = fmaps::learn::model::Model::load(dir.join("parts.npz")).unwrap();
    assert_eq!(
        a.net, b.net,
        "a resumed run differs from a run never stopped"
    );
    assert_eq!(a.provenance.get("steps").map(String::as_str), Some("6"));
    // The checkpoint is a model file too.
    fmaps::learn::model::Model::load(dir.join("parts.checkpoint.npz")).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_input_is_refused() {
    let dir = tmpdir("train-bad");
    shapes(&dir);
    // A checkpoint of another recipe.
    let o = train(&dir, "m.npz", &["--stop-after", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = train(&dir, "m.npz", &["--lr", "0.01"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("a checkpoint of another run"),
        "{}",
        stderr(&o)
    );
    // A model file of another version, as a checkpoint.
    let bytes = std::fs::read(dir.join("m.checkpoint.npz")).unwrap();
    let entries = fmaps::mesh_io::npz::read_archive(&bytes).unwrap();
    let mut edited: Vec<(String, Vec<u8>)> = Vec::new();
    for e in &entries {
        let mut data = e.data.to_vec();
        if e.name == "meta.npy" {
            let meta = fmaps::mesh_io::npy::parse_u8(&data).unwrap();
            let text = String::from_utf8(meta).unwrap();
            assert!(text.contains("\"version\": 1"), "{text}");
            data.clear();
            fmaps::mesh_io::npy::write_u8(
                &mut data,
                text.replace("\"version\": 1", "\"version\": 9").as_bytes(),
            )
            .unwrap();
        }
        edited.push((e.name.clone(), data));
    }
    let refs: Vec<(&str, &[u8])> = edited
        .iter()
        .map(|(n, d)| (n.as_str(), d.as_slice()))
        .collect();
    let mut out = Vec::new();
    fmaps::mesh_io::npz::write_archive(&mut out, &refs).unwrap();
    std::fs::write(dir.join("other.checkpoint.npz"), out).unwrap();
    let o = train(&dir, "other.npz", &[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let text = stderr(&o);
    assert!(
        text.contains("other.checkpoint.npz") && text.contains("version 9"),
        "{text}"
    );
    // A mesh that is not one.
    std::fs::write(dir.join("broken.off"), "OFF\n3 1 0\n0 0 0\n1 0 0\n").unwrap();
    let o = fmaps()
        .current_dir(&dir)
        .args(["train", "rest.off", "broken.off", "--out", "x.npz"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("broken.off"), "{}", stderr(&o));
    // One mesh, bad options.
    for args in [
        vec!["train", "rest.off", "--out", "y.npz"],
        vec![
            "train",
            "rest.off",
            "walking.off",
            "--out",
            "y.npz",
            "--coupling-samples",
            "0",
        ],
        vec![
            "train",
            "rest.off",
            "walking.off",
            "--out",
            "y.npz",
            "--steps",
            "0",
        ],
        vec!["train", "nowhere.off", "walking.off", "--out", "y.npz"],
    ] {
        let o = fmaps().current_dir(&dir).args(&args).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn coordinate_inputs() {
    let dir = tmpdir("train-xyz");
    shapes(&dir);
    let o = train(&dir, "xyz.npz", &["--input", "xyz", "--rotation", "y"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let m = fmaps::learn::model::Model::load(dir.join("xyz.npz")).unwrap();
    assert_eq!(m.preprocessing.input, fmaps::learn::model::Input::Xyz);
    assert_eq!(m.architecture().inputs, 3);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `fmaps match --features learned`: the shipped model maps a shape to
/// itself by the identity (a vertex's features are most similar to its
/// own), a trained model file is taken by path, adaptation runs, `fmaps
/// render features` draws either model's features; learned
/// options without learned features, a model file that is not one and
/// multi-start with learned features are refused with exit 2.
#[test]
fn match_with_learned_features() {
    let dir = tmpdir("match-learned");
    shapes(&dir);
    let run = |extra: &[&str]| {
        fmaps()
            .current_dir(&dir)
            .args([
                "--threads",
                "1",
                "match",
                "rest.off",
                "rest.off",
                "--out",
                "m.map",
            ])
            .args(["--json"])
            .args(extra)
            .output()
            .unwrap()
    };
    let o = run(&["--features", "learned", "--refine", "none"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["features"]["kind"], "learned");
    let t = fmaps::mesh_io::read_map(dir.join("m.map")).unwrap();
    let fixed = t.iter().enumerate().filter(|&(i, &x)| i == x).count();
    assert!(
        fixed as f64 >= 0.99 * t.len() as f64,
        "{fixed} of {}",
        t.len()
    );
    // The spectral point map, and the default refinement of learned maps.
    for extra in [
        &[
            "--features",
            "learned",
            "--point-map",
            "spectral",
            "-k",
            "30",
            "--refine",
            "none",
        ][..],
        &["--features", "learned"][..],
    ] {
        let o = run(extra);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert!(v["orientation"].as_f64().unwrap() > 0.9, "{extra:?}: {v}");
    }
    // A model of `fmaps train`, adapted to the pair for two steps.
    let o = train(&dir, "small.npz", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = fmaps()
        .current_dir(&dir)
        .args([
            "--threads",
            "1",
            "match",
            "rest.off",
            "walking.off",
            "--json",
        ])
        .args([
            "--features",
            "learned=small.npz",
            "--adapt",
            "2",
            "-k",
            "16",
            "--refine",
            "none",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["features"]["adapt"], 2);
    assert_eq!(v["features"]["adapt_dirichlet"], 0.0);
    // --non-isometric adds the Dirichlet term to the adaptation (which
    // needs the shapes' geometry: the run fails without it).
    let with = |extra: &[&str]| {
        let o = fmaps()
            .current_dir(&dir)
            .args([
                "--threads",
                "1",
                "match",
                "rest.off",
                "walking.off",
                "--json",
            ])
            .args([
                "--features",
                "learned=small.npz",
                "--adapt",
                "2",
                "-k",
                "16",
            ])
            .args(["--refine", "none"])
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    assert_eq!(
        with(&["--non-isometric"])["features"]["adapt_dirichlet"],
        fmaps::pipeline::LearnedFeatures::NON_ISOMETRIC_DIRICHLET
    );
    std::fs::write(dir.join("junk.npz"), b"not a model").unwrap();
    // The features as colours, of the shipped model and of a file.
    for extra in [&[][..], &["--model", "small.npz"][..]] {
        let o = fmaps()
            .current_dir(&dir)
            .args([
                "--threads",
                "1",
                "render",
                "features",
                "rest.off",
                "walking.off",
            ])
            .args(["--out", "f.png", "--json"])
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        assert!(std::fs::metadata(dir.join("f.png")).unwrap().len() > 1000);
    }
    let o = fmaps()
        .current_dir(&dir)
        .args(["render", "features", "rest.off", "--model", "junk.npz"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("junk.npz"), "{}", stderr(&o));
    for (extra, says) in [
        (&["--adapt", "3"][..], "--features learned"),
        (&["--point-map", "spectral"][..], "--features learned"),
        (&["--features", "learned=junk.npz"][..], "junk.npz"),
        (&["--features", "learned=absent.npz"][..], "absent.npz"),
        (&["--features", "wks"][..], "expected descriptors, learned"),
        (
            &["--features", "learned", "--starts", "8,20"][..],
            "one start",
        ),
    ] {
        let o = run(extra);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(says), "{extra:?}: {}", stderr(&o));
    }
}
