//! `fmaps eval`: a map's geodesic errors against ground truth.

use super::*;

pub(crate) fn eval(
    files: &EvalFiles,
    reverse_map: Option<&Path>,
    method: GeodesicMethod,
    json: bool,
) -> Result<(), Failure> {
    use fmaps::eval::{EvalParams, evaluate};
    let t = Instant::now();
    let EvalInputs { a, b, t_ab, gt, .. } = files.load()?;
    let t_ba = reverse_map
        .map(|p| read_indices(p, a.n_vertices(), false))
        .transpose()?;
    let spinner = Spinner::new(format!("{} geodesics on the target", method.name()));
    let solver = distance_solver(&b, &files.target, method)?;
    let r = evaluate(
        &b,
        solver.as_ref(),
        &t_ab,
        &gt,
        t_ba.as_deref(),
        &EvalParams::default(),
    )
    .map_err(input_on(&files.target))?;
    drop(spinner);
    let seconds = t.elapsed().as_secs_f64();
    if json {
        let v = json!({
            "mean_error": r.mean_error, "sym_mean_error": r.sym_mean_error, "auc": r.auc,
            "coverage": r.coverage, "bijectivity": r.bijectivity, "geodesic": r.geodesic,
            "seconds": seconds, "n_points": r.errors.len(),
            "thresholds": r.thresholds, "curve": r.curve,
        });
        return emit(&format!("{v}\n"));
    }
    let mut o = String::new();
    outln!(
        o,
        "{} ground-truth points, {} geodesics, {seconds:.3} s",
        r.errors.len(),
        r.geodesic
    );
    outln!(
        o,
        "mean error {:.6} (x100: {:.3})",
        r.mean_error,
        100.0 * r.mean_error
    );
    if let Some(s) = r.sym_mean_error {
        outln!(
            o,
            "symmetry-aware mean error {s:.6} (x100: {:.3})",
            100.0 * s
        );
    }
    outln!(
        o,
        "AUC on [0, 0.25]: {:.4}; coverage {:.4}",
        r.auc,
        r.coverage
    );
    if let Some(bij) = r.bijectivity {
        outln!(o, "bijectivity {bij:.4}");
    }
    emit(&o)
}
