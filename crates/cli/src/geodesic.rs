//! `fmaps geodesic`: distances from source vertices.

use super::*;

pub(crate) fn geodesic(
    path: &Path,
    sources: &[usize],
    method: GeodesicMethod,
    out: Option<&Path>,
    json: bool,
) -> Result<(), Failure> {
    if let Some(out) = out {
        crate::outputs::check_outputs(&[path], &[out])?;
    }
    let mesh = load(path)?;
    let t = Instant::now();
    let solver = distance_solver(&mesh, path, method)?;
    let d = solver.distances(sources).map_err(input_on(path))?;
    let seconds = t.elapsed().as_secs_f64();
    if let Some(out) = out {
        let mut text = String::with_capacity(d.len() * 20);
        for x in &d {
            outln!(text, "{x:.17e}");
        }
        mesh_io::atomic::write_atomically(out, |w| w.write_all(text.as_bytes()))
            .with_context(|| format!("writing {}", out.display()))
            .map_err(runtime)?;
    }
    let max = d
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    let unreachable = d.iter().filter(|x| x.is_infinite()).count();
    if json {
        let v = json!({"mesh": path.display().to_string(), "method": solver.name(), "sources": sources,
            "seconds": seconds, "max_distance": max, "unreachable": unreachable});
        return emit(&format!("{v}\n"));
    }
    let mut o = String::new();
    outln!(
        o,
        "{}: {} distances from {} source(s) in {seconds:.3} s; max {max:.6}, {unreachable} unreachable",
        solver.name(),
        d.len(),
        sources.len()
    );
    if out.is_none() {
        for x in &d {
            outln!(o, "{x:.17e}");
        }
    }
    emit(&o)
}
