//! Spectral point descriptors computed from a Laplace–Beltrami eigenbasis
//! (`L φ = λ M φ`, Φ M-orthonormal), with the parameter choices of the
//! literature and of pyFM, so results are comparable:
//!
//! - **HKS**, the heat kernel signature (J. Sun, M. Ovsjanikov, L. Guibas,
//!   SGP 2009): `HKS(x, t) = Σ_k e^{−tλ_k} φ_k(x)²`, for times log-spaced
//!   between `4 ln 10 / λ_max` and `4 ln 10 / λ_1`.
//! - **WKS**, the wave kernel signature (M. Aubry, U. Schlickewei,
//!   D. Cremers, ICCV workshops 2011): `WKS(x, e) = Σ_k exp(−(e − log λ_k)² /
//!   2σ²) φ_k(x)²` over the non-constant eigenpairs, for log-energies evenly
//!   spaced between `log λ_1 + 2σ` and `log λ_max − 2σ`, with
//!   `σ = 7 (log λ_max − log λ_1) / n`.
//! - Landmark variants (`Σ_k c_k φ_k(x) φ_k(l)` for landmark vertices l),
//!   "scaled" variants (each sample divided by `Σ_k c_k`), and per-column
//!   normalization in the M-norm.
//!
//! Descriptors are n x d matrices (a column per descriptor function);
//! project them with [`fmaps_eigensolve::SpectralBasis::project`].
//!
//! ```
//! use fmaps_descriptors::{hks, HksParams};
//! use nalgebra::{DMatrix, DVector};
//!
//! // A toy basis: 3 vertices, 2 eigenpairs.
//! let evals = DVector::from_vec(vec![0.0, 2.0]);
//! let evecs = DMatrix::from_row_slice(3, 2, &[0.5, 0.7, 0.5, 0.0, 0.5, -0.7]);
//! let mut params = HksParams::default(); // 100 scaled times, as pyFM
//! params.n_times = 4;
//! params.scaled = false;
//! let d = hks(&evals, &evecs, &params)?;
//! assert_eq!(d.shape(), (3, 4));
//! // Vertex 1 has no energy in the second eigenvector: HKS = 0.25 at all t.
//! assert!(d.row(1).iter().all(|x| (x - 0.25).abs() < 1e-15));
//! # Ok::<(), fmaps_descriptors::Error>(())
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

use nalgebra::{DMatrix, DVector};

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Eigenvalues and eigenvectors do not match.
    #[error("{n_values} eigenvalues but {n_vectors} eigenvectors")]
    SizeMismatch {
        /// Number of eigenvalues.
        n_values: usize,
        /// Number of eigenvector columns.
        n_vectors: usize,
    },
    /// Too few non-constant eigenpairs to define the sampling.
    #[error("need at least two nonzero eigenvalues, found {0}")]
    TooFewEigenvalues(usize),
    /// A landmark index is out of range.
    #[error("landmark {index} is out of range: the basis has {n} vertices")]
    LandmarkOutOfRange {
        /// The landmark.
        index: usize,
        /// Number of vertices.
        n: usize,
    },
    /// A parameter is invalid.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
}

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Options of the HKS. `Default`: 100 times, scaled (pyFM's `mesh_HKS`).
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct HksParams {
    /// Number of time samples.
    pub n_times: usize,
    /// Divide each time sample by `Σ_k e^{−tλ_k}`.
    pub scaled: bool,
}

impl Default for HksParams {
    fn default() -> Self {
        Self {
            n_times: 100,
            scaled: true,
        }
    }
}

/// Options of the WKS. `Default`: 100 energies, scaled (pyFM's `mesh_WKS`).
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct WksParams {
    /// Number of energy samples.
    pub n_energies: usize,
    /// Divide each energy sample by its total weight `Σ_k c_k`.
    pub scaled: bool,
}

impl Default for WksParams {
    fn default() -> Self {
        Self {
            n_energies: 100,
            scaled: true,
        }
    }
}

/// The HKS time samples for a spectrum: `n` values log-spaced from
/// `4 ln 10 / λ_max` to `4 ln 10 / λ_1` (λ_1 the first nonzero eigenvalue,
/// taken as the second smallest |λ|).
pub fn hks_times(eigenvalues: &DVector<f64>, n: usize) -> Result<Vec<f64>> {
    let abs = sorted_abs(eigenvalues);
    if abs.len() < 2 || abs[1] <= 0.0 {
        return Err(Error::TooFewEigenvalues(
            abs.iter().filter(|x| **x > 0.0).count(),
        ));
    }
    let (t0, t1) = (
        4.0 * 10f64.ln() / abs[abs.len() - 1],
        4.0 * 10f64.ln() / abs[1],
    );
    Ok(geomspace(t0, t1, n))
}

/// The WKS log-energies and σ for a spectrum (see the crate docs).
pub fn wks_energies(eigenvalues: &DVector<f64>, n: usize) -> Result<(Vec<f64>, f64)> {
    if n == 0 {
        return Err(Error::InvalidParameter("at least one energy".into()));
    }
    let abs = sorted_abs(eigenvalues);
    if abs.len() < 2 || abs[1] <= 0.0 {
        return Err(Error::TooFewEigenvalues(
            abs.iter().filter(|x| **x > 0.0).count(),
        ));
    }
    let (mut e0, mut e1) = (abs[1].ln(), abs[abs.len() - 1].ln());
    let sigma = 7.0 * (e1 - e0) / n as f64;
    e0 += 2.0 * sigma;
    e1 -= 2.0 * sigma;
    Ok((linspace(e0, e1, n), sigma))
}

/// The HKS at the given times: n x T.
pub fn hks_at(
    eigenvalues: &DVector<f64>,
    eigenvectors: &DMatrix<f64>,
    times: &[f64],
    scaled: bool,
) -> Result<DMatrix<f64>> {
    check(eigenvalues, eigenvectors)?;
    let coefs = DMatrix::from_fn(eigenvalues.len(), times.len(), |k, t| {
        (-times[t] * eigenvalues[k].abs()).exp()
    });
    Ok(signature(eigenvectors, None, coefs, scaled))
}

/// The HKS with pyFM's automatic times: n x `n_times`.
pub fn hks(
    eigenvalues: &DVector<f64>,
    eigenvectors: &DMatrix<f64>,
    params: &HksParams,
) -> Result<DMatrix<f64>> {
    let t = hks_times(eigenvalues, params.n_times)?;
    hks_at(eigenvalues, eigenvectors, &t, params.scaled)
}

/// The landmark HKS: n x (p · n_times), column `l · n_times + t` for
/// landmark l and time t.
pub fn landmark_hks(
    eigenvalues: &DVector<f64>,
    eigenvectors: &DMatrix<f64>,
    landmarks: &[usize],
    params: &HksParams,
) -> Result<DMatrix<f64>> {
    check(eigenvalues, eigenvectors)?;
    let t = hks_times(eigenvalues, params.n_times)?;
    let coefs = DMatrix::from_fn(eigenvalues.len(), t.len(), |k, j| {
        (-t[j] * eigenvalues[k].abs()).exp()
    });
    check_landmarks(eigenvectors.nrows(), landmarks)?;
    Ok(signature(
        eigenvectors,
        Some(landmarks),
        coefs,
        params.scaled,
    ))
}

/// The WKS with pyFM's automatic energies: n x `n_energies`. Eigenpairs
/// with `λ ≤ 1e-8 λ_max` (the constants) are left out.
pub fn wks(
    eigenvalues: &DVector<f64>,
    eigenvectors: &DMatrix<f64>,
    params: &WksParams,
) -> Result<DMatrix<f64>> {
    check(eigenvalues, eigenvectors)?;
    let coefs = wks_coefs(eigenvalues, params.n_energies)?;
    Ok(signature(eigenvectors, None, coefs, params.scaled))
}

/// The landmark WKS: n x (p · n_energies), column `l · n_energies + e`.
pub fn landmark_wks(
    eigenvalues: &DVector<f64>,
    eigenvectors: &DMatrix<f64>,
    landmarks: &[usize],
    params: &WksParams,
) -> Result<DMatrix<f64>> {
    check(eigenvalues, eigenvectors)?;
    check_landmarks(eigenvectors.nrows(), landmarks)?;
    let coefs = wks_coefs(eigenvalues, params.n_energies)?;
    Ok(signature(
        eigenvectors,
        Some(landmarks),
        coefs,
        params.scaled,
    ))
}

/// Divides every column by its M-norm `sqrt(Σ_i m_i d_i²)` (zero columns
/// are left as they are).
pub fn normalize_columns(descriptors: &mut DMatrix<f64>, mass: &DVector<f64>) {
    for mut col in descriptors.column_iter_mut() {
        let n2: f64 = col.iter().zip(mass.iter()).map(|(d, m)| m * d * d).sum();
        if n2 > 0.0 {
            col /= n2.sqrt();
        }
    }
}

/// k x S weights of the WKS samples (zero rows for the constant pairs).
fn wks_coefs(eigenvalues: &DVector<f64>, n: usize) -> Result<DMatrix<f64>> {
    let (e, sigma) = wks_energies(eigenvalues, n)?;
    let max = eigenvalues.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    Ok(DMatrix::from_fn(eigenvalues.len(), e.len(), |k, j| {
        let l = eigenvalues[k].abs();
        if l > 1e-8 * max {
            (-(e[j] - l.ln()).powi(2) / (2.0 * sigma * sigma)).exp()
        } else {
            0.0
        }
    }))
}

/// `D[x, s] = Σ_k c[k, s] φ_k(x) φ_k(x)` (or `φ_k(x) φ_k(l)` per landmark),
/// optionally divided by `Σ_k c[k, s]`.
fn signature(
    phi: &DMatrix<f64>,
    landmarks: Option<&[usize]>,
    mut coefs: DMatrix<f64>,
    scaled: bool,
) -> DMatrix<f64> {
    if scaled {
        for mut col in coefs.column_iter_mut() {
            let s = col.sum();
            if s > 0.0 {
                col /= s;
            }
        }
    }
    match landmarks {
        None => phi.component_mul(phi) * coefs,
        Some(lms) => {
            let (n, s) = (phi.nrows(), coefs.ncols());
            let mut out = DMatrix::zeros(n, lms.len() * s);
            for (p, &l) in lms.iter().enumerate() {
                // Weight eigenvector k by φ_k(l): Φ diag(φ(l)) C.
                let mut w = coefs.clone();
                for (k, mut row) in w.row_iter_mut().enumerate() {
                    row *= phi[(l, k)];
                }
                out.columns_mut(p * s, s).copy_from(&(phi * w));
            }
            out
        }
    }
}

fn check(eigenvalues: &DVector<f64>, eigenvectors: &DMatrix<f64>) -> Result<()> {
    if eigenvalues.len() != eigenvectors.ncols() {
        return Err(Error::SizeMismatch {
            n_values: eigenvalues.len(),
            n_vectors: eigenvectors.ncols(),
        });
    }
    Ok(())
}

fn check_landmarks(n: usize, landmarks: &[usize]) -> Result<()> {
    match landmarks.iter().find(|&&l| l >= n) {
        Some(&index) => Err(Error::LandmarkOutOfRange { index, n }),
        None => Ok(()),
    }
}

fn sorted_abs(v: &DVector<f64>) -> Vec<f64> {
    let mut a: Vec<f64> = v.iter().map(|x| x.abs()).collect();
    a.sort_by(f64::total_cmp);
    a
}

fn geomspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    linspace(a.ln(), b.ln(), n)
        .into_iter()
        .map(f64::exp)
        .collect()
}

fn linspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    match n {
        0 => Vec::new(),
        1 => vec![a],
        _ => (0..n)
            .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
            .collect(),
    }
}

/// The descriptor family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DescriptorKind {
    /// Wave kernel signature (Aubry et al. 2011).
    #[default]
    Wks,
    /// Heat kernel signature (Sun et al. 2009).
    Hks,
}

impl std::fmt::Display for DescriptorKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Wks => "wks",
            Self::Hks => "hks",
        })
    }
}

impl std::str::FromStr for DescriptorKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "wks" => Ok(Self::Wks),
            "hks" => Ok(Self::Hks),
            _ => Err(format!("unknown descriptor '{s}' (wks, hks)")),
        }
    }
}

/// What [`descriptor_matrix`] computes. `Default`: 100 WKS energies, every
/// column kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub struct DescriptorParams {
    /// The family.
    pub kind: DescriptorKind,
    /// Samples (WKS energies or HKS times) per family.
    pub n: usize,
    /// Keep every `subsample`-th column of the stacked descriptors (1: all).
    pub subsample: usize,
}

impl Default for DescriptorParams {
    fn default() -> Self {
        DescriptorParams {
            kind: DescriptorKind::Wks,
            n: 100,
            subsample: 1,
        }
    }
}

/// The descriptors of one shape as the matching pipeline uses them: the
/// family at `n` samples (pyFM's sampling), then, with landmarks, the
/// landmark variant of the same family, stacked column-wise; every
/// `subsample`-th column kept; each column of unit L² norm (`mass`).
/// Returns n_vertices x p.
pub fn descriptor_matrix(
    eigenvalues: &DVector<f64>,
    eigenvectors: &DMatrix<f64>,
    mass: &DVector<f64>,
    landmarks: &[usize],
    params: &DescriptorParams,
) -> Result<DMatrix<f64>> {
    if params.subsample == 0 {
        return Err(Error::InvalidParameter(
            "subsample must be at least 1".into(),
        ));
    }
    let (ev, phi) = (eigenvalues, eigenvectors);
    let mut parts = Vec::new();
    match params.kind {
        DescriptorKind::Wks => {
            let p = WksParams {
                n_energies: params.n,
                ..Default::default()
            };
            parts.push(wks(ev, phi, &p)?);
            if !landmarks.is_empty() {
                parts.push(landmark_wks(ev, phi, landmarks, &p)?);
            }
        }
        DescriptorKind::Hks => {
            let p = HksParams {
                n_times: params.n,
                ..Default::default()
            };
            parts.push(hks(ev, phi, &p)?);
            if !landmarks.is_empty() {
                parts.push(landmark_hks(ev, phi, landmarks, &p)?);
            }
        }
    }
    // The kept columns, in order, across the stacked parts.
    let columns: Vec<(usize, usize)> = parts
        .iter()
        .enumerate()
        .flat_map(|(i, d)| (0..d.ncols()).map(move |j| (i, j)))
        .step_by(params.subsample)
        .collect();
    let mut d = DMatrix::from_fn(phi.nrows(), columns.len(), |v, c| {
        let (i, j) = columns[c];
        parts[i][(v, j)]
    });
    normalize_columns(&mut d, mass);
    Ok(d)
}
