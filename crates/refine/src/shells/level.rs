//! One level of the Smooth Shells alignment: shells, product embedding,
//! correspondences, deformation and functional map (the points and
//! normals it reads: [`super::posed`]; the ARAP rotations:
//! [`super::arap`]; the shape that moves: [`super::shell`]).

use faer::MatRef;
use fmaps_nearest::{BallsRequest, NnParams, Partition, nearest_rows, nearest_rows_both};
use nalgebra::{DMatrix, Matrix3, Vector3};

use super::arap::rotations;
use super::posed::BALLS_FROM_ROWS;
pub(crate) use super::posed::{AtSamples, Posed, Samples};
use super::shell::Shell;
pub(crate) use super::shell::view;
use super::shell::{mul_ref, v3};
use crate::icp::nearest_orthonormal;
use crate::{RefineReport, Result};

/// The sigmoid weights of the shell of size `k` (the paper's smooth
/// truncation of the spectrum): 1/2 at eigenfunction `k`, rising to ≈ 1
/// below it and falling to 1% at `k + 9` (at `2k − 1` for `k < 10`).
pub(crate) fn shell_weights(k: usize) -> Vec<f64> {
    const TRUNCATION: f64 = 1e-2;
    const WIDTH: usize = 10;
    if k <= 1 {
        return vec![1.0];
    }
    let half = if k >= WIDTH { WIDTH - 1 } else { k - 1 };
    let t = -(1.0 / (1.0 - TRUNCATION) - 1.0).ln() / half as f64;
    (-(k as i64 - 1)..=half as i64)
        .map(|j| 1.0 / (1.0 + (t * j as f64).exp()))
        .collect()
}

/// The normals' weight in the product space: `normals` times the ratio
/// of the coordinates' to the normals' norms on the samples, averaged
/// over both shapes.
fn normal_scale(px: &AtSamples, py: &AtSamples, normals: f64) -> f64 {
    if normals == 0.0 {
        // The normals may not have been computed (see [`level`]).
        return 0.0;
    }
    let part = |p: &AtSamples| normals * frob(&p.pts) / frob(&p.nrm).max(f64::MIN_POSITIVE);
    0.5 * (part(px) + part(py))
}

/// Weights of one level's energies.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LevelWeights {
    /// Spectral features relative to the coordinates (the paper's 0.25).
    pub features: f64,
    /// Normals relative to the coordinates (0 at k ≤ 10).
    pub normals: f64,
    /// Laplacian commutativity in the functional map fit (0: none).
    pub laplacian: f64,
    /// ARAP weight relative to the data term (0: none).
    pub arap: f64,
}

impl LevelWeights {
    /// The main alignment's weights (the paper's feature weight 0.25; its
    /// ARAP weight grows with the level and is set there).
    pub const MAIN: LevelWeights = LevelWeights {
        features: 0.25,
        normals: 0.04,
        laplacian: 0.0,
        arap: 0.0,
    };
}

/// The functional map the features come from: `C` (k' x k' with
/// `Φ_X C ≈ Φ_Y ∘ π`), the shell size `k` it was fitted at and that
/// level's weights.
#[derive(Debug, Clone)]
pub(crate) struct FeatureMap {
    pub c: DMatrix<f64>,
    pub k: usize,
    pub weights: Vec<f64>,
}

/// A product embedding: rows `[p, fn · n, ff · F]`, a row per sample,
/// row-major (the searches read the rows in place).
struct Embedding {
    rows: Vec<f64>,
    n: usize,
    cols: usize,
}

impl Embedding {
    fn view(&self) -> MatRef<'_, f64> {
        MatRef::from_row_major_slice(&self.rows, self.n, self.cols)
    }
}

/// The product embedding of `p` (normals scaled by `fn_`, features `F`
/// by `ff`).
fn embed(p: &AtSamples, fn_: f64, feat: Option<(&DMatrix<f64>, f64)>) -> Embedding {
    let kf = feat.map_or(0, |(f, _)| f.ncols());
    // Normals at weight 0 are left out (their columns would be 0).
    let kn = if fn_ == 0.0 { 0 } else { 3 };
    let (pts, nrm) = (&p.pts, &p.nrm);
    let (n, cols) = (pts.len(), 3 + kn + kf);
    let mut rows = vec![0.0; n * cols];
    for (r, row) in rows.chunks_exact_mut(cols).enumerate() {
        row[..3].copy_from_slice(&pts[r]);
        if kn > 0 {
            for c in 0..3 {
                row[3 + c] = fn_ * nrm[r][c];
            }
        }
    }
    if let Some((f, s)) = feat {
        // Feature column by column (F is column-major: one slice per
        // column, no iterator adapters in the loop).
        debug_assert_eq!(f.nrows(), n);
        if n > 0 {
            for (c, col) in f.as_slice().chunks_exact(n).enumerate() {
                for (r, &v) in col.iter().enumerate() {
                    rows[r * cols + 3 + kn + c] = s * v;
                }
            }
        }
    }
    Embedding { rows, n, cols }
}

fn frob(p: &[[f64; 3]]) -> f64 {
    p.iter()
        .map(|v| v[0].powi(2) + v[1].powi(2) + v[2].powi(2))
        .sum::<f64>()
        .sqrt()
}

/// The spectral features of the samples of one shape: rows of
/// `Φ[:, :k'] C[:, :k] diag(w)` (X, with `c`) or `Φ[:, :k] diag(w)` (Y).
fn features(s: &Samples, fm: &FeatureMap, c: Option<&DMatrix<f64>>) -> DMatrix<f64> {
    let k = fm.k;
    match c {
        Some(c) => {
            let kk = c.nrows();
            let mut f = mul_ref(view(&s.phi, kk), false, view(c, k));
            for j in 0..k {
                f.column_mut(j).scale_mut(fm.weights[j]);
            }
            f
        }
        None => DMatrix::from_fn(s.len(), k, |r, j| s.phi[(r, j)] * fm.weights[j]),
    }
}

/// The state carried from level to level.
#[derive(Clone)]
pub(crate) struct Alignment {
    /// Deformation coefficients (K x 3) of X's shell.
    pub tau: DMatrix<f64>,
    /// The functional map of the last level.
    pub fmap: Option<FeatureMap>,
    /// A functional map block fixed while k ≤ 20 (from the initialisation).
    pub cfix: Option<DMatrix<f64>>,
}

/// Columns of a product embedding from which [`search_params`] takes the
/// ball search with guesses: below, brute force's fused kernel (up to 32
/// columns) was faster even with guesses (the 5k default's
/// initialisation, shells 6..20 on 1000 samples; docs/tuning.md).
pub(super) const HINTED_BALLS_FROM_COLS: usize = 33;

/// The search among the rows `data` of a product embedding (clusters of
/// its rows: `cells`), `hinted` when each query comes with a guess (the
/// previous level's correspondence). The ball search (exact: the same
/// answers as brute force) where it pays, on any CPU (the other choice is
/// brute force without the matrix tiles: with AMX the default took 20%
/// longer before the balls ran there too, docs/tuning.md):
/// - with guesses from [`HINTED_BALLS_FROM_COLS`] columns, over `cells`
///   (the alignment levels above shell ~26 on 2000 samples: the previous
///   level's correspondences bound each query's search to a few clusters;
///   docs/tuning.md has the measurement, the same maps);
/// - without guesses from [`BALLS_FROM_ROWS`] rows (the final point map
///   on every vertex), over `cells` or k-means clusters sized for one
///   search ([`BallsRequest::one_search`]): positions, normals
///   and spectral features are smooth on the surface, so the clusters are
///   compact (FAUST pair subdivided twice, 80k vertices, 197 columns:
///   brute force compared all 6.4·10⁹ pairs per finalist).
///
/// Elsewhere brute force: on a few thousand rows without guesses it
/// measured twice as fast as the tree the automatic choice takes.
fn search_params(data: MatRef<'_, f64>, cells: Option<&[u32]>, hinted: bool) -> NnParams {
    let balls = |p| NnParams::with_strategy(fmaps_nearest::NnStrategy::Balls).with_partition(p);
    if hinted
        && data.ncols() >= HINTED_BALLS_FROM_COLS
        && let Some(p) = cells.and_then(|c| {
            Partition::for_balls(data, BallsRequest::new(1).labels(c.to_vec()).over_brute())
        })
    {
        return balls(p);
    }
    let partition = match cells {
        Some(c) => Partition::for_balls(
            data,
            BallsRequest::new(BALLS_FROM_ROWS)
                .labels(c.to_vec())
                .over_brute(),
        ),
        None => Partition::for_balls(data, BallsRequest::new(BALLS_FROM_ROWS).one_search()),
    };
    match partition {
        Some(p) => balls(p),
        None => NnParams::with_strategy(fmaps_nearest::NnStrategy::Brute),
    }
}

/// Correspondences of the samples in the product embedding: for each X
/// sample a Y sample (left empty unless `both`) and for each Y sample an X
/// sample (positions in the other shape's samples). `hints`: guesses of
/// both (the previous level's), which speed the search up only (exact:
/// the same answers without them).
#[allow(clippy::too_many_arguments)]
pub(crate) fn correspondences(
    px: &AtSamples,
    py: &AtSamples,
    (sx, sy): (&Samples, &Samples),
    w: &LevelWeights,
    fmap: Option<&FeatureMap>,
    both: bool,
    hints: Option<&(Vec<usize>, Vec<usize>)>,
    report: &mut RefineReport,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let (vx, vy) = (frob(&px.pts), frob(&py.pts));
    let fnm = normal_scale(px, py, w.normals);
    // The features are dropped once embedded (on every vertex of an 80k
    // mesh they are n x k each, alive through the search otherwise).
    let (ex, ey) = {
        let feats = fmap.map(|fm| (features(sx, fm, Some(&fm.c)), features(sy, fm, None)));
        let (fx, fy) = match &feats {
            Some((fx, fy)) => {
                let (nfx, nfy) = (fx.norm(), fy.norm());
                let s = 0.5
                    * (w.features * vx / nfx.max(f64::MIN_POSITIVE)
                        + w.features * vy / nfy.max(f64::MIN_POSITIVE));
                (Some((fx, s)), Some((fy, s)))
            }
            None => (None, None),
        };
        (embed(px, fnm, fx), embed(py, fnm, fy))
    };
    let t = std::time::Instant::now();
    // The strategy of each direction (data `d`, queries `q`), then the
    // search with it.
    fn plan<'h>(
        d: &Embedding,
        q: &Embedding,
        cells: Option<&[u32]>,
        hint: Option<&'h [usize]>,
    ) -> (NnParams, Option<&'h [usize]>) {
        let hint = hint.filter(|h| h.len() == q.n);
        (search_params(d.view(), cells, hint.is_some()), hint)
    }
    let search = |d: &Embedding, q: &Embedding, (params, hint): (NnParams, Option<&[usize]>)| {
        nearest_rows(d.view(), q.view(), hint, &params).map_err(fmaps_solve::Error::Search)
    };
    let (hab, hba) = (hints.map(|h| h.0.as_slice()), hints.map(|h| h.1.as_slice()));
    let pba = plan(&ex, &ey, sx.cells.as_deref(), hba);
    let (ab, ba) = if both {
        report.nn_searches += 2;
        let pab = plan(&ey, &ex, sy.cells.as_deref(), hab);
        let brute = fmaps_nearest::NnStrategy::Brute;
        if pab.0.strategy == brute && pba.0.strategy == brute {
            // Both ways from one pass of products (the same answers).
            let (ab, ba) =
                nearest_rows_both(ex.view(), ey.view()).map_err(fmaps_solve::Error::Search)?;
            (Ok(ab), Ok(ba))
        } else {
            rayon::join(|| search(&ey, &ex, pab), || search(&ex, &ey, pba))
        }
    } else {
        report.nn_searches += 1;
        (Ok(Vec::new()), search(&ex, &ey, pba))
    };
    report.nn_seconds += t.elapsed().as_secs_f64();
    Ok((ab?, ba?))
}

/// Both shapes' shells of one size and its weights.
pub(crate) struct Shells {
    pub weights: Vec<f64>,
    pub x: Vec<[f64; 3]>,
    pub y: Posed,
}

impl Shells {
    pub fn new(x: &Shell<'_>, y: &Shell<'_>, k: usize) -> Shells {
        let weights = shell_weights(k);
        Shells {
            x: x.shell(&weights),
            y: Posed::new(y.shell(&weights), y.faces, y.orient),
            weights,
        }
    }
}

/// One level of the alignment at shell size `k` (weights `wk`): the
/// correspondences, then the deformation τ (least squares of both
/// directions' residuals, plus ARAP), then the functional map (least
/// squares on the correspondences, made orthonormal). `hints`: the
/// previous level's correspondences on the same samples (speed only);
/// returns this level's.
#[allow(clippy::too_many_arguments)]
pub(crate) fn level(
    x: &Shell<'_>,
    y: &Shell<'_>,
    shells: &Shells,
    sx: &Samples,
    sy: &Samples,
    k: usize,
    w: &LevelWeights,
    arap_gram: Option<&DMatrix<f64>>,
    state: &mut Alignment,
    hints: Option<&(Vec<usize>, Vec<usize>)>,
    report: &mut RefineReport,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let (wk, xs, ys) = (&shells.weights, &shells.x, &shells.y);
    let kk = wk.len().min(x.phi.ncols()).min(y.phi.ncols());
    let kd = k.min(kk);
    let arap = arap_gram.filter(|_| w.arap > 0.0);
    // X deformed: on every vertex for ARAP, else at the samples only;
    // normals at the samples (at weight 0 they do not enter the
    // correspondences).
    let cur = arap.map(|_| x.deform(xs, &state.tau, kd));
    let px = match &cur {
        Some(pts) => sx.at_points(x, pts, w.normals > 0.0),
        None => sx.pose(x, xs, Some((&state.tau, kd)), w.normals > 0.0),
    };
    let (ab, ba) = correspondences(
        &px,
        &ys.at(sy),
        (sx, sy),
        w,
        state.fmap.as_ref(),
        true,
        hints,
        report,
    )?;

    // Deformation: Σ ‖XS(s) + Φ(s)τ − YS(π s)‖² over both directions
    // (pairs of sample positions). Each X sample's pairs share its row of
    // Φ: the normal equations weight the row by its number of pairs and
    // sum its residuals (and, for the map, its partners' rows of Φ_Y).
    let pairs: Vec<(usize, usize)> = (0..sx.len())
        .zip(ab.iter().copied())
        .chain(ba.iter().copied().zip(0..sy.len()))
        .collect();
    let mut count = vec![0.0f64; sx.len()];
    let mut res = DMatrix::<f64>::zeros(sx.len(), 3);
    for &(xi, yi) in &pairs {
        count[xi] += 1.0;
        for d in 0..3 {
            res[(xi, d)] += ys.pts[sy[yi]][d] - xs[sx[xi]][d];
        }
    }
    // (Column by column on the column-major storage: slices, not
    // nalgebra's strided views, in the hot loop; the same sums in the
    // same order.)
    let (nx, ny) = (sx.phi.nrows(), sy.phi.nrows());
    let mut partners = DMatrix::<f64>::zeros(nx, kk);
    if nx > 0 && ny > 0 {
        for (to, from) in partners
            .as_mut_slice()
            .chunks_exact_mut(nx)
            .zip(sy.phi.as_slice().chunks_exact(ny))
        {
            for &(xi, yi) in &pairs {
                to[xi] += sx.sqrt_mass[xi] * from[yi];
            }
        }
    }
    let a = view(&sx.phi, kd);
    // The samples' first `cols` columns of Φ, row r scaled by w[r] (the
    // same products as element by element; column by column on the
    // column-major slices, which vectorises).
    let weighted = |w: &[f64], cols: usize| {
        let mut out = DMatrix::<f64>::zeros(nx, cols);
        if nx > 0 {
            for (o, p) in out
                .as_mut_slice()
                .chunks_exact_mut(nx)
                .zip(sx.phi.as_slice().chunks_exact(nx))
            {
                for ((o, &p), &wr) in o.iter_mut().zip(p).zip(w) {
                    *o = wr * p;
                }
            }
        }
        out
    };
    let ca = weighted(&count, kd);
    let mut m = mul_ref(view(&ca, kd), true, a);
    let mut z = mul_ref(a, true, view(&res, 3));
    if let (Some(g), Some(cur)) = (arap, &cur) {
        let ga = g.view((0, 0), (kd, kd));
        let rot = rotations(xs, cur, &x.neighbours);
        let mut b = vec![Vector3::zeros(); xs.len()];
        for (i, nb) in x.neighbours.iter().enumerate() {
            for &j in nb {
                let e = v3(xs[i]) - v3(xs[j]);
                let t = (rot[i] - Matrix3::identity()) * e;
                b[i] += t;
                b[j] -= t;
            }
        }
        let bm = DMatrix::from_fn(b.len(), 3, |r, d| b[r][d]);
        let za = mul_ref(view(x.phi, kd), true, view(&bm, 3));
        let s = w.arap * inf_norm(&m) / inf_norm(&ga.into_owned()).max(f64::MIN_POSITIVE);
        m += ga * s;
        z += za * s;
    }
    let reg = 1e-10 * inf_norm(&m).max(1e-300);
    m += DMatrix::identity(kd, kd) * reg;
    if let Some(sol) = m.clone().cholesky().map(|c| c.solve(&z)) {
        state.tau.view_mut((0, 0), (kd, 3)).copy_from(&sol);
    }

    // Functional map on the correspondences (area weighted).
    let ax = view(&sx.phi, kk);
    let cw: Vec<f64> = (0..sx.len())
        .map(|r| count[r] * sx.sqrt_mass[r] * sx.sqrt_mass[r])
        .collect();
    let cm = weighted(&cw, kk);
    let mm = mul_ref(view(&cm, kk), true, ax);
    let wx = weighted(&sx.sqrt_mass, kk);
    let zz = mul_ref(view(&wx, kk), true, view(&partners, kk));
    let mut c = DMatrix::<f64>::zeros(kk, kk);
    if w.laplacian > 0.0 {
        let l = DMatrix::from_fn(kk, kk, |i, j| (x.evals[i] - y.evals[j]).abs().sqrt());
        let lmean = l.mean().max(f64::MIN_POSITIVE);
        let mabs = mm.abs().mean();
        for j in 0..kk {
            let mut a = mm.clone();
            for i in 0..kk {
                a[(i, i)] += w.laplacian / lmean * mabs * l[(i, j)];
            }
            if let Some(ch) = a.cholesky() {
                c.set_column(j, &ch.solve(&zz.column(j).into_owned()));
            }
        }
    } else if let Some(ch) =
        (mm.clone() + DMatrix::identity(kk, kk) * 1e-12 * inf_norm(&mm)).cholesky()
    {
        c = ch.solve(&zz);
    }
    let mut c = nearest_orthonormal(c);
    if let Some(fix) = state.cfix.as_ref().filter(|_| k <= 20) {
        let f = fix.nrows().min(kk);
        c.view_mut((0, 0), (f, kk)).fill(0.0);
        c.view_mut((0, 0), (kk, f)).fill(0.0);
        c.view_mut((0, 0), (f, f))
            .copy_from(&fix.view((0, 0), (f, f)));
        if kk > f {
            let rest = nearest_orthonormal(c.view((f, f), (kk - f, kk - f)).into_owned());
            c.view_mut((f, f), (kk - f, kk - f)).copy_from(&rest);
        }
    }
    state.fmap = Some(FeatureMap {
        c,
        k: kd,
        weights: wk[..kk].to_vec(),
    });
    Ok((ab, ba))
}

fn inf_norm(m: &DMatrix<f64>) -> f64 {
    m.row_iter()
        .map(|r| r.iter().map(|x| x.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// `2 Φᵀ L Φ` for the uniform graph Laplacian L of the mesh edges: the
/// Gram matrix of the ARAP term's Jacobian in the deformation basis.
pub(crate) fn arap_gram(x: &Shell<'_>, k: usize) -> DMatrix<f64> {
    let k = k.min(x.phi.ncols());
    let n = x.verts.len();
    let lphi = DMatrix::from_fn(n, k, |i, c| {
        x.neighbours[i]
            .iter()
            .map(|&j| x.phi[(i, c)] - x.phi[(j, c)])
            .sum::<f64>()
    });
    mul_ref(view(x.phi, k), true, view(&lphi, k)) * 2.0
}

/// The alignment energy of a result (the initialisation's score): the
/// area-weighted mean distance, over both directions' correspondences,
/// between matched points and normals of the deformed X and of Y at full
/// detail. Also returns the correspondences.
pub(crate) fn alignment_energy(
    x: &Shell<'_>,
    y: &Shell<'_>,
    sx: &Samples,
    sy: &Samples,
    state: &Alignment,
    w: &LevelWeights,
    report: &mut RefineReport,
) -> Result<f64> {
    let k = state.fmap.as_ref().map_or(state.tau.nrows(), |f| f.k);
    let cur = sx.pose(x, &x.verts, Some((&state.tau, k)), true);
    let full_y = sy.pose(y, &y.verts, None, true);
    let (ab, ba) = correspondences(
        &cur,
        &full_y,
        (sx, sy),
        w,
        state.fmap.as_ref(),
        true,
        None,
        report,
    )?;
    let fn_ = normal_scale(&cur, &full_y, w.normals);
    let (cur, nx, yv, ny) = (&cur.pts, &cur.nrm, &full_y.pts, &full_y.nrm);
    let dist = |i: usize, j: usize| {
        let mut s = 0.0;
        for d in 0..3 {
            s += (cur[i][d] - yv[j][d]).powi(2) + (fn_ * (nx[i][d] - ny[j][d])).powi(2);
        }
        s.sqrt()
    };
    // (Positions in the samples.)
    let mut e = 0.0;
    for (&i, (si, &j)) in sx.iter().zip(ab.iter().enumerate()) {
        e += x.mass[i] * dist(si, j);
    }
    for (&i, (sj, &j)) in ba.iter().zip(sy.iter().enumerate()) {
        e += y.mass[j] * dist(i, sj);
    }
    Ok(e / (sx.len() + sy.len()) as f64)
}

#[cfg(test)]
mod tests;
