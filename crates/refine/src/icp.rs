//! Spectral ICP (Ovsjanikov et al. 2012, §6.1).

use std::time::Instant;

use fmaps_eigensolve::SpectralBasis;
use nalgebra::DMatrix;

use crate::{Error, Iteration, RefineReport, Refined, Refiner, Result, check_k, count_changed};
use fmaps_nearest::{CheckedRows, ImageSearch, NnParams, NnStrategy};
use fmaps_solve::convert::{
    BasisRows, Conversion, point_map, point_map_sinkhorn, pullback, pullback_update,
};
use fmaps_solve::sinkhorn::Sinkhorn;

/// Lloyd steps of ICP's clusters ([`fmaps_nearest::BallsRequest::kmeans_steps`]).
const ICP_KMEANS_STEPS: usize = 2;

/// ICP in the spectral domain: alternate `T_BA = NN(C)` and
/// `C ← U Vᵀ` for the SVD `U Σ Vᵀ` of `Φ_Bᵀ M_B Π_BA Φ_A`, at the input's
/// size. The defaults are pyFM's `icp_refine` (10 iterations, direct
/// conversion); unlike pyFM it stops as soon as the point map repeats,
/// which gives the same result (the next C would be identical).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Icp {
    /// Iteration limit (each iteration is one nearest-neighbour search).
    pub max_iterations: usize,
    /// Convert with the adjoint (`argmin_x ‖Φ_A(x) − Φ_B(y) C‖`).
    pub adjoint: bool,
    /// Convert with the Fast Sinkhorn Filter (Pai et al. 2021) instead of
    /// nearest neighbours (`--conversion sinkhorn`).
    pub sinkhorn: Option<Sinkhorn>,
}

impl Default for Icp {
    fn default() -> Self {
        Icp {
            max_iterations: 10,
            adjoint: false,
            sinkhorn: None,
        }
    }
}

impl Refiner for Icp {
    fn name(&self) -> String {
        format!(
            "icp {}{}{}",
            self.max_iterations,
            if self.adjoint { " adjoint" } else { "" },
            if self.sinkhorn.is_some() {
                " sinkhorn"
            } else {
                ""
            }
        )
    }

    fn refine(&self, input: &crate::RefineInput<'_>) -> Result<Refined> {
        self.run(input.c_ab, input.basis_a, input.basis_b, input.t_ba_guess)
    }
}

impl Icp {
    /// [`Refiner::refine`], the first search starting from `guess` (a
    /// vertex of A per vertex of B).
    fn run(
        &self,
        c_ab: &DMatrix<f64>,
        basis_a: &SpectralBasis,
        basis_b: &SpectralBasis,
        guess: Option<&[usize]>,
    ) -> Result<Refined> {
        let t0 = Instant::now();
        let (kb, ka) = c_ab.shape();
        if ka == 0 || kb == 0 {
            return Err(Error::InvalidParameter(
                "the functional map is empty".into(),
            ));
        }
        check_k(basis_a, "A", ka)?;
        check_k(basis_b, "B", kb)?;
        let (phi_a, phi_b) = rayon::join(
            || BasisRows::new(basis_a, ka),
            || BasisRows::new(basis_b, kb),
        );
        let (phi_a, phi_b) = (&phi_a, &phi_b);
        let mass_b = basis_b.mass.as_slice();
        let mut report = RefineReport::start(self.name());
        // ICP's map changes little from one iteration to the next, so the
        // previous one is a good guess at every step: without matrix tiles
        // the prefix search pays from lower dimensions than in ZoomOut,
        // whose early maps are noisy (docs/tuning.md; the tree is better up
        // to 48 dimensions).
        let dim = if self.adjoint { ka } else { kb };
        // Without tiles, in more than 32 dimensions: the clusters of A's
        // rows (the data of every search) and the ball search. Two Lloyd
        // steps: ten searches at one size do not repay five (docs/tuning.md).
        let partition = if dim > 32 && self.sinkhorn.is_none() {
            crate::zoomout::balls_partition_steps(phi_a, ICP_KMEANS_STEPS)
        } else {
            None
        };
        // With clusters and the direct conversion: A's rows copied into
        // their clusters' order once, each image `Φ_A Cᵀ` computed in that
        // order; B's rows checked once.
        let image = match &partition {
            Some(p) if !self.adjoint => Some((
                ImageSearch::new(phi_a.view(ka), p.clone()).map_err(fmaps_solve::Error::Search)?,
                CheckedRows::new(phi_b.view(kb)).map_err(fmaps_solve::Error::Search)?,
            )),
            _ => None,
        };
        let nn_params = match partition {
            Some(p) => NnParams::with_strategy(NnStrategy::Balls).with_partition(p),
            None => NnParams::with_strategy(if dim > 48 && !fmaps_nearest::tiles_available() {
                NnStrategy::Prefix
            } else {
                NnStrategy::Auto
            }),
        };
        let conversion = if self.adjoint {
            Conversion::Adjoint
        } else {
            Conversion::Direct
        };
        let nn = |c: &DMatrix<f64>, hint: Option<&[usize]>, report: &mut RefineReport| {
            let t = Instant::now();
            let map = match (&self.sinkhorn, &image) {
                (Some(p), _) => point_map_sinkhorn(c, phi_a, phi_b, conversion, p)?.0,
                (None, Some((search, q))) => crate::zoomout::image_point_map(c, search, q, hint)?,
                (None, None) => point_map(c, phi_a, phi_b, conversion, hint, &nn_params)?,
            };
            report.nn_searches += 1;
            report.nn_seconds += t.elapsed().as_secs_f64();
            Ok::<_, Error>(map)
        };
        let mut c = c_ab.clone();
        let guess = guess.filter(|g| g.len() == basis_b.n());
        let mut t_ba = nn(&c, guess, &mut report)?;
        // The last pull-back and its map: the next one sums only the rows
        // of B whose image changed.
        let mut last: Option<(DMatrix<f64>, Vec<usize>)> = None;
        for _ in 0..self.max_iterations {
            let ti = Instant::now();
            let pulled = match &last {
                Some((p, t_prev)) => {
                    pullback_update(p, t_prev, &t_ba, phi_a, ka, phi_b, kb, mass_b)?
                }
                None => pullback(&t_ba, phi_a, ka, phi_b, kb, mass_b)?,
            };
            c = nearest_orthonormal(pulled.clone());
            let next = nn(&c, Some(&t_ba), &mut report)?;
            let changed = count_changed(Some(&t_ba), &next);
            // (The map just searched from becomes the last pull-back's.)
            last = Some((pulled, std::mem::replace(&mut t_ba, next)));
            report.iterations.push(Iteration {
                k: (ka, kb),
                changed,
                seconds: ti.elapsed().as_secs_f64(),
            });
            if changed == 0 {
                // T is a fixed point: every further iteration reproduces C.
                report.converged = true;
                break;
            }
        }
        report.seconds = t0.elapsed().as_secs_f64();
        Ok(Refined {
            c_ab: c,
            t_ba,
            report,
        })
    }
}

/// The nearest orthonormal matrix `U Vᵀ` (with the rectangular identity
/// between them for k_B ≠ k_A): orthogonal Procrustes.
pub(crate) fn nearest_orthonormal(c: DMatrix<f64>) -> DMatrix<f64> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::svd::{self, ComputeSvdVectors};
    let (kb, ka) = c.shape();
    let r = kb.min(ka);
    if r == 0 {
        return DMatrix::zeros(kb, ka);
    }
    // faer's thin SVD (one thread: callers run in parallel themselves);
    // nalgebra's is several times slower at the sizes of ZoomOut and
    // Smooth Shells (up to 200 x 200).
    let a = faer::MatRef::from_column_major_slice(c.as_slice(), kb, ka);
    let (mut u, mut v) = (
        faer::Mat::<f64>::zeros(kb, r),
        faer::Mat::<f64>::zeros(ka, r),
    );
    let mut s = faer::diag::Diag::<f64>::zeros(r);
    let par = faer::Par::Seq;
    let thin = ComputeSvdVectors::Thin;
    let mut mem = MemBuffer::new(svd::svd_scratch::<f64>(
        kb,
        ka,
        thin,
        thin,
        par,
        Default::default(),
    ));
    let done = svd::svd(
        a,
        s.as_mut(),
        Some(u.as_mut()),
        Some(v.as_mut()),
        par,
        MemStack::new(&mut mem),
        Default::default(),
    );
    if done.is_err() {
        // No convergence (non-finite entries): nalgebra's SVD as before.
        let svd = c.svd(true, true);
        let (u, vt) = (svd.u.expect("u requested"), svd.v_t.expect("v_t requested"));
        return u.columns(0, r) * vt.rows(0, r);
    }
    let mut out = DMatrix::zeros(kb, ka);
    faer::linalg::matmul::matmul(
        faer::MatMut::from_column_major_slice_mut(out.as_mut_slice(), kb, ka),
        faer::Accum::Replace,
        u.as_ref(),
        v.as_ref().transpose(),
        1.0,
        par,
    );
    out
}
