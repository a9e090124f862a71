//! The basic functional-map pipeline: two meshes in, a point map out.
//!
//! For shapes A (source) and B (target) it computes
//!
//! 1. the Laplace–Beltrami eigenbases of both ([`crate::spectrum`]),
//! 2. spectral descriptors (WKS or HKS from the first `k_descr` eigenpairs,
//!    optionally landmark descriptors), every column normalized to unit
//!    L² norm,
//! 3. the functional map `C_BA` (k x k, functions on B to functions on A)
//!    minimizing the energy of [`fmaps_solve::FmapEnergy`]: descriptor
//!    preservation, Laplacian commutativity (resolvent mask), descriptor
//!    commutativity and orientation preservation, with the first column
//!    fixed (constants to constants), solved exactly,
//! 4. the point map `T_AB` (a vertex of B for every vertex of A) by exact
//!    nearest neighbours in the spectral embedding,
//! 5. a refinement of `C_BA` and `T_AB` ([`Refinement`]: Smooth Shells by
//!    default, ZoomOut, ICP, discrete optimisation from `fmaps-refine`, or
//!    any [`fmaps_refine::Refiner`] through [`refine_result`]),
//! 6. with several initial sizes ([`Starts`]), one final map kept by a
//!    score without ground truth ([`fmaps_refine::starts`]).
//!
//! Each stage is a module here, in the order the pipeline runs them
//! (`prepare`, `fit`, `refining`, `single`, `starts`), each wiring the
//! crate that owns the stage; [`match_prepared`] reads top to bottom.
//!
//! The direction follows the dataset convention: the map file `A_B.map`
//! lists a B vertex per A vertex, and `T_AB` is read off `C_BA` (pull-back
//! of B's functions).
//!
//! [`MatchParams::default`] is what `fmaps match` runs: the initial map of
//! the literature's standard automatic pipeline, as pyFM ships it (100 WKS
//! descriptors from 128 eigenpairs, a 50 x 50 map, weights `descr = 0.1,
//! lap = 1e-3, dcomm = 1` with the resolvent mask (γ = 0.5) and pyFM's term
//! normalization, and the orientation term on (`orient = 1`; without it,
//! maps of left-right symmetric shapes flip)), refined by Smooth Shells on
//! 200 eigenpairs per shape.

use std::time::Instant;

use fmaps_mesh_io::TriMesh;

mod confidence;
mod error;
mod features;
mod fit;
mod from_map;
mod learned;
mod params;
mod prepare;
mod refinement;
mod refining;
mod result;
mod single;
mod starts;

pub use confidence::Confidence;
pub use error::MatchError;
pub use features::{LearnedFeatures, LearnedPointMap, LearnedShape};
use fit::Described;
pub use fit::{Fit, fit_descriptors};
pub use from_map::{RefinedMap, refine_point_map};
pub use params::{DescriptorKind, DescriptorOptions, Features, MatchParams, Starts};
pub use prepare::{PreparedShape, prepare, prepare_with_basis, shape_descriptors};
pub use refinement::{
    RefineOptions, RefineSampling, Refinement, RefinerKind, default_select_at, default_starts,
    named_refinement,
};
use refining::draw_samples;
pub use refining::refine_result;
pub use result::{MatchResult, MatchTimes, PassedOver, Start};
use single::match_described;
use starts::multi_start;

/// Memory the descriptor matrices of one shape may take (2 GiB).
const MAX_DESCRIPTOR_BYTES: usize = 1 << 31;

/// Runs the whole pipeline from source `a` to target `b`.
pub fn match_shapes(
    a: &TriMesh,
    b: &TriMesh,
    params: &MatchParams,
) -> Result<MatchResult, MatchError> {
    match_shapes_with_progress(a, b, params, &|_| {})
}

/// [`match_shapes`], calling `stage` with a short description as each
/// stage starts (for progress displays).
pub fn match_shapes_with_progress(
    a: &TriMesh,
    b: &TriMesh,
    params: &MatchParams,
    stage: &dyn Fn(&str),
) -> Result<MatchResult, MatchError> {
    params.check()?;
    stage("Laplacians and eigenbases of both shapes");
    let mut single = params.clone();
    single.spectrum.threads = 1;
    // The two shapes side by side, one thread each.
    let t = Instant::now();
    let (pa, pb) = rayon::join(|| prepare(a, &single), || prepare(b, &single));
    let spectra = t.elapsed().as_secs_f64();
    let name = |shape, e| match e {
        MatchError::Spectrum { source, .. } => MatchError::Spectrum { shape, source },
        MatchError::InvalidShape { message, .. } => MatchError::InvalidShape { shape, message },
        e => e,
    };
    let pa = pa.map_err(|e| name("source", e))?;
    let pb = pb.map_err(|e| name("target", e))?;
    stage(match params.refinement {
        Refinement::None => "descriptors, functional map, point map",
        _ => "descriptors, functional map, point map, refinement",
    });
    let mut out = match_prepared(&pa, &pb, params)?;
    out.times.spectra = spectra;
    out.times.total += spectra;
    Ok(out)
}

/// The pipeline on two prepared shapes (source `a`, target `b`), the
/// final map's [`Confidence`] included.
pub fn match_prepared(
    a: &PreparedShape,
    b: &PreparedShape,
    params: &MatchParams,
) -> Result<MatchResult, MatchError> {
    let mut out = match_map(a, b, params)?;
    let confidence = Confidence::of_map(&out.t_ab, a, b)?;
    out.times.total += confidence.seconds;
    out.confidence = Some(confidence);
    let Some(other) = &params.second_opinion else {
        return Ok(out);
    };
    let mut second = match_prepared(a, b, other)?;
    let area = |r: &MatchResult| r.confidence.map_or(f64::INFINITY, |c| c.area_distortion);
    let seconds = out.times.total + second.times.total;
    let features = |p: &MatchParams| match p.features {
        Features::Learned(_) => "learned",
        _ => "descriptors",
    };
    let passed = |r: &MatchResult, p: &MatchParams| PassedOver {
        features: features(p),
        refiner: r.refine.as_ref().map(|x| x.method.clone()),
        area_distortion: area(r),
        orientation: r.orientation,
    };
    // Ties keep this pipeline's map.
    let mut kept = if area(&second) < area(&out) {
        second.passed_over = Some(passed(&out, params));
        second
    } else {
        out.passed_over = Some(passed(&second, other));
        out
    };
    kept.times.total = seconds;
    Ok(kept)
}

/// [`match_prepared`] without the confidence.
fn match_map(
    a: &PreparedShape,
    b: &PreparedShape,
    params: &MatchParams,
) -> Result<MatchResult, MatchError> {
    params.check()?;
    let k = params.k;
    for (shape, s) in [("source", a), ("target", b)] {
        if s.basis.k() < params.k_process.max(k) {
            return Err(MatchError::InvalidParameter(format!(
                "the {shape} shape was prepared with {} eigenpairs, fewer than k_process = {}",
                s.basis.k(),
                params.k_process
            )));
        }
    }
    if let Features::Learned(l) = &params.features {
        return learned::match_learned(a, b, l, params);
    }
    for &(x, y) in &params.descriptors.landmarks {
        if x >= a.basis.n() || y >= b.basis.n() {
            return Err(MatchError::InvalidParameter(format!(
                "landmark ({x}, {y}) is outside the shapes ({} and {} vertices)",
                a.basis.n(),
                b.basis.n()
            )));
        }
    }
    // The descriptor matrices (n x columns) of the larger shape, and the
    // columns x columns Gram matrix of their compression, must fit.
    let d = &params.descriptors;
    let columns = d.n.saturating_mul(1 + d.landmarks.len()) / d.subsample;
    let bytes = columns
        .saturating_mul(a.basis.n().max(b.basis.n()).max(columns))
        .saturating_mul(8);
    if bytes > MAX_DESCRIPTOR_BYTES {
        return Err(MatchError::InvalidParameter(format!(
            "{} descriptors ({} samples x (1 + {} landmarks) / subsample {}) on {} vertices need {:.1} GB (with their Gram matrix), more than {} GB: use fewer landmarks or samples",
            columns,
            d.n,
            d.landmarks.len(),
            d.subsample,
            a.basis.n().max(b.basis.n()),
            bytes as f64 / 1e9,
            MAX_DESCRIPTOR_BYTES as f64 / 1e9
        )));
    }
    let t = Instant::now();
    let (da, db) = match &d.given {
        Some(given) => given_descriptors(a, b, given, d)?,
        None => {
            let lm_a: Vec<usize> = d.landmarks.iter().map(|p| p.0).collect();
            let lm_b: Vec<usize> = d.landmarks.iter().map(|p| p.1).collect();
            let (da, db) = rayon::join(
                || shape_descriptors(a, &lm_a, params),
                || shape_descriptors(b, &lm_b, params),
            );
            (da?, db?)
        }
    };
    // Checked and compressed once for every start.
    let described = Described::new(a, b, &da, &db, params)?;
    let seconds = t.elapsed().as_secs_f64();
    let (sampled, sampling_seconds) = draw_samples(a, b, params);
    let params = sampled.as_ref().unwrap_or(params);
    let mut out = if params.starts.sizes.is_empty() {
        let mut out = match_described(a, b, &described, params)?;
        out.times.descriptors += seconds;
        out.times.total += seconds;
        out
    } else {
        multi_start(a, b, &described, seconds, params)?
    };
    out.times.refine += sampling_seconds;
    out.times.total += sampling_seconds;
    Ok(out)
}

/// The user's descriptors ([`DescriptorOptions::given`]) checked against
/// the shapes: one row per vertex, the same columns on both, finite, no
/// landmarks besides.
fn given_descriptors(
    a: &PreparedShape,
    b: &PreparedShape,
    given: &(nalgebra::DMatrix<f64>, nalgebra::DMatrix<f64>),
    d: &DescriptorOptions,
) -> Result<(nalgebra::DMatrix<f64>, nalgebra::DMatrix<f64>), MatchError> {
    let bad = |m: String| Err(MatchError::InvalidParameter(m));
    let (da, db) = given;
    if !d.landmarks.is_empty() {
        return bad("landmarks add spectral landmark descriptors: with given descriptors, add landmark columns to them".into());
    }
    for (name, m, n) in [("A", da, a.basis.n()), ("B", db, b.basis.n())] {
        if m.nrows() != n {
            return bad(format!(
                "the descriptors of {name} have {} rows, the shape has {n} vertices (one row per vertex)",
                m.nrows()
            ));
        }
        if let Some(i) = m.iter().position(|x| !x.is_finite()) {
            return bad(format!(
                "the descriptors of {name}: entry ({}, {}) is not finite",
                i % m.nrows(),
                i / m.nrows()
            ));
        }
    }
    if da.ncols() != db.ncols() || da.ncols() == 0 {
        return bad(format!(
            "descriptors of A and B need the same number of columns (at least 1), got {} and {}",
            da.ncols(),
            db.ncols()
        ));
    }
    Ok((da.clone(), db.clone()))
}
