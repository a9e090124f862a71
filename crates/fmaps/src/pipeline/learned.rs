//! Learned features in place of the descriptors: a trained feature
//! extractor ([`crate::learn::model::Model`], DiffusionNet) on each shape,
//! optionally adapted to the pair first ([`crate::learn::adapt`]), then
//! the initial point map either by nearest neighbours in feature space or
//! through the regularised functional-map layer the network was trained
//! with, then any refinement.

use std::borrow::Cow;
use std::sync::Arc;
use std::time::Instant;

use fmaps_learn::adapt::adapt;
use fmaps_learn::fmap_layer::FmapLayer;
use fmaps_learn::layers::Spectrum;
use fmaps_learn::train::TrainShape;
use fmaps_mesh_io::TriMesh;
use fmaps_solve::convert::{BasisRows, pullback};
use nalgebra::DMatrix;

use super::error::MatchError;
use super::features::{LearnedFeatures, LearnedPointMap, LearnedShape, learn_error, learned_shape};
use super::params::MatchParams;
use super::prepare::PreparedShape;
use super::refining::{initial_map, refine_and_orient};
use super::result::{MatchResult, MatchTimes};
use crate::solve;

/// The learned state of `s`: its own when it serves `learned`, else
/// computed now (a shape prepared without learned features, or for
/// another model or fewer eigenpairs).
fn state_of(
    s: &PreparedShape,
    learned: &LearnedFeatures,
    params: &MatchParams,
) -> Result<Arc<LearnedShape>, MatchError> {
    if let Some(l) = s.learned.as_ref().filter(|l| l.serves(learned)) {
        return Ok(Arc::clone(l));
    }
    let mesh = TriMesh::new(s.vertices.clone(), s.faces.clone()).map_err(|e| {
        MatchError::InvalidShape {
            shape: "input",
            message: e.to_string(),
        }
    })?;
    Ok(Arc::new(learned_shape(
        &mesh,
        &s.basis,
        params.spectrum.mass,
        learned,
    )?))
}

/// Rows scaled to unit length (zero rows stay zero): nearest rows are
/// then most cosine-similar.
fn unit_rows(f: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = f.clone();
    for mut r in out.row_iter_mut() {
        let n = r.norm();
        if n > 0.0 {
            r /= n;
        }
    }
    out
}

/// The pipeline with learned features (see the module docs).
pub(super) fn match_learned(
    a: &PreparedShape,
    b: &PreparedShape,
    learned: &LearnedFeatures,
    params: &MatchParams,
) -> Result<MatchResult, MatchError> {
    let k = params.k;
    let mut times = MatchTimes::default();
    let t = Instant::now();
    let (la, lb) = rayon::join(
        || state_of(a, learned, params),
        || state_of(b, learned, params),
    );
    let (la, lb) = (la?, lb?);
    let (fa, fb) = if learned.adaptation.steps == 0 {
        (Cow::Borrowed(&la.features), Cow::Borrowed(&lb.features))
    } else {
        let recipe = &learned.adaptation.recipe;
        let shape = |name: &str, s: &PreparedShape, l: &LearnedShape| {
            let t = TrainShape::from_operators(name, l.operators.clone(), l.input.clone(), recipe);
            if recipe.weights.dirichlet == 0.0 {
                return Ok(t);
            }
            // The Dirichlet term needs the positions and the stiffness.
            let mesh = TriMesh::new(s.vertices.clone(), s.faces.clone()).map_err(|e| {
                MatchError::InvalidShape {
                    shape: "input",
                    message: e.to_string(),
                }
            })?;
            t.with_geometry(&mesh).map_err(learn_error)
        };
        let (x, y) = (shape("source", a, &la)?, shape("target", b, &lb)?);
        let adapted = adapt(&learned.model, &x, &y, &learned.adaptation).map_err(learn_error)?;
        let m = &adapted.model;
        let (fa, fb) = rayon::join(
            || m.features_of(&la.operators, &la.input),
            || m.features_of(&lb.operators, &lb.input),
        );
        (Cow::Owned(fa), Cow::Owned(fb))
    };
    times.descriptors = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let (sb, sa) = (b.basis.truncate(k), a.basis.truncate(k));
    let (c_ba, t_ab) = match learned.point_map {
        LearnedPointMap::Features => {
            let (ua, ub) = (unit_rows(&fa), unit_rows(&fb));
            let t_ab = crate::nearest::nearest_rows(
                crate::nearest::view(&ub),
                crate::nearest::view(&ua),
                None,
                &crate::nearest::NnParams::default(),
            )
            .map_err(|e| MatchError::Solve(solve::Error::Search(e)))?;
            let c_ba = pullback(
                &t_ab,
                &BasisRows::new(&b.basis, k),
                k,
                &BasisRows::new(&a.basis, k),
                k,
                a.basis.mass.as_slice(),
            )?;
            (c_ba, t_ab)
        }
        LearnedPointMap::Spectral => {
            let f = learned.adaptation.recipe.fmap;
            let layer = FmapLayer {
                lambda: f.lambda,
                gamma: f.gamma,
            };
            let project = |s: &fmaps_eigensolve::SpectralBasis, f: &DMatrix<f64>| {
                Spectrum {
                    eigenvalues: &s.eigenvalues,
                    eigenvectors: &s.eigenvectors,
                    mass: &s.mass,
                }
                .project(f)
            };
            // C_BA takes B's coefficients to A's.
            let c_ba = layer
                .forward(
                    &project(&sb, &fb),
                    &project(&sa, &fa),
                    &sb.eigenvalues,
                    &sa.eigenvalues,
                )
                .map_err(learn_error)?;
            let t_ab = initial_map(&c_ba, a, b, params)?;
            (c_ba, t_ab)
        }
    };
    times.point_map = t.elapsed().as_secs_f64();
    times.total = times.descriptors + times.point_map;
    let metrics = solve::fmap_metrics(&c_ba, &sb.eigenvalues, &sa.eigenvalues)?;
    let mut out = MatchResult {
        t_ab_init: t_ab.clone(),
        t_ab,
        c_ba,
        refine: None,
        orientation: 0.0,
        starts: Vec::new(),
        metrics,
        energy_terms: solve::PerTerm::default(),
        energy: 0.0,
        times,
        confidence: None,
        passed_over: None,
    };
    refine_and_orient(&mut out, a, b, params)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::{Features, MatchParams, match_shapes};
    use fmaps_learn::model::{Architecture, Model, Preprocessing};

    fn small_model() -> Arc<Model> {
        let arch = Architecture {
            inputs: 16,
            width: 16,
            blocks: 2,
            outputs: 32,
        };
        let pre = Preprocessing {
            eigenpairs: 30,
            ..Preprocessing::default()
        };
        Arc::new(Model::new(arch, pre, 3))
    }

    fn learned_params(model: Arc<Model>, point_map: LearnedPointMap) -> MatchParams {
        let mut l = LearnedFeatures::new(model);
        l.point_map = point_map;
        let mut p = MatchParams::unrefined();
        p.k = 20;
        p.features = Features::Learned(l);
        p.k_process = p.k_process_needed();
        p
    }

    /// The pipeline's features map is the most cosine-similar vertex of
    /// the model's own features (its own unit-area scaling and
    /// eigensolve, a dense similarity matrix): two computations agree.
    #[test]
    fn features_map_is_the_most_similar_vertex() {
        let pair = fmaps_shapes::creature_pair(2);
        let model = small_model();
        let params = learned_params(Arc::clone(&model), LearnedPointMap::Features);
        assert_eq!(params.k_process, 30);
        let r = match_shapes(&pair.source, &pair.target, &params).unwrap();
        let fa = unit_rows(&model.features(&pair.source).unwrap());
        let fb = unit_rows(&model.features(&pair.target).unwrap());
        let sim = &fa * fb.transpose();
        let same = (0..sim.nrows())
            .filter(|&i| sim.row(i).transpose().argmax().0 == r.t_ab[i])
            .count();
        // Ties within the eigensolvers' rounding may go either way.
        assert!(
            same as f64 >= 0.99 * sim.nrows() as f64,
            "{same} of {} agree",
            sim.nrows()
        );
        assert_eq!(r.t_ab, r.t_ab_init, "no refinement asked");
        assert_eq!(r.c_ba.shape(), (20, 20));
    }

    /// The spectral map's C_BA is the layer's on the features projected
    /// onto the bases, and the map is the spectral conversion of it.
    #[test]
    fn spectral_map_is_the_layers() {
        let pair = fmaps_shapes::creature_pair(2);
        let model = small_model();
        let params = learned_params(Arc::clone(&model), LearnedPointMap::Spectral);
        let a = crate::pipeline::prepare(&pair.source, &params).unwrap();
        let b = crate::pipeline::prepare(&pair.target, &params).unwrap();
        let r = crate::pipeline::match_prepared(&a, &b, &params).unwrap();
        let (la, lb) = (a.learned.as_ref().unwrap(), b.learned.as_ref().unwrap());
        let (sa, sb) = (a.basis.truncate(20), b.basis.truncate(20));
        let proj = |s: &fmaps_eigensolve::SpectralBasis, f: &DMatrix<f64>| {
            s.eigenvectors.transpose() * DMatrix::from_diagonal(&s.mass) * f
        };
        let c = FmapLayer::default()
            .forward(
                &proj(&sb, &lb.features),
                &proj(&sa, &la.features),
                &sb.eigenvalues,
                &sa.eigenvalues,
            )
            .unwrap();
        assert!((&c - &r.c_ba).norm() < 1e-10 * c.norm());
        let t = solve::point_map_from_fmap(&c, &sb, &sa).unwrap();
        assert_eq!(t, r.t_ab);
    }

    /// A shape prepared for one model and matched with another gets the
    /// other's features: the map equals the one of shapes prepared for it.
    #[test]
    fn prepared_state_of_another_model_is_not_used() {
        let pair = fmaps_shapes::creature_pair(2);
        let first = learned_params(small_model(), LearnedPointMap::Features);
        let arch = small_model().architecture();
        let other = Arc::new(Model::new(arch, small_model().preprocessing, 11));
        let second = learned_params(Arc::clone(&other), LearnedPointMap::Features);
        let a = crate::pipeline::prepare(&pair.source, &first).unwrap();
        let b = crate::pipeline::prepare(&pair.target, &first).unwrap();
        let la = a.learned.as_ref().unwrap();
        let Features::Learned(l2) = &second.features else {
            unreachable!()
        };
        assert!(!la.serves(l2));
        let mut l3 = l2.clone();
        l3.model = Arc::new((*small_model()).clone());
        assert!(la.serves(&l3), "the same weights in another Arc");
        let r = crate::pipeline::match_prepared(&a, &b, &second).unwrap();
        let direct = match_shapes(&pair.source, &pair.target, &second).unwrap();
        let stale = crate::pipeline::match_prepared(&a, &b, &first).unwrap();
        assert_eq!(r.t_ab, direct.t_ab);
        assert_ne!(r.t_ab, stale.t_ab, "two models, two maps");
    }

    /// A second opinion keeps the less area-distorting of the two
    /// pipelines' maps, each the map its pipeline gives alone, and says
    /// which it passed over.
    #[test]
    fn a_second_opinion_keeps_the_less_distorting_map() {
        let pair = fmaps_shapes::creature_pair(3);
        let learned = learned_params(small_model(), LearnedPointMap::Features);
        let (na, nb) = (pair.source.n_vertices(), pair.target.n_vertices());
        let both = learned.clone().with_axiomatic_opinion(na, nb).unwrap();
        let other = both.second_opinion.as_deref().unwrap().clone();
        assert_eq!(other.k_process, both.k_process);
        assert!(matches!(other.features, Features::Descriptors));
        let a = crate::pipeline::prepare(&pair.source, &both).unwrap();
        let b = crate::pipeline::prepare(&pair.target, &both).unwrap();
        let r = crate::pipeline::match_prepared(&a, &b, &both).unwrap();
        let alone = MatchParams {
            k_process: both.k_process,
            ..learned
        };
        let l = crate::pipeline::match_prepared(&a, &b, &alone).unwrap();
        let d = crate::pipeline::match_prepared(&a, &b, &other).unwrap();
        let area = |r: &MatchResult| r.confidence.unwrap().area_distortion;
        let (kept, passed, name) = if area(&d) < area(&l) {
            (&d, &l, "learned")
        } else {
            (&l, &d, "descriptors")
        };
        assert_eq!(r.t_ab, kept.t_ab);
        let p = r.passed_over.as_ref().unwrap();
        assert_eq!(p.features, name);
        assert_eq!(p.area_distortion, area(passed));
        assert!(area(&r) <= p.area_distortion);
        // Both run on the same prepared shapes.
        let mut bad = both.clone();
        bad.second_opinion.as_mut().unwrap().k_process -= 1;
        let e = crate::pipeline::match_prepared(&a, &b, &bad).unwrap_err();
        assert!(e.to_string().contains("second opinion"), "{e}");
    }

    #[test]
    fn learned_features_refuse_what_they_cannot_use() {
        let pair = fmaps_shapes::creature_pair(1);
        let mut p = learned_params(small_model(), LearnedPointMap::Features);
        p.area_normalize = false;
        let e = match_shapes(&pair.source, &pair.target, &p).unwrap_err();
        assert!(e.to_string().contains("area normalisation"), "{e}");
        let mut p = learned_params(small_model(), LearnedPointMap::Features);
        p.descriptors.landmarks = vec![(0, 0)];
        let e = match_shapes(&pair.source, &pair.target, &p).unwrap_err();
        assert!(e.to_string().contains("landmarks"), "{e}");
        let mut p = learned_params(small_model(), LearnedPointMap::Features);
        p.k_process = 20;
        let e = match_shapes(&pair.source, &pair.target, &p).unwrap_err();
        assert!(e.to_string().contains("30 eigenpairs"), "{e}");
    }
}
