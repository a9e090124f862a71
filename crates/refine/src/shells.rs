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
//! directions, at full detail): the unperturbed shell; random coarse
//! deformations `τ[:6]` (scaled by the shell's own coefficients, half of
//! them with Laplacian commutativity in the map fit, as in the authors'
//! code); the sign hypotheses of φ_2..φ_6 (every choice of signs as the
//! first features' map, the "eigenfunction sign choices"); and
//! the input functional map. The best proposal's τ and functional map
//! start the full alignment (the map is held fixed up to shell 20).
//! Proposals and orientations run in parallel.
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
//! lowest final energy wins).

mod level;

use std::time::Instant;

use fmaps_eigensolve::SpectralBasis;
use nalgebra::{DMatrix, Matrix3, Vector3};
use rayon::prelude::*;

use crate::{Error, Iteration, RefineReport, Refined, Refiner, Result, ShapeGeometry};
use level::{Alignment, LevelWeights, Samples, Shell};

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
    /// Random deformation proposals of the initialisation (the paper:
    /// 100), besides the unperturbed shell, the sign hypotheses and the
    /// input map.
    pub proposals: usize,
    /// Seed of the proposals (the result is deterministic for a seed).
    pub seed: u64,
    /// Align the shapes rigidly first (off: they are given aligned).
    pub rigid: bool,
    /// Add the input functional map as a proposal.
    pub use_input_map: bool,
    /// Proposals (best first by the initialisation's energy) that run the
    /// whole alignment; the one with the lowest final energy is kept.
    pub finalists: usize,
    /// Eigenfunctions φ_2.. whose signs the initialisation tries in every
    /// combination (0: none; at most 5).
    pub sign_hypotheses: usize,
}

impl Default for SmoothShells {
    fn default() -> Self {
        SmoothShells {
            k_max: 191,
            levels: 50,
            samples: 2000,
            init_samples: 1000,
            proposals: 100,
            seed: 1,
            rigid: true,
            use_input_map: true,
            finalists: 1,
            sign_hypotheses: 5,
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

/// A small deterministic generator (SplitMix64) with normal draws.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn uniform(&mut self) -> f64 {
        ((self.next() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// Rotation by `angle` about the unit `axis` (Rodrigues).
fn axis_rotation(axis: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    let k = axis.cross_matrix();
    Matrix3::identity() * c + k * s + axis * axis.transpose() * (1.0 - c)
}

/// The rotation taking unit `a` to unit `b` (the shortest arc).
fn align_vectors(a: &Vector3<f64>, b: &Vector3<f64>) -> Matrix3<f64> {
    let v = a.cross(b);
    let c = a.dot(b);
    if v.norm() < 1e-12 {
        if c > 0.0 {
            return Matrix3::identity();
        }
        let e = if a.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        return axis_rotation(&a.cross(&e).normalize(), std::f64::consts::PI);
    }
    axis_rotation(&v.normalize(), v.norm().atan2(c))
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
    for (k, sh) in shells {
        let w = LevelWeights {
            normals: if *k > 10 { align.normals } else { 0.0 },
            ..align
        };
        level::level(x, y, sh, sx, sy, *k, &w, None, state, report)?;
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

    /// Rotates `x` onto `y`: main axes, then the best of eight
    /// orientations (each refined by ICP about the main axis) by a
    /// surrogate alignment.
    fn rigid_alignment(
        &self,
        x: &mut Shell<'_>,
        y: &Shell<'_>,
        sx: &Samples,
        sy: &Samples,
        input: &level::FeatureMap,
        report: &mut RefineReport,
    ) -> Result<()> {
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
        let mut best: Option<(f64, Matrix3<f64>)> = None;
        for run in runs {
            let (e, r, rep) = run?;
            merge(report, &rep);
            if best.as_ref().is_none_or(|b| e < b.0) {
                best = Some((e, r));
            }
        }
        if let Some((_, r)) = best {
            x.rotate(&r);
        }
        Ok(())
    }

    /// The proposals of the initialisation; returns the best `finalists`
    /// (τ and the functional map to hold fixed up to shell 20), best first.
    fn initialise(
        &self,
        x: &Shell<'_>,
        y: &Shell<'_>,
        sx: &Samples,
        sy: &Samples,
        input: Option<&level::FeatureMap>,
        report: &mut RefineReport,
    ) -> Result<Vec<Alignment>> {
        const K_MIN: usize = 6;
        let kt = self.k_max + 9;
        let sigma: Vec<f64> = (0..K_MIN)
            .map(|i| if i == 0 { 0.0 } else { x.xi.row(i).norm() })
            .collect();
        let mut rng = Rng(self.seed);
        let mut starts: Vec<(Alignment, f64)> = Vec::new();
        let zero = || DMatrix::<f64>::zeros(kt, 3);
        starts.push((
            Alignment {
                tau: zero(),
                fmap: None,
                cfix: None,
            },
            0.0,
        ));
        if let Some(fm) = input.filter(|_| self.use_input_map) {
            starts.push((
                Alignment {
                    tau: zero(),
                    fmap: Some(fm.clone()),
                    cfix: None,
                },
                0.0,
            ));
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
                starts.push((
                    Alignment {
                        tau: zero(),
                        fmap: Some(level::FeatureMap {
                            c,
                            k: m,
                            weights: wm.clone(),
                        }),
                        cfix: None,
                    },
                    0.0,
                ));
            }
        }
        let fixed = starts.len();
        while starts.len() < fixed + self.proposals {
            let mut tau = zero();
            for i in 1..K_MIN {
                for d in 0..3 {
                    tau[(i, d)] = sigma[i] * rng.normal();
                }
            }
            let lap = if starts.len().is_multiple_of(2) {
                0.0
            } else {
                10.0
            };
            starts.push((
                Alignment {
                    tau,
                    fmap: None,
                    cfix: None,
                },
                lap,
            ));
        }
        let shells: Vec<_> = (K_MIN..=20)
            .map(|k| (k, level::Shells::new(x, y, k)))
            .collect();
        let runs: Vec<Result<(f64, Alignment, RefineReport)>> = starts
            .into_par_iter()
            .map(|(mut state, lap)| {
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
                let e = surrogate(x, y, &shells, sx, sy, align, score, &mut state, &mut rep)?;
                Ok((e, state, rep))
            })
            .collect();
        let mut ranked = Vec::with_capacity(runs.len());
        for run in runs {
            let (e, state, rep) = run?;
            merge(report, &rep);
            ranked.push((e, state));
        }
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        ranked.truncate(self.finalists.max(1));
        Ok(ranked
            .into_iter()
            .map(|(_, best)| Alignment {
                tau: best.tau,
                cfix: best.fmap.map(|f| f.c),
                fmap: None,
            })
            .collect())
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
        let mut prev: Option<Vec<usize>> = None;
        let mut w = LevelWeights {
            features: 0.25,
            normals: 0.04,
            laplacian: 0.0,
            arap: 0.0,
        };
        for k in schedule(self.k_max, self.levels) {
            let t = Instant::now();
            w.arap = 0.02 * (k.saturating_sub(20) as f64).sqrt();
            let shells = level::Shells::new(x, y, k);
            let (_, ba) =
                level::level(x, y, &shells, sx, sy, k, &w, Some(gram), &mut state, report)?;
            report.iterations.push(Iteration {
                k: (k, k),
                changed: crate::count_changed(prev.as_deref(), &ba),
                seconds: t.elapsed().as_secs_f64(),
            });
            prev = Some(ba);
        }
        let score = LevelWeights {
            features: 0.11,
            ..w
        };
        let e = level::alignment_energy(x, y, ix, iy, &state, &score, report)?;
        Ok((e, state))
    }
}

/// ICP of `x` about the main axis `axis` (through the origin, where both
/// shapes are centred): `iterations` rounds of both directions' nearest
/// points and the closed-form best angle. Rotates `x`; returns the
/// rotation applied.
fn axis_icp(
    x: &mut Shell<'_>,
    y: &Shell<'_>,
    sx: &[usize],
    sy: &[usize],
    axis: &Vector3<f64>,
    iterations: usize,
    report: &mut RefineReport,
) -> Result<Matrix3<f64>> {
    let mut total = Matrix3::identity();
    let pts =
        |s: &Shell<'_>, idx: &[usize]| faer::Mat::from_fn(idx.len(), 3, |r, c| s.verts[idx[r]][c]);
    let qy = pts(y, sy);
    for _ in 0..iterations {
        let qx = pts(x, sx);
        let t = Instant::now();
        let p = fmaps_nn::NnParams::default();
        let ab = fmaps_nn::nearest_rows(qy.as_ref(), qx.as_ref(), None, &p)
            .map_err(fmaps_solve::Error::Search)?;
        let ba = fmaps_nn::nearest_rows(qx.as_ref(), qy.as_ref(), None, &p)
            .map_err(fmaps_solve::Error::Search)?;
        report.nn_searches += 2;
        report.nn_seconds += t.elapsed().as_secs_f64();
        let (mut sin, mut cos) = (0.0, 0.0);
        let pairs = sx
            .iter()
            .zip(&ab)
            .map(|(&i, &j)| (i, sy[j]))
            .chain(ba.iter().zip(sy).map(|(&i, &j)| (sx[i], j)));
        for (i, j) in pairs {
            let p = Vector3::from(x.verts[i]);
            let q = Vector3::from(y.verts[j]);
            let pp = p - axis * axis.dot(&p);
            let qp = q - axis * axis.dot(&q);
            sin += axis.dot(&pp.cross(&qp));
            cos += pp.dot(&qp);
        }
        let r = axis_rotation(axis, sin.atan2(cos));
        x.rotate(&r);
        total = r * total;
    }
    Ok(total)
}

impl Refiner for SmoothShells {
    fn name(&self) -> String {
        format!(
            "smooth-shells 20:{} ({} levels, {} proposals)",
            self.k_max, self.levels, self.proposals
        )
    }

    fn k_needed(&self) -> usize {
        self.k_max + 9
    }

    fn refine(
        &self,
        _c_ab: &DMatrix<f64>,
        _basis_a: &SpectralBasis,
        _basis_b: &SpectralBasis,
    ) -> Result<Refined> {
        Err(crate::needs_geometry("Smooth Shells"))
    }

    fn refine_with_geometry(
        &self,
        c_ab: &DMatrix<f64>,
        basis_a: &SpectralBasis,
        basis_b: &SpectralBasis,
        geo_a: ShapeGeometry<'_>,
        geo_b: ShapeGeometry<'_>,
    ) -> Result<Refined> {
        let t0 = Instant::now();
        self.check(basis_a, basis_b)?;
        crate::check_geometry(basis_a, basis_b, &geo_a, &geo_b)?;
        let mut report = RefineReport::start(self.name());
        let kt = self.k_max + 9;
        let (pa, pb) = (
            basis_a.eigenvectors.columns(0, kt).into_owned(),
            basis_b.eigenvectors.columns(0, kt).into_owned(),
        );
        let mut x = Shell::new(
            geo_a.vertices,
            geo_a.faces,
            &pa,
            basis_a.mass.as_slice(),
            &basis_a.eigenvalues.as_slice()[..kt],
        );
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
        if self.rigid {
            let t = Instant::now();
            self.rigid_alignment(&mut x, &y, &ix, &iy, &input, &mut report)?;
            report.iterations.push(Iteration {
                k: (2, 20),
                changed: 0,
                seconds: t.elapsed().as_secs_f64(),
            });
        }
        let t = Instant::now();
        let finalists = self.initialise(&x, &y, &ix, &iy, Some(&input), &mut report)?;
        report.iterations.push(Iteration {
            k: (6, 20),
            changed: 0,
            seconds: t.elapsed().as_secs_f64(),
        });
        let (sx, sy) = (fps(&x, self.samples), fps(&y, self.samples));
        let gram = level::arap_gram(&x, self.k_max);
        let mut best: Option<(f64, Alignment)> = None;
        for start in finalists {
            let (e, state) =
                self.align(&x, &y, (&sx, &sy), (&ix, &iy), &gram, start, &mut report)?;
            if best.as_ref().is_none_or(|b| e < b.0) {
                best = Some((e, state));
            }
        }
        let (_, state) = best.expect("at least one finalist");
        // The final map on all vertices, in the last level's product space.
        let fm = state.fmap.clone().expect("at least one level ran");
        let wk = level::shell_weights(self.k_max);
        let xs = x.shell(&wk);
        let cur = level::Posed::new(x.deform(&xs, &state.tau, fm.k), x.faces);
        let ys = level::Posed::new(y.shell(&wk), y.faces);
        let all_x = Samples::new(&x, (0..x.verts.len()).collect());
        let all_y = Samples::new(&y, (0..y.verts.len()).collect());
        let w = LevelWeights {
            features: 0.25,
            normals: 0.04,
            laplacian: 0.0,
            arap: 0.0,
        };
        let (_, t_ba) =
            level::correspondences(&cur, &ys, &all_x, &all_y, &w, Some(&fm), &mut report)?;
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
    fn rotations_are_proper_and_align() {
        let a = Vector3::new(1.0, 2.0, -0.5).normalize();
        let b = Vector3::new(-0.3, 0.1, 1.0).normalize();
        let r = align_vectors(&a, &b);
        assert!((r * a - b).norm() < 1e-12);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        let r = align_vectors(&a, &(-a));
        assert!((r * a + a).norm() < 1e-12);
        let q = axis_rotation(&Vector3::z(), std::f64::consts::FRAC_PI_2);
        assert!((q * Vector3::x() - Vector3::y()).norm() < 1e-12);
    }

    #[test]
    fn normal_draws_have_unit_variance() {
        let mut r = Rng(7);
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
