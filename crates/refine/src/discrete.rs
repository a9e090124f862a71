//! Discrete optimisation of functional-map energies over proper maps
//! (J. Ren, S. Melzi, P. Wonka, M. Ovsjanikov, "Discrete Optimization for
//! Shape Matching", SGP 2021), with bijective ZoomOut as a preset.
//!
//! The paper's observation: an energy of functional maps `E(C_AB, C_BA)`
//! minimised under the constraint that both maps are *proper* (induced by
//! point maps, `C_AB = Φ_B⁺ Π_BA Φ_A`) splits into two easy steps. With the
//! point maps fixed, each C is the pull-back of its point map. With the Cs
//! fixed, every term becomes a distance between rows of two matrices, one
//! per shape, so the best point map is one nearest-neighbour search in the
//! concatenation of the terms' embeddings (each scaled by the square root
//! of its weight). For `T_BA` (a vertex of A per vertex of B), with
//! `Λ` the eigenvalues divided by the largest in use:
//!
//! | term | energy | rows of A (data) | rows of B (queries) |
//! | --- | --- | --- | --- |
//! | coupling (properness) | `‖Φ_B C_AB − Π_BA Φ_A‖²` | `Φ_A` | `Φ_B C_AB` |
//! | bijectivity | `‖C_AB C_BA − I‖²` as `‖Π_BA Φ_A C_BA − Φ_B‖²` | `Φ_A C_BA` | `Φ_B` |
//! | orthogonality | `‖C_ABᵀ C_AB − I‖²` as `‖Π_BA Φ_A C_ABᵀ − Φ_B‖²` | `Φ_A C_ABᵀ` | `Φ_B` |
//! | Laplacian commutativity | `‖C_AB Λ_A − Λ_B C_AB‖²` as `‖Π_BA Φ_A Λ_A − Φ_B Λ_B C_AB‖²` | `Φ_A Λ_A` | `Φ_B Λ_B C_AB` |
//!
//! and `T_AB` symmetrically. As in ZoomOut, the basis grows from `k_start`
//! to `k_final` by `step`; at each size the maps are updated `inner` times.
//! The first point maps come from the same searches with the given C and
//! its transpose standing in for the reverse map. The returned C is the
//! pull-back of the returned point map.
//!
//! ZoomOut is this solver on one term: its usual conversion (`Φ_A C_ABᵀ`
//! against `Φ_B`) is the orthogonality term, its adjoint conversion the
//! coupling term (the tests check that both give ZoomOut's maps).
//! Orthogonality and bijectivity together are the paper's *bijective
//! ZoomOut*.

use std::time::Instant;

use faer::linalg::matmul::matmul;
use faer::reborrow::ReborrowMut;
use faer::{Accum, Mat, MatRef, Par};
use fmaps_eigensolve::SpectralBasis;
use fmaps_nearest::{NnParams, nearest_rows};
use fmaps_solve::convert::{BasisRows, pullback};
use nalgebra::DMatrix;

use crate::{Error, Iteration, RefineReport, Refined, Refiner, Result, check_k, count_changed};

/// Weights of the energy terms of [`DiscreteOp`] (0 switches a term off).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiscreteWeights {
    /// Properness: C is the pull-back of the point map (ZoomOut's term).
    pub coupling: f64,
    /// `C_AB C_BA = I`: the two point maps are inverse to each other.
    pub bijectivity: f64,
    /// `C_ABᵀ C_AB = I`: area preservation.
    pub orthogonality: f64,
    /// C commutes with the Laplacians: isometry.
    pub laplacian: f64,
}

/// The discrete solver (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct DiscreteOp {
    /// Size of the initial block taken from the input map.
    pub k_start: usize,
    /// Final size of the maps.
    pub k_final: usize,
    /// Growth per size step.
    pub step: usize,
    /// Point-map updates per size.
    pub inner: usize,
    /// The energy.
    pub weights: DiscreteWeights,
    /// The preset's name, for reports.
    pub preset: &'static str,
    /// Convert with the Fast Sinkhorn Filter (Pai et al. 2021) instead of
    /// nearest neighbours (`--conversion sinkhorn`).
    pub sinkhorn: Option<fmaps_solve::sinkhorn::Sinkhorn>,
}

impl DiscreteOp {
    /// The presets by name: `zoomout` (orthogonality alone: ZoomOut),
    /// `bijective-zoomout` (orthogonality and bijectivity, the paper's
    /// bijective ZoomOut) and `discrete` (all four terms, equal weights),
    /// each on ZoomOut's default schedule 50 → 150 step 5 with one update
    /// per size.
    pub fn preset(name: &str) -> Result<DiscreteOp> {
        let w = |coupling, bijectivity, orthogonality, laplacian| DiscreteWeights {
            coupling,
            bijectivity,
            orthogonality,
            laplacian,
        };
        let (preset, weights) = match name {
            "zoomout" => ("zoomout", w(0.0, 0.0, 1.0, 0.0)),
            "bijective-zoomout" => ("bijective-zoomout", w(0.0, 1.0, 1.0, 0.0)),
            "discrete" => ("discrete", w(1.0, 1.0, 1.0, 1.0)),
            other => {
                return Err(Error::InvalidParameter(format!(
                    "unknown discrete-optimisation preset '{other}': expected zoomout, bijective-zoomout or discrete"
                )));
            }
        };
        Ok(DiscreteOp {
            k_start: 50,
            k_final: 150,
            step: 5,
            inner: 1,
            weights,
            preset,
            sinkhorn: None,
        })
    }

    fn check(&self, c_ab: &DMatrix<f64>, a: &SpectralBasis, b: &SpectralBasis) -> Result<()> {
        if self.k_start == 0 || self.k_final < self.k_start || self.inner == 0 {
            return Err(Error::InvalidParameter(format!(
                "discrete optimisation needs 0 < k_start <= k_final and inner >= 1, got {}:{} inner {}",
                self.k_start, self.k_final, self.inner
            )));
        }
        let w = self.weights;
        let ws = [w.coupling, w.bijectivity, w.orthogonality, w.laplacian];
        if ws.iter().any(|x| !x.is_finite() || *x < 0.0) || ws.iter().all(|&x| x == 0.0) {
            return Err(Error::InvalidParameter(format!(
                "discrete optimisation weights must be finite, non-negative and not all 0: {w:?}"
            )));
        }
        if c_ab.nrows() < self.k_start || c_ab.ncols() < self.k_start {
            return Err(Error::InvalidParameter(format!(
                "discrete optimisation starts from a {k} x {k} block, but the map is {} x {}",
                c_ab.nrows(),
                c_ab.ncols(),
                k = self.k_start
            )));
        }
        // A map wider than a basis refers to functions that do not exist.
        check_k(a, "A", self.k_final.max(c_ab.ncols()))?;
        check_k(b, "B", self.k_final.max(c_ab.nrows()))
    }
}

/// The nearest row of `data` for every row of `queries` (or the Sinkhorn
/// conversion's map), counted and timed in `report`.
pub(crate) fn search_rows(
    data: &Mat<f64>,
    queries: &Mat<f64>,
    hint: Option<&[usize]>,
    sinkhorn: Option<&fmaps_solve::sinkhorn::Sinkhorn>,
    report: &mut RefineReport,
) -> Result<Vec<usize>> {
    let t = Instant::now();
    let r = match sinkhorn {
        Some(p) => {
            fmaps_solve::sinkhorn::sinkhorn_maps(data.as_ref(), queries.as_ref(), p)?.query_to_data
        }
        None => nearest_rows(data.as_ref(), queries.as_ref(), hint, &NnParams::default())
            .map_err(fmaps_solve::Error::Search)?,
    };
    report.nn_searches += 1;
    report.nn_seconds += t.elapsed().as_secs_f64();
    Ok(r)
}

/// One shape's rows and what its embedding blocks need.
pub(crate) struct Shape<'a> {
    pub(crate) phi: BasisRows,
    pub(crate) mass: &'a [f64],
    pub(crate) evals: &'a [f64],
}

/// `Φ[:, :k] M` (n x k) into `dst`, `m` a k x k nalgebra matrix.
fn times(dst: faer::MatMut<'_, f64>, phi: MatRef<'_, f64>, m: &DMatrix<f64>) {
    let k = m.nrows();
    let mr = MatRef::from_column_major_slice(m.as_slice(), k, m.ncols());
    matmul(dst, Accum::Replace, phi, mr, 1.0, Par::rayon(0));
}

/// The concatenated embeddings for the point map `other ← this` (a row of
/// `data` per vertex of `other`, a row of `queries` per vertex of `this`):
/// `c_to_this` maps functions on `other` to `this` (the C of the point map
/// being solved for), `c_back` the reverse one.
pub(crate) fn embeddings(
    w: &DiscreteWeights,
    k: usize,
    other: &Shape<'_>,
    this: &Shape<'_>,
    c_to_this: &DMatrix<f64>,
    c_back: &DMatrix<f64>,
) -> (Mat<f64>, Mat<f64>) {
    let terms = [w.coupling, w.bijectivity, w.orthogonality, w.laplacian];
    let blocks = terms.iter().filter(|&&x| x > 0.0).count();
    let (po, pt) = (other.phi.view(k), this.phi.view(k));
    let mut data = Mat::<f64>::zeros(po.nrows(), blocks * k);
    let mut queries = Mat::<f64>::zeros(pt.nrows(), blocks * k);
    let lmax = |s: &Shape<'_>| s.evals[..k].iter().fold(0.0f64, |m, &x| m.max(x.abs()));
    let (lo, lt) = (
        lmax(other).max(f64::MIN_POSITIVE),
        lmax(this).max(f64::MIN_POSITIVE),
    );
    let mut col = 0;
    for (term, &wt) in terms.iter().enumerate() {
        if wt <= 0.0 {
            continue;
        }
        let s = wt.sqrt();
        let mut d = data.as_mut().submatrix_mut(0, col, po.nrows(), k);
        let mut q = queries.as_mut().submatrix_mut(0, col, pt.nrows(), k);
        match term {
            // ‖Φ_this C − Π Φ_other‖
            0 => {
                d.copy_from(po);
                times(q.rb_mut(), pt, c_to_this);
            }
            // ‖Π Φ_other C_back − Φ_this‖
            1 => {
                times(d.rb_mut(), po, c_back);
                q.copy_from(pt);
            }
            // ‖Π Φ_other Cᵀ − Φ_this‖
            2 => {
                times(d.rb_mut(), po, &c_to_this.transpose());
                q.copy_from(pt);
            }
            // ‖Π Φ_other Λ_other − Φ_this Λ_this C‖
            _ => {
                d.copy_from(po);
                for j in 0..k {
                    let f = other.evals[j] / lo;
                    d.rb_mut().col_mut(j).iter_mut().for_each(|x| *x *= f);
                }
                let lc = DMatrix::from_fn(k, k, |i, j| this.evals[i] / lt * c_to_this[(i, j)]);
                times(q.rb_mut(), pt, &lc);
            }
        }
        for x in d.rb_mut().col_iter_mut().flat_map(|c| c.iter_mut()) {
            *x *= s;
        }
        for x in q.rb_mut().col_iter_mut().flat_map(|c| c.iter_mut()) {
            *x *= s;
        }
        col += k;
    }
    (data, queries)
}

impl Refiner for DiscreteOp {
    fn name(&self) -> String {
        format!(
            "{} {}:{}:{}{}",
            self.preset,
            self.k_start,
            self.k_final,
            self.step,
            if self.sinkhorn.is_some() {
                " sinkhorn"
            } else {
                ""
            }
        )
    }

    fn k_needed(&self) -> usize {
        self.k_final
    }

    fn for_initial_size(&self, k: usize) -> Option<Box<dyn Refiner>> {
        Some(Box::new(DiscreteOp {
            k_start: self.k_start.min(k),
            ..self.clone()
        }))
    }

    fn refine(&self, input: &crate::RefineInput<'_>) -> Result<Refined> {
        let (c_ab, basis_a, basis_b) = (input.c_ab, input.basis_a, input.basis_b);
        let t0 = Instant::now();
        self.check(c_ab, basis_a, basis_b)?;
        let kf = self.k_final;
        let (phi_a, phi_b) = rayon::join(
            || BasisRows::new(basis_a, kf),
            || BasisRows::new(basis_b, kf),
        );
        let a = Shape {
            phi: phi_a,
            mass: basis_a.mass.as_slice(),
            evals: basis_a.eigenvalues.as_slice(),
        };
        let b = Shape {
            phi: phi_b,
            mass: basis_b.mass.as_slice(),
            evals: basis_b.eigenvalues.as_slice(),
        };
        let mut report = RefineReport::start(self.name());
        // The start: the given C_AB's block and, for lack of a reverse map,
        // C_BA = C_ABᵀ (the maps of an isometry are orthonormal); the same
        // energy's searches give the first T_BA and T_AB.
        let k0 = self.k_start;
        let c0 = c_ab.view((0, 0), (k0, k0)).into_owned();
        let c0t = c0.transpose();
        let (d, q) = embeddings(&self.weights, k0, &a, &b, &c0, &c0t);
        let mut t_ba = search_rows(&d, &q, None, self.sinkhorn.as_ref(), &mut report)?;
        let (d, q) = embeddings(&self.weights, k0, &b, &a, &c0t, &c0);
        let mut t_ab = search_rows(&d, &q, None, self.sinkhorn.as_ref(), &mut report)?;
        // As in ZoomOut: each size fits both Cs to the current point maps
        // and updates the maps; the start size only converts.
        for k in crate::growth_schedule(self.k_start, self.k_final, self.step) {
            for _ in 0..self.inner {
                let ti = Instant::now();
                // Both Cs from the current point maps (the proper maps).
                let c = pullback(&t_ba, &a.phi, k, &b.phi, k, b.mass)?;
                let c_ba = pullback(&t_ab, &b.phi, k, &a.phi, k, a.mass)?;
                let (d, q) = embeddings(&self.weights, k, &a, &b, &c, &c_ba);
                let next_ba =
                    search_rows(&d, &q, Some(&t_ba), self.sinkhorn.as_ref(), &mut report)?;
                let (d, q) = embeddings(&self.weights, k, &b, &a, &c_ba, &c);
                let next_ab =
                    search_rows(&d, &q, Some(&t_ab), self.sinkhorn.as_ref(), &mut report)?;
                report.iterations.push(Iteration {
                    k: (k, k),
                    changed: count_changed(Some(&t_ba), &next_ba),
                    seconds: ti.elapsed().as_secs_f64(),
                });
                t_ba = next_ba;
                t_ab = next_ab;
            }
        }
        let c = pullback(&t_ba, &a.phi, kf, &b.phi, kf, b.mass)?;
        report.converged = true;
        report.seconds = t0.elapsed().as_secs_f64();
        Ok(Refined {
            c_ab: c,
            t_ba,
            report,
        })
    }
}
