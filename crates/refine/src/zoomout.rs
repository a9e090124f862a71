//! ZoomOut (Melzi et al. 2019): spectral upsampling of a functional map.

use std::time::Instant;

use fmaps_eigensolve::SpectralBasis;
use nalgebra::DMatrix;

use crate::{Error, Iteration, RefineReport, Refined, Refiner, Result, check_k, count_changed};
use fmaps_nearest::{CheckedRows, ImageSearch, NnParams};
use fmaps_solve::convert::{
    BasisRows, Conversion, gram, point_map, point_map_sinkhorn, pullback, pullback_unweighted,
    pullback_update,
};
use fmaps_solve::sinkhorn::Sinkhorn;

/// Vertices of A and of B on which the ZoomOut iterations run (the paper's
/// fast variant); typically a few thousand farthest points per shape
/// ([`crate::farthest_point_sampling`]). Each iteration then matches
/// samples of B to samples of A, and fits C by least squares on the
/// samples of B (`argmin ‖Φ_B[S_B] C − Φ_A[T(S_B)]‖`, as pyFM does); only
/// the final point map is computed on all vertices.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Subsample {
    /// Sample vertices of A.
    pub a: Vec<usize>,
    /// Sample vertices of B (at least k_final of them).
    pub b: Vec<usize>,
    /// For every vertex of B, the position in `b` of a nearby sample
    /// (its nearest, as [`crate::farthest_point_sampling_with_nearest`]
    /// gives it), or empty. The final full-size search then starts each
    /// vertex from its sample's image, an upper bound that prunes most of
    /// the search (the result is the same exact nearest neighbour either
    /// way: only the time depends on it).
    pub nearest_b: Vec<usize>,
    /// For every vertex of A, the position in `a` of a nearby sample, or
    /// empty. Where the final search bounds clusters of A's rows by balls,
    /// these patches are its clusters (else k-means clusters of the rows
    /// are computed). [`Subsample::farthest`] gives each vertex's nearest
    /// among the first `n / PartitionParams::coarse_ball_size(n)` samples
    /// (rows per patch about `√(n/5)`).
    pub nearest_a: Vec<usize>,
}

/// Clusters for the full-size search among the `n` rows of a shape after
/// iterations on samples: `n /` [`fmaps_nearest::PartitionParams::coarse_ball_size`]`(n)`
/// (rows per cluster about `√(n/5)`): on FAUST's 80k pair, 635 cells of
/// ~126 rows, which search faster than the 5000 samples' cells of ~16
/// (docs/benchmarks.md, "Large meshes: sampled refinement").
pub(crate) fn search_cells(n: usize) -> usize {
    n.div_ceil(fmaps_nearest::PartitionParams::default().coarse_ball_size(n))
        .max(1)
}

impl Subsample {
    /// `n` farthest points of each shape (from vertex 0,
    /// [`crate::farthest_point_sampling_with_nearest`]), given the
    /// vertices of A and of B, with each vertex of B's nearest sample.
    ///
    /// ```
    /// let line = |m: usize| (0..m).map(|i| [i as f64, 0.0, 0.0]).collect::<Vec<_>>();
    /// let s = fmaps_refine::Subsample::farthest(&line(10), &line(20), 3);
    /// assert_eq!(s.a, vec![0, 9, 4]);
    /// assert_eq!(s.b, vec![0, 19, 9]);
    /// assert_eq!(s.nearest_b.len(), 20);
    /// ```
    pub fn farthest(vertices_a: &[[f64; 3]], vertices_b: &[[f64; 3]], n: usize) -> Subsample {
        let ((a, nearest_a), (b, nearest_b)) = rayon::join(
            || crate::farthest_point_sampling_with_nearest(vertices_a, n, 0),
            || crate::farthest_point_sampling_with_nearest(vertices_b, n, 0),
        );
        // The search's clusters: the cells of the first samples (a
        // coarser farthest point sampling of A, the prefix of `a`).
        let cells = search_cells(vertices_a.len());
        let nearest_a = if cells < a.len() {
            crate::farthest_point_sampling_with_nearest(vertices_a, cells, 0).1
        } else {
            nearest_a
        };
        Subsample {
            a,
            b,
            nearest_a,
            nearest_b,
        }
    }

    /// The clusters of A's rows `rows_a` (one per vertex of A) for a
    /// full-size ball search: the cells of `nearest_a`, where the ball
    /// search pays ([`fmaps_nearest::BallsRequest::labels`]);
    /// `None` without `nearest_a` or where another search is faster.
    pub fn cells_of_a(
        &self,
        rows_a: faer::MatRef<'_, f64>,
    ) -> Option<std::sync::Arc<fmaps_nearest::Partition>> {
        if self.nearest_a.len() != rows_a.nrows() {
            return None;
        }
        // (Positions among the samples: below u32::MAX wherever the ball
        // search pays.)
        let labels = self.nearest_a.iter().map(|&j| j as u32).collect();
        fmaps_nearest::Partition::for_balls(
            rows_a,
            fmaps_nearest::BallsRequest::new(BALLS_MIN_ROWS).labels(labels),
        )
    }

    /// The guesses of the full-size search: for every vertex of B, the
    /// vertex of A its nearest sample maps to under `t_samples` (positions
    /// in `a`, one per sample of B); `None` without `nearest_b`.
    pub fn guesses(&self, t_samples: &[usize]) -> Option<Vec<usize>> {
        (!self.nearest_b.is_empty()).then(|| {
            self.nearest_b
                .iter()
                .map(|&j| self.a[t_samples[j]])
                .collect()
        })
    }
}

/// ZoomOut: starting from the leading `k_start x k_start` block of the
/// input, alternate `T_BA = NN(C)` and `C ← Φ_Bᵀ M_B Π_BA Φ_A` with the
/// basis grown by `step` per iteration up to `k_final x k_final`; the
/// output point map is the conversion of the final C.
///
/// The default schedule 50 → 150 step 5 is the one pyFM users run (and
/// the peers' pyFM pipeline script); the ZoomOut paper's is k → 200 in
/// steps of 1 (`--zoomout 30:200:1` on the command line).
#[derive(Debug, Clone, PartialEq)]
pub struct ZoomOut {
    /// Size of the initial block taken from the input map.
    pub k_start: usize,
    /// Final size of C (both shapes need this many eigenpairs).
    pub k_final: usize,
    /// Growth per iteration (the last step may be shorter).
    pub step: usize,
    /// Convert with the adjoint (`argmin_x ‖Φ_A(x) − Φ_B(y) C‖`).
    pub adjoint: bool,
    /// Refine both directions: each iteration computes `T_BA` from C and
    /// `T_AB` from Cᵀ and sets C to the mean of `Φ_Bᵀ M_B Π_BA Φ_A` and
    /// `(Φ_Aᵀ M_A Π_AB Φ_B)ᵀ`, which pulls the two point maps towards
    /// mutual inverses (twice the searches).
    pub bijective: bool,
    /// Run the iterations on sample vertices only.
    pub subsample: Option<Subsample>,
    /// With `subsample`: iterations at `k_final` on every vertex after
    /// those on the samples (each a fit `Φ_Bᵀ M_B Π_BA Φ_A` with B's mass,
    /// free of the samples' quadrature error, and one full-size search
    /// from the previous map). 0 (the default): the paper's fast variant,
    /// as pyFM runs it; `fmaps match` runs 1 (on FAUST tr_reg_002 → 007
    /// subdivided to 80k vertices, three starts: mean error x100 2.092 → 2.088, the
    /// unsampled ZoomOut's 2.073).
    pub full_iterations: usize,
    /// Convert with the Fast Sinkhorn Filter (Pai et al. 2021) instead of
    /// nearest neighbours, in every iteration and for the output map
    /// (`--conversion sinkhorn`).
    pub sinkhorn: Option<Sinkhorn>,
}

impl Default for ZoomOut {
    fn default() -> Self {
        ZoomOut {
            k_start: 50,
            k_final: 150,
            step: 5,
            adjoint: false,
            bijective: false,
            subsample: None,
            full_iterations: 0,
            sinkhorn: None,
        }
    }
}

impl ZoomOut {
    /// The sizes C takes, after the start: `k_start + step, ...,
    /// k_final`.
    pub fn schedule(&self) -> Vec<usize> {
        crate::growth_schedule(self.k_start, self.k_final, self.step)
    }

    /// The default ZoomOut with the schedule `START:FINAL:STEP` (the
    /// command line's and the evaluation's notation, e.g. `30:200:1`, the
    /// paper's): `0 < START <= FINAL`, `STEP >= 1`.
    pub fn with_schedule(text: &str) -> Result<ZoomOut> {
        let parts: Vec<Option<usize>> = text.split(':').map(|p| p.trim().parse().ok()).collect();
        match parts.as_slice() {
            [Some(a), Some(b), Some(c)] if *a > 0 && a <= b && *c > 0 => Ok(ZoomOut {
                k_start: *a,
                k_final: *b,
                step: *c,
                ..ZoomOut::default()
            }),
            _ => Err(Error::InvalidParameter(format!(
                "ZoomOut schedule '{text}': expected START:FINAL:STEP with 0 < START <= FINAL and STEP >= 1, e.g. 30:200:1"
            ))),
        }
    }

    fn check(&self, c_ab: &DMatrix<f64>, a: &SpectralBasis, b: &SpectralBasis) -> Result<()> {
        if self.k_start == 0 || self.k_final < self.k_start {
            return Err(Error::InvalidParameter(format!(
                "ZoomOut needs 0 < k_start <= k_final, got {}:{}",
                self.k_start, self.k_final
            )));
        }
        if self.step == 0 && self.k_final > self.k_start {
            return Err(Error::InvalidParameter(
                "ZoomOut step must be at least 1".into(),
            ));
        }
        if c_ab.nrows() < self.k_start || c_ab.ncols() < self.k_start {
            return Err(Error::InvalidParameter(format!(
                "ZoomOut starts from a {k} x {k} block, but the map is {} x {}",
                c_ab.nrows(),
                c_ab.ncols(),
                k = self.k_start
            )));
        }
        // The map's columns and rows are coefficients of A's and B's
        // eigenfunctions: a map wider than a basis refers to functions
        // that do not exist.
        check_k(a, "A", self.k_final.max(c_ab.ncols()))?;
        check_k(b, "B", self.k_final.max(c_ab.nrows()))?;
        if let Some(s) = &self.subsample {
            for (shape, idx, n) in [("A", &s.a, a.n()), ("B", &s.b, b.n())] {
                if let Some((at, &index)) = idx.iter().enumerate().find(|(_, v)| **v >= n) {
                    return Err(Error::SampleOutOfRange {
                        shape,
                        at,
                        index,
                        n,
                    });
                }
            }
            if !s.nearest_b.is_empty() {
                if s.nearest_b.len() != b.n() {
                    return Err(Error::InvalidParameter(format!(
                        "ZoomOut samples: nearest_b has {} entries, B has {} vertices",
                        s.nearest_b.len(),
                        b.n()
                    )));
                }
                if let Some(v) = s.nearest_b.iter().position(|&j| j >= s.b.len()) {
                    return Err(Error::InvalidParameter(format!(
                        "ZoomOut samples: nearest_b[{v}] = {} is not a position among the {} samples of B",
                        s.nearest_b[v],
                        s.b.len()
                    )));
                }
            }
            let need_a = if self.bijective { self.k_final } else { 1 };
            if s.b.len() < self.k_final || s.a.len() < need_a {
                return Err(Error::InvalidParameter(format!(
                    "ZoomOut to k = {} on samples needs at least {} samples of B{}, got {} (A: {})",
                    self.k_final,
                    self.k_final,
                    if self.bijective { " and of A" } else { "" },
                    s.b.len(),
                    s.a.len()
                )));
            }
        }
        Ok(())
    }
}

/// One shape's rows for the iterations: all vertices with the mass, or
/// samples with the Gram matrix of their basis rows.
struct Side {
    phi: BasisRows,
    fit: Fit,
}

enum Fit {
    Mass(Vec<f64>),
    Gram(DMatrix<f64>),
}

impl Side {
    fn new(basis: &SpectralBasis, rows: Option<&[usize]>, k: usize) -> Result<Side> {
        Ok(match rows {
            None => Side {
                phi: BasisRows::new(basis, k),
                fit: Fit::Mass(basis.mass.as_slice().to_vec()),
            },
            Some(rows) => {
                let phi = BasisRows::at_vertices(basis, k, rows)?;
                let g = gram(&phi, k);
                Side {
                    phi,
                    fit: Fit::Gram(g),
                }
            }
        })
    }
}

/// The map `this ← other` of size k_this x k_other induced by `t` (one
/// row of `other` per row of `this`). With `previous`, the fit `c` of an
/// earlier map `t_prev` (a smaller or equal size): on all vertices, only
/// the rows whose image changed and the new rows and columns are summed
/// ([`pullback_update`]); on samples the fit is a least-squares solve,
/// computed directly.
fn fit(
    previous: Option<(&DMatrix<f64>, &[usize])>,
    t: &[usize],
    other: &Side,
    k_other: usize,
    this: &Side,
    k_this: usize,
) -> Result<DMatrix<f64>> {
    match &this.fit {
        Fit::Mass(m) => Ok(match previous {
            Some((c, t_prev)) => {
                pullback_update(c, t_prev, t, &other.phi, k_other, &this.phi, k_this, m)?
            }
            None => pullback(t, &other.phi, k_other, &this.phi, k_this, m)?,
        }),
        Fit::Gram(g) => {
            let rhs = pullback_unweighted(t, &other.phi, k_other, &this.phi, k_this)?;
            let chol = g
                .view((0, 0), (k_this, k_this))
                .into_owned()
                .cholesky()
                .ok_or(Error::SingularSample {
                    samples: this.phi.n(),
                    k: k_this,
                })?;
            Ok(chol.solve(&rhs))
        }
    }
}

impl Refiner for ZoomOut {
    fn k_needed(&self) -> usize {
        self.k_final
    }

    fn for_initial_size(&self, k: usize) -> Option<Box<dyn Refiner>> {
        Some(Box::new(ZoomOut {
            k_start: self.k_start.min(k),
            ..self.clone()
        }))
    }

    fn name(&self) -> String {
        let mut s = format!("zoomout {}:{}:{}", self.k_start, self.k_final, self.step);
        if self.adjoint {
            s.push_str(" adjoint");
        }
        if self.bijective {
            s.push_str(" bijective");
        }
        if let Some(sub) = &self.subsample {
            s.push_str(&format!(" samples {}/{}", sub.a.len(), sub.b.len()));
            if self.full_iterations > 0 {
                s.push_str(&format!(" + {} on every vertex", self.full_iterations));
            }
        }
        if self.sinkhorn.is_some() {
            s.push_str(" sinkhorn");
        }
        s
    }

    fn refine(&self, input: &crate::RefineInput<'_>) -> Result<Refined> {
        self.run(input.c_ab, input.basis_a, input.basis_b, input.t_ba_guess)
    }
}

impl ZoomOut {
    /// [`Refiner::refine`], the first search starting from `guess` (a
    /// vertex of A per vertex of B; used only without samples, where the
    /// searches run on all vertices).
    fn run(
        &self,
        c_ab: &DMatrix<f64>,
        basis_a: &SpectralBasis,
        basis_b: &SpectralBasis,
        guess: Option<&[usize]>,
    ) -> Result<Refined> {
        let t0 = Instant::now();
        self.check(c_ab, basis_a, basis_b)?;
        let kf = self.k_final;
        let sub = self.subsample.as_ref();
        let side_a = Side::new(basis_a, sub.map(|s| s.a.as_slice()), kf)?;
        let side_b = Side::new(basis_b, sub.map(|s| s.b.as_slice()), kf)?;
        let mut report = RefineReport::start(self.name());
        let conversion = if self.adjoint {
            Conversion::Adjoint
        } else {
            Conversion::Direct
        };
        // Without matrix tiles, each shape's rows are clustered once (at
        // the final size) and every search bounds the clusters' images by
        // balls (`NnStrategy::Balls`, exact): the data searched, `Φ_A Cᵀ`
        // or `Φ_A`, is a linear image of the same rows at every size.
        let t_part = Instant::now();
        let partitions = balls_partitions(&self.sinkhorn, &side_a.phi, &side_b.phi, self.bijective);
        let nn_params_a = partitions.0.as_ref().map_or_else(NnParams::default, |p| {
            NnParams::default().with_partition(p.clone())
        });
        let nn_params_b = partitions.1.as_ref().map_or_else(NnParams::default, |p| {
            NnParams::default().with_partition(p.clone())
        });
        // With clusters (and the direct conversion): the searched rows
        // copied into their clusters' order once, each image `Φ Cᵀ`
        // computed in that order; the other side's rows, the queries,
        // checked once.
        let image_search = |part: &Option<std::sync::Arc<fmaps_nearest::Partition>>,
                            rows: &BasisRows| match part {
            Some(p) if !self.adjoint && self.sinkhorn.is_none() => {
                ImageSearch::new(rows.view(rows.k()), p.clone()).map(Some)
            }
            _ => Ok(None),
        };
        fn checked<'r>(
            search: &Option<ImageSearch>,
            rows: &'r BasisRows,
        ) -> fmaps_nearest::Result<Option<CheckedRows<'r>>> {
            search
                .as_ref()
                .map(|_| CheckedRows::new(rows.view(rows.k())))
                .transpose()
        }
        let images = (
            image_search(&partitions.0, &side_a.phi).map_err(fmaps_solve::Error::Search)?,
            image_search(&partitions.1, &side_b.phi).map_err(fmaps_solve::Error::Search)?,
        );
        let checked_rows = (
            checked(&images.1, &side_a.phi).map_err(fmaps_solve::Error::Search)?,
            checked(&images.0, &side_b.phi).map_err(fmaps_solve::Error::Search)?,
        );
        let partition_seconds = t_part.elapsed().as_secs_f64();
        report.nn_seconds += partition_seconds;
        let mut nn =
            |c: &DMatrix<f64>, data: &BasisRows, queries: &BasisRows, hint: Option<&[usize]>| {
                let t = Instant::now();
                // The data side's clusters (ignored where the rows differ).
                let nn_params = if std::ptr::eq(data, &side_b.phi) {
                    &nn_params_b
                } else {
                    &nn_params_a
                };
                // The image search of the data side and the queries'
                // checked rows, only for the rows they were made of (not,
                // e.g., all vertices after iterations on samples).
                let same = |a: &BasisRows, b: &BasisRows| {
                    std::ptr::eq(data, a) && std::ptr::eq(queries, b)
                };
                let image = if same(&side_a.phi, &side_b.phi) {
                    images.0.as_ref().zip(checked_rows.1.as_ref())
                } else if same(&side_b.phi, &side_a.phi) {
                    images.1.as_ref().zip(checked_rows.0.as_ref())
                } else {
                    None
                };
                let map = match (&self.sinkhorn, image) {
                    (Some(p), _) => point_map_sinkhorn(c, data, queries, conversion, p)?.0,
                    (None, Some((search, q))) => image_point_map(c, search, q, hint)?,
                    (None, None) => point_map(c, data, queries, conversion, hint, nn_params)?,
                };
                report.nn_searches += 1;
                report.nn_seconds += t.elapsed().as_secs_f64();
                Ok::<_, Error>(map)
            };
        let k0 = self.k_start;
        let mut c = c_ab.view((0, 0), (k0, k0)).into_owned();
        // The first search's guesses: the caller's, when they are vertices
        // of A for every vertex of B (not on samples).
        let mut prev: Option<Vec<usize>> = guess
            .filter(|g| sub.is_none() && g.len() == basis_b.n())
            .map(<[usize]>::to_vec);
        let mut prev_ab: Option<Vec<usize>> = None;
        // Each direction's last fit, of the maps prev / prev_ab (B ← A's
        // up to FIT_AHEAD columns ahead of k).
        let (mut fit_ab, mut fit_ba): (Option<DMatrix<f64>>, Option<DMatrix<f64>>) = (None, None);
        let mut iterations = Vec::new();
        for k in self.schedule() {
            let ti = Instant::now();
            let t_ba = nn(&c, &side_a.phi, &side_b.phi, prev.as_deref())?;
            // The previous iteration's fit and map (not the caller's guess).
            let before = fit_ab
                .as_ref()
                .zip(prev.as_deref())
                .filter(|_| !iterations.is_empty());
            // With the mass, the fit runs ahead of the schedule: at up to
            // FIT_AHEAD more rows and columns than k (the leading k x k
            // block is the fit at k), so that its new rows and columns,
            // a pass over every row of both shapes, are summed once per
            // FIT_AHEAD columns instead of at every step.
            let size = match (&side_b.fit, before) {
                (Fit::Mass(_), Some((f, _))) if f.nrows() >= k => f.nrows(),
                (Fit::Mass(_), _) => (k + FIT_AHEAD).min(kf),
                _ => k,
            };
            let c_ab_fit = fit(before, &t_ba, &side_a, size, &side_b, size)?;
            let mut next = c_ab_fit.view((0, 0), (k, k)).into_owned();
            fit_ab = Some(c_ab_fit);
            if self.bijective {
                let ct = c.transpose();
                let t_ab = nn(&ct, &side_b.phi, &side_a.phi, prev_ab.as_deref())?;
                let c_ba = fit(
                    fit_ba.as_ref().zip(prev_ab.as_deref()),
                    &t_ab,
                    &side_b,
                    k,
                    &side_a,
                    k,
                )?;
                prev_ab = Some(t_ab);
                next = (next + c_ba.transpose()) * 0.5;
                fit_ba = Some(c_ba);
            }
            c = next;
            iterations.push(Iteration {
                k: (k, k),
                // (The first iteration counts every point: the guess is
                // not a map of this refinement.)
                changed: count_changed(prev.as_deref().filter(|_| !iterations.is_empty()), &t_ba),
                seconds: ti.elapsed().as_secs_f64(),
            });
            prev = Some(t_ba);
        }
        // The output: the final C converted on all vertices.
        let t_ba = if sub.is_some() {
            let (all_a, all_b) = rayon::join(
                || BasisRows::new(basis_a, kf),
                || BasisRows::new(basis_b, kf),
            );
            // The clusters of all of A's rows, for the one full-size
            // search, from each vertex's nearest sample's image.
            let partition = match (&self.sinkhorn, sub) {
                (Some(_), _) => None,
                (None, Some(s)) if s.nearest_a.len() == basis_a.n() => {
                    s.cells_of_a(all_a.view(all_a.k()))
                }
                (None, _) => balls_partition(&all_a),
            };
            let guesses = sub.zip(prev.as_deref()).and_then(|(s, t)| s.guesses(t));
            // Searches with the clusters of all rows (counted here: `nn`
            // counts its own).
            let (mut searches, mut seconds) = (0, 0.0);
            let mut full = |c: &DMatrix<f64>, hints: Option<&[usize]>| -> Result<Vec<usize>> {
                Ok(match &partition {
                    Some(p) => {
                        let t = Instant::now();
                        let params = NnParams::with_strategy(fmaps_nearest::NnStrategy::Balls)
                            .with_partition(p.clone());
                        let map = point_map(c, &all_a, &all_b, conversion, hints, &params)?;
                        searches += 1;
                        seconds += t.elapsed().as_secs_f64();
                        map
                    }
                    None => nn(c, &all_a, &all_b, hints)?,
                })
            };
            let mut t = full(&c, guesses.as_deref())?;
            // Iterations at the final size on every vertex: the fit with
            // B's mass (no sampling error), the search from the map before.
            for _ in 0..self.full_iterations {
                let ti = Instant::now();
                c = pullback(&t, &all_a, kf, &all_b, kf, basis_b.mass.as_slice())?;
                let next = full(&c, Some(&t))?;
                iterations.push(Iteration {
                    k: (kf, kf),
                    changed: count_changed(Some(&t), &next),
                    seconds: ti.elapsed().as_secs_f64(),
                });
                t = next;
            }
            report.nn_searches += searches;
            report.nn_seconds += seconds;
            t
        } else {
            nn(&c, &side_a.phi, &side_b.phi, prev.as_deref())?
        };
        report.iterations = iterations;
        report.converged = true;
        report.seconds = t0.elapsed().as_secs_f64();
        Ok(Refined {
            c_ab: c,
            t_ba,
            report,
        })
    }
}

/// k-means clusters of A's rows (and B's when the refinement also searches
/// among B's rows) for the ball search ([`balls_partition`]).
fn balls_partitions(
    sinkhorn: &Option<Sinkhorn>,
    a: &BasisRows,
    b: &BasisRows,
    bijective: bool,
) -> (
    Option<std::sync::Arc<fmaps_nearest::Partition>>,
    Option<std::sync::Arc<fmaps_nearest::Partition>>,
) {
    if sinkhorn.is_some() {
        return (None, None);
    }
    if bijective {
        rayon::join(|| balls_partition(a), || balls_partition(b))
    } else {
        (balls_partition(a), None)
    }
}

/// The direct point map `T_BA` of `c` (k_B x k_A) by `search`, the
/// image search of A's rows, and B's rows `queries` (as
/// [`fmaps_solve::convert::point_map`] with [`Conversion::Direct`]);
/// `hint`: a guess per row of B (ignored when the count differs).
pub(crate) fn image_point_map(
    c: &DMatrix<f64>,
    search: &ImageSearch,
    queries: &CheckedRows<'_>,
    hint: Option<&[usize]>,
) -> Result<Vec<usize>> {
    let (kb, ka) = c.shape();
    let m = faer::MatRef::from_column_major_slice(c.as_slice(), kb, ka);
    let hint = hint.filter(|h| h.len() == queries.rows().nrows());
    Ok(search
        .nearest(m, &queries.leading(kb), hint)
        .map_err(fmaps_solve::Error::Search)?)
}

/// Columns by which ZoomOut's fit runs ahead of the schedule (the leading
/// k x k block of a point map's fit at k + FIT_AHEAD is its fit at k): its
/// border, the new rows and columns over every vertex of B, is then
/// summed once per twenty columns, where the update over the changed rows
/// grows only by the wider rows (docs/tuning.md).
const FIT_AHEAD: usize = 20;

/// Rows from which the balls pay (below, brute force is as fast).
const BALLS_MIN_ROWS: usize = 1024;

/// k-means clusters of the rows `r` (one per ~24 rows) for the ball search
/// (`NnStrategy::Balls`: exact, and where there are no matrix tiles the
/// fastest search of a linear image of these rows with guesses), when it
/// pays ([`fmaps_nearest::Partition::for_balls`]: 1024-250,000 rows, with
/// matrix tiles from `fmaps_nearest::PartitionParams::tiled_from_rows`, `FMAPS_NO_BALLS`
/// unset).
pub(crate) fn balls_partition(r: &BasisRows) -> Option<std::sync::Arc<fmaps_nearest::Partition>> {
    fmaps_nearest::Partition::for_balls(
        r.view(r.k()),
        fmaps_nearest::BallsRequest::new(BALLS_MIN_ROWS),
    )
}

/// [`balls_partition`] with `steps` Lloyd steps (ICP's).
pub(crate) fn balls_partition_steps(
    r: &BasisRows,
    steps: usize,
) -> Option<std::sync::Arc<fmaps_nearest::Partition>> {
    fmaps_nearest::Partition::for_balls(
        r.view(r.k()),
        fmaps_nearest::BallsRequest::new(BALLS_MIN_ROWS).kmeans_steps(steps),
    )
}

#[cfg(test)]
mod tests {
    /// FAUST's 80k pair: 635 cells of about 126 rows.
    #[test]
    fn search_cells_of_a_large_shape() {
        assert_eq!(super::search_cells(80_000), 635);
        assert_eq!(super::search_cells(1), 1);
    }
}
