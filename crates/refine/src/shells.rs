//! Smooth Shells (Eisenberger, Lähner, Cremers, "Smooth Shells:
//! Multi-Scale Shape Registration with Functional Maps", CVPR 2020),
//! reconstructed from the paper.
//!
//! A *smooth shell* of size k is the surface rebuilt from the first
//! eigenfunctions of its Laplace–Beltrami operator with a sigmoid cut at
//! k: `X_k = Φ diag(s_k) Φᵀ M X`. Shape A (X) is deformed onto shape B (Y)
//! shell by shell, k growing from 20 to `k_max`: at each level,
//!
//! 1. **correspondences** in the product space of the deformed shell
//!    (coordinates), its normals and the spectral coordinates mapped by the
//!    current functional map (`Φ_X C` against `Φ_Y`, weighted by the
//!    previous shell's sigmoid), nearest neighbours in both directions;
//! 2. **deformation**: the displacement field `Φ_X[:, :k] τ` minimising the
//!    squared distances of both directions' correspondences, regularised
//!    by ARAP (local/global: rotations per vertex, then the least squares
//!    in τ; weight `0.02 √(k − 20)`);
//! 3. **functional map**: least squares on the correspondences (area
//!    weighted), projected to the nearest orthonormal matrix.
//!
//! **Initialisation** without descriptors (the paper's surrogate
//! search): a rigid alignment (main axes from the second eigenfunction,
//! the eight orientations about them refined by ICP about the main axis,
//! each scored by a short surrogate alignment over shells 2..20), then
//! proposals, each aligned over shells 6..20 and scored by the alignment
//! energy (area-weighted distance of matched points and normals, both
//! directions, at full detail). Each of the two best rigid orientations
//! gets the fixed proposals — the unperturbed shell, the input functional
//! map, and the sign hypotheses of φ_2..φ_5 (every choice of signs as the
//! first features' map, the paper's "eigenfunction sign choices") — and
//! 60 random coarse deformations `τ[:6]` (scaled by the shell's own
//! coefficients, half of them with Laplacian commutativity in the map
//! fit, as in the authors' code). Each orientation's best proposal (τ and
//! functional map, the map held fixed up to shell 20) runs the whole
//! alignment, and the orientation whose final map preserves orientation
//! best is kept: the surrogate cannot tell a body facing forwards from
//! one facing backwards, the folds of the wrong one's map can.
//! Proposals and orientations run in parallel. `reflect` aligns A's
//! mirror image instead (for a B that is a mirror image of A).
//!
//! **Landmarks**: with at least three landmark pairs
//! ([`crate::RefineInput::landmarks`]) the rigid alignment is the proper
//! rotation that best takes A's landmarks onto B's (Kabsch), and no
//! orientation is searched: the user's correspondence decides which way
//! round the shapes go, where the surrogate and the orientation screen
//! can only guess (symmetric bodies, different species).
//!
//! Between shapes that are not near-isometric (different builds) the
//! surrogate's two best orientations often miss the right one;
//! [`SmoothShells::non_isometric`] screens all eight by a short alignment
//! and keeps the two whose maps distort area least and fold least (area
//! distortion and orientation score together), and chooses the final map
//! by the same score; its initialisation runs on 500 samples with 30
//! random proposals per aligned orientation, so that it costs about the
//! default's time.
//!
//! Where this differs from the paper's description: the alignment levels
//! use `samples` farthest-point samples of each shape (the paper's
//! initialisation uses 1000 samples, its main run all vertices) and the
//! final map is computed on all vertices; the largest shell is 191 by
//! default (the paper: 500), so that the pipeline's 200 eigenpairs
//! suffice; the functional map fit uses the correspondences only (the
//! authors' code adds SHOT and HKS descriptor terms); the ARAP term is
//! the classic local/global one (per-vertex rotations by Procrustes, then
//! least squares in τ); the proposals are independent draws, the best
//! kept (optionally the best `finalists` run the whole alignment and the
//! lowest final energy wins); 60 random proposals for each of two
//! orientations instead of 100 for one (docs/benchmarks.md).

mod arap;
mod level;
mod posed;
mod rigid;
mod screen;
mod shell;

/// The smallest shell of the proposals.
const K_MIN: usize = 6;

/// What the main alignment works on: its samples of both shapes and the
/// ARAP Gram matrix of X.
#[derive(Clone, Copy)]
struct Main<'a> {
    samples: (&'a Samples<'a>, &'a Samples<'a>),
    gram: &'a DMatrix<f64>,
}

/// The landmark pairs, checked against the shapes' sizes.
fn input_landmarks(
    landmarks: &[(usize, usize)],
    na: usize,
    nb: usize,
) -> Result<&[(usize, usize)]> {
    if let Some(&(i, j)) = landmarks.iter().find(|&&(i, j)| i >= na || j >= nb) {
        return Err(Error::InvalidParameter(format!(
            "Smooth Shells: landmark ({i}, {j}) is outside the shapes ({na} and {nb} vertices)"
        )));
    }
    Ok(landmarks)
}

/// A proposal's result as the start of an alignment: its τ, and its
/// functional map held fixed up to shell 20.
fn as_start(a: Alignment) -> Alignment {
    Alignment {
        tau: a.tau,
        cfix: a.fmap.map(|f| f.c),
        fmap: None,
    }
}

use std::time::Instant;

use fmaps_eigensolve::SpectralBasis;
use fmaps_simd::SplitMix;
use nalgebra::{DMatrix, Matrix3, Vector3};
use rayon::prelude::*;

use crate::{Error, Iteration, RefineReport, Refined, Refiner, Result};
use level::{Alignment, LevelWeights, Samples};
use rigid::{align_vectors, axis_icp, axis_rotation};
use shell::Shell;

/// The Smooth Shells refiner (see the module docs). With its own
/// initialisation it needs no initial map: the input map is one of the
/// proposals, kept only if it aligns the shells best.
#[derive(Debug, Clone, PartialEq)]
pub struct SmoothShells {
    /// The largest shell (the paper: 500; here 191 by default, so that the
    /// pipeline's default 200 eigenpairs hold its sigmoid's tail: bases
    /// need `k_max + 9` eigenpairs).
    pub k_max: usize,
    /// Levels above shell 20 (the paper: 50, spaced as `20 + t⁴`).
    pub levels: usize,
    /// Farthest-point samples per shape in the alignment levels.
    pub samples: usize,
    /// Samples per shape in the initialisation (the paper: 1000).
    pub init_samples: usize,
    /// Random deformation proposals of the initialisation per orientation
    /// (the paper: 100, one orientation; here 60 for each of two),
    /// besides the unperturbed shell, the sign hypotheses and the input
    /// map.
    pub proposals: usize,
    /// Seed of the proposals (the result is deterministic for a seed).
    pub seed: u64,
    /// Align the shapes rigidly first (off: they are given aligned).
    pub rigid: bool,
    /// Rigid orientations (best first by their surrogate energy) that the
    /// initialisation tries: each runs the fixed and random proposals and
    /// the whole alignment from its best, and the one whose final map
    /// preserves orientation best is kept. The surrogate alignment tells a
    /// body facing forwards from one facing backwards poorly (on FAUST_r
    /// the best of its orientations was the wrong one for 7 pairs in 190);
    /// the orientation score of the final maps tells them apart.
    pub orientations: usize,
    /// B is a mirror image of A (the correspondence reverses orientation):
    /// A's reflection is aligned instead of A, so the map found reverses
    /// orientation (the pipeline's `orient_reversing` for the descriptor
    /// map). Off, a mirror image of an asymmetric shape is matched by an
    /// orientation-preserving map, and the orientation score of the
    /// result stays positive.
    pub reflect: bool,
    /// Add the input functional map as a proposal.
    pub use_input_map: bool,
    /// Proposals per orientation (best first by the initialisation's
    /// energy) that run the whole alignment; within an orientation the
    /// one with the lowest final energy is kept.
    pub finalists: usize,
    /// Eigenfunctions φ_2.. whose signs the initialisation tries in every
    /// combination (0: none; at most 5).
    pub sign_hypotheses: usize,
    /// Rigid orientations screened (0 or at most `orientations`: no
    /// screening, the surrogate's best `orientations` are used): each of
    /// the `screen` best by the surrogate gets the fixed proposals and an
    /// equal share of the random ones (the total stays `proposals` x
    /// `orientations`), its best proposal runs a short alignment (12
    /// levels on the initialisation's samples), and the `orientations`
    /// whose short alignment's map scores best run the whole alignment:
    /// with [`Select::AreaAndOrientation`] by the final choice's own score
    /// (area distortion and orientation score), else by the least area
    /// distortion ([`crate::area_distortion`]). A body aligned facing
    /// backwards, or with a leg on an arm, stretches the surface far more
    /// than the right alignment even between different builds, where the
    /// alignment energies are close; a map onto the mirror image of the
    /// right one (left and right swapped: TOSCA's cats, FAUST_r) can
    /// stretch it as little, but folds over (its orientation score is
    /// negative). See [`SmoothShells::non_isometric`].
    pub screen: usize,
    /// How the final maps of the orientations that ran the whole
    /// alignment are compared.
    pub select: Select,
}

/// How [`SmoothShells`] chooses among the final maps of its orientations
/// (none of these needs ground truth).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Select {
    /// The highest [`crate::orientation_score`]: the one that folds least.
    #[default]
    Orientation,
    /// The lowest [`crate::area_distortion`] minus
    /// [`crate::orientation_score`]: stretching and folding, both
    /// unitless and of the same order (area distortions ~0.3-0.7 and
    /// orientation scores ~0.5-0.9 between bodies of different builds).
    AreaAndOrientation,
}

impl Default for SmoothShells {
    fn default() -> Self {
        SmoothShells {
            k_max: 191,
            levels: 50,
            samples: 2000,
            init_samples: 1000,
            proposals: 60,
            seed: 1,
            rigid: true,
            orientations: 2,
            reflect: false,
            use_input_map: true,
            finalists: 1,
            sign_hypotheses: 4,
            screen: 0,
            select: Select::Orientation,
        }
    }
}

/// Shell sizes of the main alignment: 20, then `20 + round(t⁴)` for `t`
/// evenly spaced from 1 to `(k_max − 20)^(1/4)` (`levels` values).
fn schedule(k_max: usize, levels: usize) -> Vec<usize> {
    let mut ks = vec![20];
    if k_max > 20 && levels > 0 {
        let hi = ((k_max - 20) as f64).powf(0.25);
        for i in 0..levels {
            let t = if levels == 1 {
                hi
            } else {
                1.0 + (hi - 1.0) * i as f64 / (levels - 1) as f64
            };
            ks.push(20 + t.powi(4).round() as usize);
        }
    }
    ks
}

/// Surrogate alignment over `ks` from `state`; returns its energy.
#[allow(clippy::too_many_arguments)]
fn surrogate(
    x: &Shell<'_>,
    y: &Shell<'_>,
    shells: &[(usize, level::Shells)],
    sx: &Samples,
    sy: &Samples,
    align: LevelWeights,
    score: LevelWeights,
    state: &mut Alignment,
    report: &mut RefineReport,
) -> Result<f64> {
    let mut prev = None;
    for (k, sh) in shells {
        let w = LevelWeights {
            normals: if *k > 10 { align.normals } else { 0.0 },
            ..align
        };
        let found = level::level(x, y, sh, sx, sy, *k, &w, None, state, prev.as_ref(), report)?;
        prev = Some(found);
    }
    level::alignment_energy(x, y, sx, sy, state, &score, report)
}

fn merge(into: &mut RefineReport, from: &RefineReport) {
    into.nn_searches += from.nn_searches;
    into.nn_seconds += from.nn_seconds;
}

impl SmoothShells {
    fn check(&self, basis_a: &SpectralBasis, basis_b: &SpectralBasis) -> Result<()> {
        if self.k_max < 20 || self.samples == 0 || self.init_samples == 0 {
            return Err(Error::InvalidParameter(format!(
                "smooth shells: k_max {} (at least 20), samples {}, init samples {} (at least 1)",
                self.k_max, self.samples, self.init_samples
            )));
        }
        crate::check_k(basis_a, "A", self.k_max + 9)?;
        crate::check_k(basis_b, "B", self.k_max + 9)?;
        Ok(())
    }

    /// Rotations of `x` onto `y`, best first by a surrogate alignment:
    /// main axes, then eight orientations about them, each refined by ICP
    /// about the main axis.
    fn rigid_alignment(
        &self,
        x: &Shell<'_>,
        y: &Shell<'_>,
        sx: &Samples,
        sy: &Samples,
        input: &level::FeatureMap,
        report: &mut RefineReport,
    ) -> Result<Vec<Matrix3<f64>>> {
        let axis = |s: &Shell<'_>| {
            let v = Vector3::new(s.xi[(1, 0)], s.xi[(1, 1)], s.xi[(1, 2)]);
            if v.norm() > 0.0 {
                v.normalize()
            } else {
                Vector3::z()
            }
        };
        let (dx, dy) = (axis(x), axis(y));
        let r0 = align_vectors(&dx, &dy);
        let e = if dy.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let perp = dy.cross(&e).normalize();
        let mut candidates = Vec::new();
        for flip in [false, true] {
            for j in 0..4 {
                let f = if flip {
                    axis_rotation(&perp, std::f64::consts::PI)
                } else {
                    Matrix3::identity()
                };
                let turn = axis_rotation(&dy, std::f64::consts::FRAC_PI_2 * j as f64);
                candidates.push(turn * f * r0);
            }
        }
        let align = LevelWeights {
            features: 0.11,
            normals: 0.1,
            laplacian: 1.0,
            arap: 0.0,
        };
        let runs: Vec<Result<(f64, Matrix3<f64>, RefineReport)>> = candidates
            .par_iter()
            .map(|r| {
                let mut rep = RefineReport::start(String::new());
                let mut xr = x.clone_rotated(r);
                let r = axis_icp(&mut xr, y, sx, sy, &dy, 5, &mut rep)? * r;
                let shells: Vec<_> = (2..=20)
                    .map(|k| (k, level::Shells::new(&xr, y, k)))
                    .collect();
                let mut state = Alignment {
                    tau: DMatrix::zeros(self.k_max + 9, 3),
                    fmap: Some(input.clone()),
                    cfix: Some(input.c.clone()),
                };
                let e = surrogate(&xr, y, &shells, sx, sy, align, align, &mut state, &mut rep)?;
                Ok((e, r, rep))
            })
            .collect();
        let mut ranked = Vec::with_capacity(runs.len());
        for run in runs {
            let (e, r, rep) = run?;
            merge(report, &rep);
            ranked.push((e, r));
        }
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(ranked.into_iter().map(|(_, r)| r).collect())
    }

    /// The initialisation: for each orientation `xs` of X, the fixed
    /// proposals (the unperturbed shell, the input map, the sign
    /// hypotheses) and its share of the random proposals, all over shells
    /// 6..20. Returns, per orientation, its best `finalists` (their states
    /// after shell 20; [`as_start`] makes them starts), best first.
    fn initialise(
        &self,
        xs: &[Shell<'_>],
        y: &Shell<'_>,
        (sx, sy): (&Samples, &Samples),
        input: Option<&level::FeatureMap>,
        report: &mut RefineReport,
    ) -> Result<Vec<Vec<Alignment>>> {
        let kt = self.k_max + 9;
        let zero = || DMatrix::<f64>::zeros(kt, 3);
        let start = |tau, fmap| Alignment {
            tau,
            fmap,
            cfix: None,
        };
        let mut fixed = vec![start(zero(), None)];
        if let Some(fm) = input.filter(|_| self.use_input_map) {
            fixed.push(start(zero(), Some(fm.clone())));
        }
        // Sign hypotheses: the spectral coordinates φ_2..φ_m of X with every
        // choice of signs against Y's, as the features' map from the first
        // shell (intrinsic, so they hold across poses).
        if self.sign_hypotheses > 0 {
            let m = (self.sign_hypotheses + 1).min(K_MIN);
            let wm = level::shell_weights(m);
            let kk = wm.len();
            for bits in 0..1usize << (m - 1) {
                let mut c = DMatrix::<f64>::zeros(kk, kk);
                c[(0, 0)] = 1.0;
                for i in 1..m {
                    c[(i, i)] = if bits >> (i - 1) & 1 == 1 { -1.0 } else { 1.0 };
                }
                let fm = level::FeatureMap {
                    c,
                    k: m,
                    weights: wm.clone(),
                };
                fixed.push(start(zero(), Some(fm)));
            }
        }
        let n_fixed = fixed.len();
        let shells: Vec<Vec<_>> = xs
            .iter()
            .map(|x| {
                (K_MIN..=20)
                    .map(|k| (k, level::Shells::new(x, y, k)))
                    .collect()
            })
            .collect();
        let mut starts: Vec<(usize, Alignment, f64)> = (0..xs.len())
            .flat_map(|o| fixed.iter().map(move |a| (o, a.clone(), 0.0)))
            .collect();
        // Random coarse deformations (scaled by the shell's own
        // coefficients, which a rotation keeps), dealt to the orientations
        // in turn; every other one fits the map with Laplacian
        // commutativity.
        let sigma: Vec<f64> = (0..K_MIN)
            .map(|i| if i == 0 { 0.0 } else { xs[0].xi.row(i).norm() })
            .collect();
        let mut rng = SplitMix(self.seed);
        for i in 0..self.proposals * xs.len().min(self.orientations.max(1)) {
            let mut tau = zero();
            for r in 1..K_MIN {
                for d in 0..3 {
                    tau[(r, d)] = sigma[r] * rng.normal();
                }
            }
            let o = i % xs.len();
            let lap = if (n_fixed + i / xs.len()).is_multiple_of(2) {
                0.0
            } else {
                10.0
            };
            starts.push((o, start(tau, None), lap));
        }
        let ranked = self.proposals(xs, y, &shells, (sx, sy), starts, report)?;
        let mut best: Vec<Vec<Alignment>> = vec![Vec::new(); xs.len()];
        for (_, o, state) in ranked {
            if best[o].len() < self.finalists.max(1) {
                best[o].push(state);
            }
        }
        Ok(best)
    }

    /// The whole alignment of each orientation's finalists (orientations
    /// in parallel; within one, the lowest final energy wins), then the
    /// orientation whose final map scores best by [`SmoothShells::select`]
    /// (by default: preserves orientation best): a body
    /// aligned facing the wrong way fits the shells about as well, but
    /// its map folds over. Returns its state and its point map of Y onto
    /// X.
    fn finish(
        &self,
        xs: &[Shell<'_>],
        y: &Shell<'_>,
        finalists: Vec<Vec<Alignment>>,
        main: Main<'_>,
        init: (&Samples, &Samples),
        report: &mut RefineReport,
    ) -> Result<(Alignment, Vec<usize>)> {
        type Run = (f64, Alignment, Vec<usize>, RefineReport);
        let runs: Vec<Result<Run>> = finalists
            .into_par_iter()
            .enumerate()
            .map(|(o, starts)| {
                let mut rep = RefineReport::start(String::new());
                let x = &xs[o];
                let mut best: Option<(f64, Alignment)> = None;
                for start in starts {
                    let (e, state) =
                        self.align(x, y, main.samples, init, main.gram, start, &mut rep)?;
                    if best.as_ref().is_none_or(|b| e < b.0) {
                        best = Some((e, state));
                    }
                }
                let (_, state) = best.expect("at least one finalist");
                let map = Self::point_map(x, y, &state, self.k_max, &mut rep)?;
                let score = if xs.len() > 1 {
                    self.selection_score(&map, x, y)?
                } else {
                    0.0
                };
                Ok((score, state, map, rep))
            })
            .collect();
        let mut done: Vec<Run> = Vec::with_capacity(runs.len());
        for run in runs {
            let run = run?;
            merge(report, &run.3);
            done.push(run);
        }
        // The first of the best-oriented (a NaN score never wins).
        let mut kept = 0;
        for (o, run) in done.iter().enumerate() {
            if run.0 > done[kept].0 {
                kept = o;
            }
        }
        let (_, state, map, rep) = done.swap_remove(kept);
        // The kept orientation's levels are the report's iterations.
        report.iterations.extend(rep.iterations);
        Ok((state, map))
    }

    /// Runs proposals `(orientation, state, Laplacian weight)` over shells
    /// 6..20 in parallel; returns `(energy, orientation, state)`, best
    /// first.
    fn proposals(
        &self,
        xs: &[Shell<'_>],
        y: &Shell<'_>,
        shells: &[Vec<(usize, level::Shells)>],
        (sx, sy): (&Samples, &Samples),
        starts: Vec<(usize, Alignment, f64)>,
        report: &mut RefineReport,
    ) -> Result<Vec<(f64, usize, Alignment)>> {
        let runs: Vec<Result<(f64, usize, Alignment, RefineReport)>> = starts
            .into_par_iter()
            .map(|(o, mut state, lap)| {
                let mut rep = RefineReport::start(String::new());
                let align = LevelWeights {
                    features: 1.5,
                    normals: 0.04,
                    laplacian: lap,
                    arap: 0.0,
                };
                let score = LevelWeights {
                    features: 0.11,
                    ..align
                };
                let e = surrogate(
                    &xs[o], y, &shells[o], sx, sy, align, score, &mut state, &mut rep,
                )?;
                Ok((e, o, state, rep))
            })
            .collect();
        let mut ranked = Vec::with_capacity(runs.len());
        for run in runs {
            let (e, o, state, rep) = run?;
            merge(report, &rep);
            ranked.push((e, o, state));
        }
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(ranked)
    }

    /// The point map of Y onto X (an X vertex per Y vertex, all vertices)
    /// of an alignment state, in the product space of shell `k`.
    fn point_map(
        x: &Shell<'_>,
        y: &Shell<'_>,
        state: &Alignment,
        k: usize,
        report: &mut RefineReport,
    ) -> Result<Vec<usize>> {
        let fm = state.fmap.as_ref().expect("at least one level ran");
        let wk = level::shell_weights(k);
        let shell = x.shell(&wk);
        let cur = level::Posed::new(x.deform(&shell, &state.tau, fm.k), x.faces, x.orient);
        let ys = level::Posed::new(y.shell(&wk), y.faces, y.orient);
        let all_x = Samples::all(x, true);
        let all_y = Samples::all(y, false);
        let (_, t_ba) = level::correspondences(
            &cur.at(&all_x),
            &ys.at(&all_y),
            (&all_x, &all_y),
            &LevelWeights::MAIN,
            Some(fm),
            false,
            None,
            report,
        )?;
        Ok(t_ba)
    }

    /// The coarse-to-fine alignment from an initialisation; returns its
    /// final energy and state.
    #[allow(clippy::too_many_arguments)]
    fn align(
        &self,
        x: &Shell<'_>,
        y: &Shell<'_>,
        (sx, sy): (&Samples, &Samples),
        (ix, iy): (&Samples, &Samples),
        gram: &DMatrix<f64>,
        mut state: Alignment,
        report: &mut RefineReport,
    ) -> Result<(f64, Alignment)> {
        let mut prev: Option<(Vec<usize>, Vec<usize>)> = None;
        let mut w = LevelWeights::MAIN;
        for k in schedule(self.k_max, self.levels) {
            let t = Instant::now();
            w.arap = 0.02 * (k.saturating_sub(20) as f64).sqrt();
            let shells = level::Shells::new(x, y, k);
            let found = level::level(
                x,
                y,
                &shells,
                sx,
                sy,
                k,
                &w,
                Some(gram),
                &mut state,
                prev.as_ref(),
                report,
            )?;
            report.iterations.push(Iteration {
                k: (k, k),
                changed: crate::count_changed(prev.as_ref().map(|p| p.1.as_slice()), &found.1),
                seconds: t.elapsed().as_secs_f64(),
            });
            prev = Some(found);
        }
        let score = LevelWeights {
            features: 0.11,
            ..w
        };
        let e = level::alignment_energy(x, y, ix, iy, &state, &score, report)?;
        Ok((e, state))
    }
}

/// The first `k` eigenvectors of `b`: borrowed when that is all of them
/// (an n x k copy otherwise).
fn first_columns(b: &SpectralBasis, k: usize) -> std::borrow::Cow<'_, DMatrix<f64>> {
    if b.eigenvectors.ncols() == k {
        std::borrow::Cow::Borrowed(&b.eigenvectors)
    } else {
        std::borrow::Cow::Owned(b.eigenvectors.columns(0, k).into_owned())
    }
}

impl Refiner for SmoothShells {
    fn name(&self) -> String {
        let screen = if self.screen > self.orientations.max(1) {
            format!(
                ", {} orientations screened, {} aligned",
                self.screen,
                self.orientations.max(1)
            )
        } else {
            String::new()
        };
        let select = match self.select {
            Select::Orientation => "",
            Select::AreaAndOrientation => ", kept by area distortion and orientation",
        };
        format!(
            "smooth-shells 20:{} ({} levels, {} proposals{screen}{select})",
            self.k_max, self.levels, self.proposals
        )
    }

    fn k_needed(&self) -> usize {
        self.k_max + 9
    }

    fn refine(&self, input: &crate::RefineInput<'_>) -> Result<Refined> {
        let (c_ab, basis_a, basis_b) = (input.c_ab, input.basis_a, input.basis_b);
        let (geo_a, geo_b) = input.geometry_for("Smooth Shells")?;
        let t0 = Instant::now();
        self.check(basis_a, basis_b)?;
        crate::check_geometry(basis_a, basis_b, &geo_a, &geo_b)?;
        let landmarks = input_landmarks(input.landmarks, basis_a.n(), basis_b.n())?;
        let mut report = RefineReport::start(self.name());
        let kt = self.k_max + 9;
        // The first kt eigenvectors (borrowed when that is all of them:
        // an n x kt copy per shape otherwise).
        let (pa, pb) = (first_columns(basis_a, kt), first_columns(basis_b, kt));
        let mut x = Shell::new(
            geo_a.vertices,
            geo_a.faces,
            &pa,
            basis_a.mass.as_slice(),
            &basis_a.eigenvalues.as_slice()[..kt],
        );
        if self.reflect {
            // x -> -x (a linear map like the rotations; the normals stay
            // outward: they are oriented by the signed volume).
            x.rotate(&Matrix3::from_diagonal(&Vector3::new(-1.0, 1.0, 1.0)));
        }
        let y = Shell::new(
            geo_b.vertices,
            geo_b.faces,
            &pb,
            basis_b.mass.as_slice(),
            &basis_b.eigenvalues.as_slice()[..kt],
        );
        let fps = |s: &Shell<'_>, n: usize| {
            let mut v = crate::farthest_point_sampling(&s.verts, n, 0);
            v.sort_unstable();
            Samples::new(s, v)
        };
        let (ix, iy) = (fps(&x, self.init_samples), fps(&y, self.init_samples));
        // The input C_AB (k_B x k_A) as the features' map `Φ_X Cᵀ` of shell 20.
        let input = {
            let w20 = level::shell_weights(20);
            let f = w20.len().min(c_ab.nrows()).min(c_ab.ncols());
            level::FeatureMap {
                c: crate::icp::nearest_orthonormal(c_ab.view((0, 0), (f, f)).transpose()),
                k: 20.min(f),
                weights: w20[..f].to_vec(),
            }
        };
        let t = Instant::now();
        let rotations = if self.rigid && landmarks.len() >= 3 {
            // The user's landmarks fix the orientation: no search.
            let p: Vec<[f64; 3]> = landmarks.iter().map(|&(i, _)| x.verts[i]).collect();
            let q: Vec<[f64; 3]> = landmarks.iter().map(|&(_, j)| y.verts[j]).collect();
            vec![rigid::kabsch(&p, &q)]
        } else if self.rigid {
            self.rigid_alignment(&x, &y, &ix, &iy, &input, &mut report)?
        } else {
            vec![Matrix3::identity()]
        };
        let xs: Vec<Shell<'_>> = rotations
            .iter()
            .take(self.orientations.max(self.screen).max(1))
            .map(|r| x.clone_rotated(r))
            .collect();
        report.iterations.push(Iteration {
            k: (2, 20),
            changed: 0,
            seconds: t.elapsed().as_secs_f64(),
        });
        let t = Instant::now();
        let (sx, sy) = (fps(&x, self.samples), fps(&y, self.samples));
        let gram = level::arap_gram(&x, self.k_max);
        let main = Main {
            samples: (&sx, &sy),
            gram: &gram,
        };
        let ranked = self.initialise(&xs, &y, (&ix, &iy), Some(&input), &mut report)?;
        let (xs, ranked) = if self.screen > self.orientations.max(1) && xs.len() > 1 {
            self.screened(xs, &y, ranked, (&ix, &iy), &gram, &mut report)?
        } else {
            (xs, ranked)
        };
        let finalists: Vec<Vec<Alignment>> = ranked
            .into_iter()
            .map(|v| v.into_iter().map(as_start).collect())
            .collect();
        report.iterations.push(Iteration {
            k: (6, 20),
            changed: 0,
            seconds: t.elapsed().as_secs_f64(),
        });
        let (state, t_ba) = self.finish(&xs, &y, finalists, main, (&ix, &iy), &mut report)?;
        let fm = state.fmap.expect("at least one level ran");
        report.converged = true;
        report.seconds = t0.elapsed().as_secs_f64();
        Ok(Refined {
            c_ab: fm.c.transpose(),
            t_ba,
            report,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_schedule_grows_from_20_to_k_max() {
        let ks = schedule(500, 50);
        assert_eq!(ks.len(), 51);
        assert_eq!((ks[0], ks[1], *ks.last().unwrap()), (20, 21, 500));
        assert!(ks.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(schedule(20, 50), vec![20]);
    }

    #[test]
    fn normal_draws_have_unit_variance() {
        let mut r = SplitMix(7);
        let xs: Vec<f64> = (0..20000).map(|_| r.normal()).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        // 20000 draws: standard errors 0.007 (mean) and 0.01 (variance).
        assert!(
            mean.abs() < 0.03 && (var - 1.0).abs() < 0.04,
            "{mean} {var}"
        );
    }
}
