//! The data side of the ball search: each ball's centre, radius and
//! tangent box, and each row's distance to its centre and coordinates
//! (see [`super`]).

use super::{TANGENT, slack};
use crate::rows::dot8 as dot;

/// The per-ball geometry of [`super::BallData`] (see its fields).
pub(super) struct Geometry {
    /// The ball centres (means; row-major, m x d) and the balls' radii
    /// (rounded up).
    pub(super) centers: Vec<f64>,
    pub(super) radii: Vec<f64>,
    /// Each row's distance to its ball's centre (ball order).
    pub(super) to_center: Vec<f64>,
    /// Per ball, [`TANGENT`] orthonormal directions (row-major,
    /// `TANGENT x d`; unused ones zero) spanning most of its rows' spread.
    pub(super) tangent: Vec<f64>,
    /// Per ball, the box `[lo, hi]` of the rows' coordinates along its
    /// directions (rounded outwards), and a bound on the rows' distance
    /// to their affine span.
    pub(super) box_lo: Vec<f64>,
    pub(super) box_hi: Vec<f64>,
    pub(super) r_perp: Vec<f64>,
    /// Per row (ball order): its coordinates along its ball's directions
    /// (direction by direction: `row_tan[i * n + p]`) and a bound on its
    /// distance to their affine span.
    pub(super) row_tan: Vec<f64>,
    pub(super) row_perp: Vec<f64>,
    /// Per ball, its directions' dot products with its centre.
    pub(super) uc: Vec<f64>,
    /// A bound on `‖UUᵀ − I‖` over every ball's directions `U`.
    pub(super) eta: f64,
}

crate::cpu::dispatched! {
    /// Each ball's centre, radius and tangent box, and each row's distance
    /// to its centre and coordinates, of the rows `x_ord` (row-major, `d`
    /// wide, in ball order; ball `b` is `ranges[b]`).
    pub(super) fn geometry(x_ord: &[f64], d: usize, ranges: &[(usize, usize)]) -> Geometry {
            let (m, nx) = (ranges.len(), x_ord.len() / d.max(1));
            let sl = slack(d);
            let mut centers = vec![0.0; m * d];
            let mut radii = vec![0.0; m];
            let mut to_center = vec![0.0; nx];
            let mut tangent = vec![0.0; m * TANGENT * d];
            let mut box_lo = vec![0.0; m * TANGENT];
            let mut box_hi = vec![0.0; m * TANGENT];
            let mut r_perp = vec![0.0; m];
            let mut row_tan = vec![0.0; nx * TANGENT];
            let mut row_perp = vec![0.0; nx];
            let mut uc = vec![0.0; m * TANGENT];
            let mut eta = 0.0f64;
            // Per ball: its rows less the mean, their squared norms, and
            // what the directions leave of them.
            let (mut e, mut n0, mut res) = (Vec::new(), Vec::new(), Vec::new());
            for (c, &(start, len)) in ranges.iter().enumerate() {
                let rows = &x_ord[start * d..(start + len) * d];
                let mean = &mut centers[c * d..(c + 1) * d];
                for row in rows.chunks_exact(d) {
                    for (m, x) in mean.iter_mut().zip(row) {
                        *m += x;
                    }
                }
                for v in mean.iter_mut() {
                    *v /= len as f64;
                }
                let mean = &centers[c * d..(c + 1) * d];
                e.clear();
                n0.clear();
                for row in rows.chunks_exact(d) {
                    let at = e.len();
                    e.extend(row.iter().zip(mean).map(|(x, m)| x - m));
                    n0.push(dot(&e[at..], &e[at..]));
                }
                let mut r2 = 0.0f64;
                for (t, &v) in n0.iter().enumerate() {
                    to_center[start + t] = v.sqrt();
                    r2 = r2.max(v);
                }
                let r = r2.sqrt() * (1.0 + sl) + f64::MIN_POSITIVE;
                radii[c] = r;
                // The directions: greedy pivoted Gram–Schmidt (the row
                // farthest from the span so far, orthogonalised twice
                // against the directions before it, normalised). Each
                // row's coordinate along a new direction is computed once,
                // as the coordinate the bounds use and to downdate what
                // the span leaves of the row (`|r|² − a²`, which only
                // guides the next choice); a row left below 1e-12 of the
                // largest norm² gives no direction.
                let u = &mut tangent[c * TANGENT * d..(c + 1) * TANGENT * d];
                res.clear();
                res.extend_from_slice(&n0);
                let floor = 1e-12 * r2;
                for i in 0..TANGENT {
                    let (mut arg, mut big) = (usize::MAX, floor);
                    for (t, &v) in res.iter().enumerate() {
                        if v > big {
                            (arg, big) = (t, v);
                        }
                    }
                    if arg == usize::MAX {
                        break;
                    }
                    let (done, rest) = u.split_at_mut(i * d);
                    let w = &mut rest[..d];
                    w.copy_from_slice(&e[arg * d..(arg + 1) * d]);
                    for _ in 0..2 {
                        for k in 0..i {
                            let uk = &done[k * d..(k + 1) * d];
                            let a = dot(uk, w);
                            for (w, u) in w.iter_mut().zip(uk) {
                                *w -= a * u;
                            }
                        }
                    }
                    let nw = dot(w, w).sqrt();
                    if !(nw > 0.0) {
                        w.fill(0.0);
                        break;
                    }
                    for v in w.iter_mut() {
                        *v /= nw;
                    }
                    for (t, row) in e.chunks_exact(d).enumerate() {
                        let a = dot(w, row);
                        row_tan[i * nx + start + t] = a;
                        res[t] -= a * a;
                    }
                }
                // ‖UUᵀ − I‖ ≤ its Frobenius norm (plus a margin for its own
                // rounding).
                let mut f = 0.0;
                for i in 0..TANGENT {
                    for k in 0..TANGENT {
                        let g = dot(&u[i * d..(i + 1) * d], &u[k * d..(k + 1) * d]);
                        let want = if i == k && u[i * d..(i + 1) * d].iter().any(|&v| v != 0.0) {
                            1.0
                        } else {
                            0.0
                        };
                        f += (g - want) * (g - want);
                    }
                }
                // (The query-time bounds use 1 − η ≤ 1/(1 + η) and 1 + 2η ≥
                // 1/(1 − η), true for η ≤ 1/2: a ball whose directions are
                // that far from orthonormal gets none.)
                // (Directions never found were never measured: their
                // coordinates stay zero.)
                if f.sqrt() + 1e-14 > 0.25 {
                    u.fill(0.0);
                    f = 0.0;
                    for i in 0..TANGENT {
                        row_tan[i * nx + start..i * nx + start + len].fill(0.0);
                    }
                }
                eta = eta.max(f.sqrt() + 1e-14);
                let (lo, hi) = (
                    &mut box_lo[c * TANGENT..(c + 1) * TANGENT],
                    &mut box_hi[c * TANGENT..(c + 1) * TANGENT],
                );
                lo.fill(f64::INFINITY);
                hi.fill(f64::NEG_INFINITY);
                let mut perp2 = 0.0f64;
                for (k, &nk) in n0.iter().enumerate() {
                    let mut a2 = 0.0;
                    for i in 0..TANGENT {
                        let a = row_tan[i * nx + start + k];
                        lo[i] = lo[i].min(a);
                        hi[i] = hi[i].max(a);
                        a2 += a * a;
                    }
                    let p2 = nk * (1.0 + sl) - a2 * (1.0 - sl) / (1.0 + eta);
                    row_perp[start + k] = (p2.max(0.0) + sl * r * r).sqrt() * (1.0 + sl);
                    perp2 = perp2.max(p2);
                }
                // Outwards by the coordinates' rounding (at most sl r).
                lo.iter_mut().for_each(|v| *v -= sl * r);
                hi.iter_mut().for_each(|v| *v += sl * r);
                r_perp[c] = (perp2.max(0.0) + sl * r * r).sqrt() * (1.0 + sl);
                for i in 0..TANGENT {
                    uc[c * TANGENT + i] = dot(&u[i * d..(i + 1) * d], mean);
                }
            }
        Geometry {
            centers,
            radii,
            to_center,
            tangent,
            box_lo,
            box_hi,
            r_perp,
            row_tan,
            row_perp,
            uc,
            eta,
        }
    }
}
