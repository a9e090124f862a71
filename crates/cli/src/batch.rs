//! `fmaps batch`: the pairs of a collection, resumable, each shape's
//! eigenbasis computed once (cached on disk), optionally one shard of a
//! job array.

use std::collections::HashMap;
use std::sync::Arc;

use fmaps::eigensolve::SpectralBasis;
use fmaps::mesh_io::basis::{BasisFile, read_basis, write_basis};
use fmaps::pipeline::{MatchParams, PreparedShape, match_prepared, prepare_with_basis};
use nalgebra::{DMatrix, DVector};
use serde_json::{Value, json};

use super::*;

/// Options of `fmaps batch`.
#[derive(clap::Args)]
pub(crate) struct BatchArgs {
    /// Pairs: two shape names per line (the datasets' test_pairs.txt);
    /// blank lines and lines starting with `#` are skipped.
    pairs: PathBuf,
    /// Folder of the meshes: NAME.off, NAME.obj or NAME.ply.
    #[arg(long)]
    data: PathBuf,
    /// Output folder (created): A_B.map (as `fmaps match --out`), A_B.json
    /// per pair, report.jsonl (every finished pair, in the file's order)
    /// and bases/ (the eigenbasis cache). Batches may share it (shards of
    /// one job, or the same shard twice): a pair or a basis one of them is
    /// working on is left to it (locks in .locks/), and the last to finish
    /// writes the whole report.
    #[arg(long)]
    out: PathBuf,
    /// This job's share `I/N` (1-based): pairs I, I + N, I + 2N, ... of the
    /// file, for a Slurm job array (`--shard $SLURM_ARRAY_TASK_ID/N`) or
    /// GNU parallel.
    #[arg(long)]
    shard: Option<String>,
    /// Folder of ground-truth files NAME.vts: adds each map's geodesic
    /// error (and NAME.sym.vts, when present, the symmetry-aware one).
    #[arg(long)]
    corres: Option<PathBuf>,
    /// Geodesics of the errors.
    #[arg(long, value_enum, default_value_t = GeodesicMethod::Exact)]
    geodesic: GeodesicMethod,
    /// Print the summary as one JSON object on stdout (pairs, matched,
    /// cached, failed, busy, seconds, report).
    #[arg(long)]
    json: bool,
    /// Options of `fmaps match` for every pair, after `--`
    /// (e.g. `-- --refine zoomout -k 30`).
    #[arg(last = true)]
    match_options: Vec<String>,
}

/// `fmaps match`'s options alone, parsed from `--` onwards.
#[derive(clap::Parser)]
#[command(name = "fmaps batch --")]
struct MatchOnly {
    #[command(flatten)]
    args: MatchArgs,
}

/// A pair of the file: its line and the two names.
struct Pair {
    line: usize,
    a: String,
    b: String,
}

/// `I/N` to (I − 1, N).
fn parse_shard(text: &str) -> Result<(usize, usize), Failure> {
    let bad = || {
        input(anyhow::anyhow!(
            "--shard {text}: expected I/N with 1 <= I <= N (e.g. 3/10)"
        ))
    };
    let (i, n) = text.split_once('/').ok_or_else(bad)?;
    let (i, n): (usize, usize) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if i == 0 || i > n {
        return Err(bad());
    }
    Ok((i - 1, n))
}

/// The pairs of the file (errors name the line).
fn read_pairs(path: &Path) -> Result<Vec<Pair>, Failure> {
    let bytes =
        fmaps::mesh_io::read_bounded(path, fmaps::mesh_io::MAX_INPUT_BYTES).map_err(input)?;
    let text = String::from_utf8(bytes)
        .map_err(|_| input(anyhow::anyhow!("{}: not UTF-8 text", path.display())))?;
    let mut pairs = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let names: Vec<&str> = t.split_whitespace().collect();
        let fine = |n: &str| !n.contains(['/', '\\']) && n != "." && n != "..";
        match names[..] {
            [a, b] if fine(a) && fine(b) => pairs.push(Pair {
                line: i + 1,
                a: a.to_string(),
                b: b.to_string(),
            }),
            _ => {
                return Err(input(anyhow::anyhow!(
                    "{}: line {}: expected two shape names (no path separators), got {t:?}",
                    path.display(),
                    i + 1
                )));
            }
        }
    }
    Ok(pairs)
}

/// The mesh file of shape `name` in `data` (exactly one of the formats).
fn mesh_path(data: &Path, name: &str, line: usize, pairs: &Path) -> Result<PathBuf, Failure> {
    let found: Vec<PathBuf> = ["off", "obj", "ply"]
        .iter()
        .map(|e| data.join(format!("{name}.{e}")))
        .filter(|p| p.is_file())
        .collect();
    match &found[..] {
        [p] => Ok(p.clone()),
        [] => Err(input(anyhow::anyhow!(
            "{}: line {line}: no {name}.off, .obj or .ply in {}",
            pairs.display(),
            data.display()
        ))),
        _ => Err(input(anyhow::anyhow!(
            "{}: line {line}: {name} is there in more than one format in {}",
            pairs.display(),
            data.display()
        ))),
    }
}

/// FNV-1a, 64 bits: the cache key of a mesh file's bytes.
fn fnv64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Loaded meshes and prepared shapes of this run, by name; prepared shapes
/// come from the disk cache when it holds them.
struct Shapes<'a> {
    args: &'a BatchArgs,
    pairs_file: &'a Path,
    meshes: HashMap<String, (Arc<TriMesh>, u64)>,
    prepared: HashMap<String, Arc<PreparedShape>>,
}

/// Prepared shapes kept in memory (most recently used first out of
/// consideration; the disk cache holds the rest).
const KEEP_PREPARED: usize = 16;

impl Shapes<'_> {
    fn mesh(&mut self, name: &str, line: usize) -> Result<(Arc<TriMesh>, u64), Failure> {
        if let Some(m) = self.meshes.get(name) {
            return Ok(m.clone());
        }
        let path = mesh_path(&self.args.data, name, line, self.pairs_file)?;
        // Read once: the bytes are both the cache key and the mesh.
        let format = fmaps::mesh_io::Format::from_path(&path).map_err(input)?;
        let bytes =
            fmaps::mesh_io::read_bounded(&path, fmaps::mesh_io::MAX_INPUT_BYTES).map_err(input)?;
        let mesh = Arc::new(
            fmaps::mesh_io::parse_mesh(&bytes, format).map_err(|e| input(e.with_path(&path)))?,
        );
        let entry = (mesh, fnv64(&bytes));
        self.meshes.insert(name.to_string(), entry.clone());
        Ok(entry)
    }

    /// The prepared shape and whether its basis came from the cache.
    fn prepared(
        &mut self,
        name: &str,
        line: usize,
        params: &MatchParams,
    ) -> Result<(Arc<PreparedShape>, bool), Failure> {
        if let Some(p) = self.prepared.get(name) {
            return Ok((Arc::clone(p), true));
        }
        let (mesh, hash) = self.mesh(name, line)?;
        let key = format!(
            "{name} {hash:016x} k_process={} mass={:?} backend={:?} area_normalize={}",
            params.k_process, params.spectrum.mass, params.spectrum.backend, params.area_normalize
        );
        let dir = self.args.out.join("bases");
        let stem = format!("{name}-{:016x}", fnv64(key.as_bytes()));
        let file = dir.join(format!("{stem}.npz"));
        // One process computes a basis at a time: another batch on the
        // same folder waits here, then finds it in the cache.
        let _lock = lock(&self.args.out, &format!("bases-{stem}"), true)?;
        let cached = read_basis(&file)
            .ok()
            .filter(|b| b.key == key && b.n() == mesh.n_vertices())
            .map(|b| SpectralBasis {
                eigenvectors: DMatrix::from_vec(b.n(), b.k(), b.vectors),
                eigenvalues: DVector::from_vec(b.eigenvalues),
                mass: DVector::from_vec(b.mass),
                report: {
                    let mut r = fmaps::eigensolve::SolveReport::default();
                    r.backend = "cache";
                    r
                },
            });
        let hit = cached.is_some();
        let mut single = params.clone();
        single.spectrum.threads = 1;
        let p = prepare_with_basis(&mesh, &single, cached).map_err(|e| {
            input(anyhow::anyhow!(
                "{}: {e}",
                mesh_path(&self.args.data, name, line, self.pairs_file)
                    .map_or_else(|_| name.to_string(), |p| p.display().to_string())
            ))
        })?;
        if !hit {
            std::fs::create_dir_all(&dir)
                .map_err(|e| runtime(anyhow::anyhow!("{}: {e}", dir.display())))?;
            let b = &p.basis;
            write_basis(
                &file,
                &BasisFile {
                    key,
                    eigenvalues: b.eigenvalues.as_slice().to_vec(),
                    mass: b.mass.as_slice().to_vec(),
                    vectors: b.eigenvectors.as_slice().to_vec(),
                },
            )
            .map_err(runtime)?;
        }
        if self.prepared.len() >= KEEP_PREPARED {
            self.prepared.clear();
        }
        let p = Arc::new(p);
        self.prepared.insert(name.to_string(), Arc::clone(&p));
        Ok((p, hit))
    }
}

pub(crate) fn batch(args: &BatchArgs) -> Result<(), Failure> {
    let parsed = MatchOnly::try_parse_from(
        ["fmaps batch --", "A", "B"]
            .into_iter()
            .map(String::from)
            .chain(args.match_options.iter().cloned()),
    )
    .map_err(|e| input(anyhow::anyhow!("match options after --: {e}")))?;
    let m = parsed.args;
    if m.descr_files.descr_source.is_some() {
        return Err(input(anyhow::anyhow!(
            "match options after --: --descr-source and --descr-target are one pair's descriptors (use fmaps match for each pair)"
        )));
    }
    if m.out.is_some() || m.save_fmap.is_some() || m.json {
        return Err(input(anyhow::anyhow!(
            "match options after --: --out, --save-fmap and --json are batch's own (A_B.map and A_B.json in --out)"
        )));
    }
    let all = read_pairs(&args.pairs)?;
    let (shard, shards) = args
        .shard
        .as_deref()
        .map(parse_shard)
        .transpose()?
        .unwrap_or((0, 1));
    // Every mesh of this shard must exist before any work starts.
    let mine: Vec<&Pair> = all.iter().skip(shard).step_by(shards).collect();
    for p in &mine {
        mesh_path(&args.data, &p.a, p.line, &args.pairs)?;
        mesh_path(&args.data, &p.b, p.line, &args.pairs)?;
    }
    std::fs::create_dir_all(&args.out)
        .map_err(|e| runtime(anyhow::anyhow!("{}: {e}", args.out.display())))?;
    remove_stale_temporaries(&args.out);
    remove_stale_temporaries(&args.out.join("bases"));
    let mut shapes = Shapes {
        args,
        pairs_file: &args.pairs,
        meshes: HashMap::new(),
        prepared: HashMap::new(),
    };
    let (mut done, mut skipped, mut failed) = (0usize, 0usize, 0usize);
    // The exit code of the failures: 2 if any pair had bad input, else 1.
    let mut code = 1;
    let mut busy = 0usize;
    let t0 = Instant::now();
    let progress = Progress::new(mine.len());
    for p in &mine {
        progress.show(done, skipped, failed, t0.elapsed().as_secs_f64());
        let stem = format!("{}_{}", p.a, p.b);
        if args.out.join(format!("{stem}.json")).is_file() {
            skipped += 1;
            continue;
        }
        // A pair another batch on the same folder is matching: left to it.
        let Some(_claim) = lock(&args.out, &format!("pair-{stem}"), false)? else {
            busy += 1;
            continue;
        };
        // Finished by another batch between the check and the claim.
        if args.out.join(format!("{stem}.json")).is_file() {
            skipped += 1;
            continue;
        }
        match run_pair(&mut shapes, &m, p, &stem) {
            Ok(()) => done += 1,
            Err(Failure(c, e)) => {
                failed += 1;
                code = code.max(c);
                progress.println(&format!("error: {stem} (line {}): {e:#}", p.line));
            }
        }
    }
    drop(progress);
    write_report(args, &all)?;
    let elsewhere = if busy > 0 {
        format!(" ({busy} left to another batch on this folder)")
    } else {
        String::new()
    };
    let seconds = t0.elapsed().as_secs_f64();
    let report = args.out.join("report.jsonl");
    eprintln!(
        "{} pairs in this shard ({}/{}): {done} matched, {skipped} already done, {failed} failed{elsewhere} in {seconds:.1} s; report: {}",
        mine.len(),
        shard + 1,
        shards,
        report.display()
    );
    if args.json {
        let summary = json!({
            "pairs": mine.len(), "shard": [shard + 1, shards], "matched": done,
            "cached": skipped, "failed": failed, "busy": busy, "seconds": seconds,
            "report": report.display().to_string(),
        });
        emit(&format!("{summary}\n"))?;
    }
    if failed > 0 {
        return Err(Failure(
            code,
            anyhow::anyhow!("{failed} pairs failed (exit code 2: bad input in at least one)"),
        ));
    }
    Ok(())
}

/// Matches one pair and writes its map, then its JSON (the mark of a
/// finished pair), both atomically.
fn run_pair(shapes: &mut Shapes<'_>, m: &MatchArgs, p: &Pair, stem: &str) -> Result<(), Failure> {
    let t = Instant::now();
    let (ma, _) = shapes.mesh(&p.a, p.line)?;
    let (mb, _) = shapes.mesh(&p.b, p.line)?;
    let params = match_cmd::params_of(m, (ma.n_vertices(), mb.n_vertices()))?;
    let (pa, hit_a) = shapes.prepared(&p.a, p.line, &params)?;
    let (pb, hit_b) = shapes.prepared(&p.b, p.line, &params)?;
    let r = match_prepared(&pa, &pb, &params).map_err(runtime)?;
    let quality = fmaps::eval::map_quality(&r.t_ab, &ma, &mb, None).map_err(runtime)?;
    let args = shapes.args;
    let errors = match &args.corres {
        Some(dir) => Some(errors(dir, &p.a, &p.b, &mb, &r.t_ab, args.geodesic)?),
        None => None,
    };
    let out = &args.out;
    fmaps::mesh_io::write_map(out.join(format!("{stem}.map")), &r.t_ab).map_err(runtime)?;
    let v = json!({
        "source": p.a, "target": p.b, "line": p.line,
        "n_source": ma.n_vertices(), "n_target": mb.n_vertices(),
        "bases": {"source": if hit_a { "cached" } else { "computed" },
                  "target": if hit_b { "cached" } else { "computed" }},
        "seconds": {"descriptors": r.times.descriptors, "operators": r.times.operators,
            "solve": r.times.solve, "point_map": r.times.point_map, "refine": r.times.refine,
            "pair": t.elapsed().as_secs_f64()},
        "refine": r.refine.as_ref().map(|rep| rep.method.clone()),
        "orientation": r.orientation,
        "confidence": r.confidence.map(|c| json!({
            "metric_distortion": c.distortion, "long_range": c.long_range,
            "area_distortion": c.area_distortion, "likely_wrong": c.likely_wrong,
        })),
        "quality": quality,
        "errors": errors,
    });
    let line = format!("{v}\n");
    fmaps::mesh_io::atomic::write_atomically(&out.join(format!("{stem}.json")), |w| {
        w.write_all(line.as_bytes())
    })
    .map_err(|e| runtime(anyhow::anyhow!("{}: {e}", out.display())))?;
    Ok(())
}

/// The map's geodesic errors against `dir`'s ground truth.
fn errors(
    dir: &Path,
    a: &str,
    b: &str,
    mesh_b: &TriMesh,
    t_ab: &[usize],
    method: GeodesicMethod,
) -> Result<Value, Failure> {
    let vts = |name: &str, ext: &str| dir.join(format!("{name}.{ext}"));
    let sym = vts(b, "sym.vts");
    let gt = fmaps::eval::GroundTruth::new(
        read_indices(&vts(a, "vts"), t_ab.len(), true)?,
        read_indices(&vts(b, "vts"), mesh_b.n_vertices(), true)?,
        if sym.is_file() {
            Some(read_indices(&sym, mesh_b.n_vertices(), true)?)
        } else {
            None
        },
    )
    .map_err(input)?;
    let solver = distance_solver(mesh_b, &vts(b, "vts"), method)?;
    let r = fmaps::eval::evaluate(
        mesh_b,
        solver.as_ref(),
        t_ab,
        &gt,
        None,
        &fmaps::eval::EvalParams::default(),
    )
    .map_err(runtime)?;
    Ok(json!({"mean": r.mean_error, "sym_mean": r.sym_mean_error, "geodesic": r.geodesic}))
}

/// Removes the temporary files (`.NAME.PID.K.tmp`) that a killed process
/// left in `dir`: those whose process no longer runs (Linux: no
/// `/proc/PID`). They are never read, only space; elsewhere they stay.
fn remove_stale_temporaries(dir: &Path) {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !(name.starts_with('.') && name.ends_with(".tmp")) {
            continue;
        }
        let parts: Vec<&str> = name.split('.').collect();
        let Some(pid) = parts
            .len()
            .checked_sub(3)
            .and_then(|i| parts[i].parse::<u32>().ok())
        else {
            continue;
        };
        if !proc.join(pid.to_string()).exists() {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// An exclusive lock on `out/.locks/NAME.lock`, held until the file is
/// dropped (the system releases it when the process ends, killed or not):
/// waiting for it with `wait`, else `None` when another process holds it.
fn lock(out: &Path, name: &str, wait: bool) -> Result<Option<std::fs::File>, Failure> {
    let dir = out.join(".locks");
    let fail = |e: std::io::Error, p: &Path| runtime(anyhow::anyhow!("{}: {e}", p.display()));
    std::fs::create_dir_all(&dir).map_err(|e| fail(e, &dir))?;
    let path = dir.join(format!("{name}.lock"));
    let file = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(|e| fail(e, &path))?;
    if wait {
        file.lock().map_err(|e| fail(e, &path))?;
        return Ok(Some(file));
    }
    match file.try_lock() {
        Ok(()) => Ok(Some(file)),
        Err(std::fs::TryLockError::WouldBlock) => Ok(None),
        Err(std::fs::TryLockError::Error(e)) => Err(fail(e, &path)),
    }
}

/// report.jsonl: the JSON line of every finished pair of the whole file
/// (all shards), in the file's order; rewritten atomically, under a lock,
/// so that of batches running side by side on one folder the last to
/// finish writes every line (each pair's JSON file is written before its
/// batch writes the report).
fn write_report(args: &BatchArgs, all: &[Pair]) -> Result<(), Failure> {
    let _lock = lock(&args.out, "report", true)?;
    let mut text = String::new();
    for p in all {
        let f = args.out.join(format!("{}_{}.json", p.a, p.b));
        if let Ok(line) = std::fs::read_to_string(&f) {
            text.push_str(line.trim_end());
            text.push('\n');
        }
    }
    let path = args.out.join("report.jsonl");
    fmaps::mesh_io::atomic::write_atomically(&path, |w| w.write_all(text.as_bytes()))
        .map_err(|e| runtime(anyhow::anyhow!("{}: {e}", path.display())))
}

/// The progress of a batch on a terminal: a bar counting the pairs done
/// (matched, cached, failed) with the time left, estimated from the pairs
/// matched in this run (cached ones take no time). Not drawn when stderr
/// is not a terminal (a log, a pipe): the summary line says it all there.
struct Progress(indicatif::ProgressBar);

impl Progress {
    fn new(pairs: usize) -> Progress {
        let bar = indicatif::ProgressBar::new(pairs as u64);
        if let Ok(style) =
            indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} pairs  {msg}")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        Progress(bar)
    }

    /// Before the next pair: counts and the estimate of the time left.
    fn show(&self, matched: usize, cached: usize, failed: usize, elapsed: f64) {
        let finished = matched + cached + failed;
        let worked = matched + failed;
        let left = self.0.length().unwrap_or(0) as usize
            - finished.min(self.0.length().unwrap_or(0) as usize);
        let eta = if worked > 0 {
            format!(
                ", about {} left",
                duration(elapsed / worked as f64 * left as f64)
            )
        } else {
            String::new()
        };
        self.0.set_position(finished as u64);
        self.0.set_message(format!(
            "{matched} matched, {cached} cached, {failed} failed; {} elapsed{eta}",
            duration(elapsed)
        ));
    }

    /// A line above the bar.
    fn println(&self, line: &str) {
        self.0.suspend(|| eprintln!("{line}"));
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}

/// Seconds as `1h02m`, `3m05s` or `42s`.
fn duration(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    if s >= 3600 {
        format!("{}h{:02}m", s / 3600, s % 3600 / 60)
    } else if s >= 60 {
        format!("{}m{:02}s", s / 60, s % 60)
    } else {
        format!("{s}s")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn durations_read_as_hours_minutes_seconds() {
        assert_eq!(super::duration(42.4), "42s");
        assert_eq!(super::duration(185.0), "3m05s");
        assert_eq!(super::duration(3720.0), "1h02m");
    }
}
