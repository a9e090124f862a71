//! Exact polyhedral geodesic distances by window propagation.
//!
//! The continuous Dijkstra of Mitchell, Mount and Papadimitriou (1987) in
//! the simple form of Chen and Han (1990) as improved by Xin and Wang
//! ("Improving Chen and Han's algorithm on the discrete geodesic problem",
//! ACM TOG 28(4), 2009): a *window* is an interval of an edge lit by one
//! (pseudo-)source through a sequence of unfolded faces, stored as the
//! source's position in the edge's own 2D frame plus the distance σ already
//! travelled to reach that pseudo-source. Windows are processed in order of
//! their smallest distance; each one is unfolded across the next face and
//! split into at most two children on the face's other edges. Geodesics
//! bend only at saddle and boundary vertices, which become pseudo-sources
//! when reached. Windows are discarded when an endpoint vertex already
//! offers a shorter path to every point of them, and trimmed to the part
//! no endpoint vertex dominates (exact; see `trim`).
//!
//! Everything is intrinsic: only edge lengths are used.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::topology::Topology;

/// A lit interval `[b0, b1]` of edge `edge` of face `face`, seen from a
/// pseudo-source at `(sx, sy)` (`sy >= 0`) in the edge's frame: origin at
/// the edge's start vertex, x along the edge, y pointing away from `face`.
/// The window propagates into `face`.
#[derive(Debug, Clone, Copy)]
struct Window {
    face: usize,
    edge: usize,
    b0: f64,
    b1: f64,
    sx: f64,
    sy: f64,
    sigma: f64,
}

impl Window {
    fn dist_at(&self, x: f64) -> f64 {
        self.sigma + ((x - self.sx).powi(2) + self.sy * self.sy).sqrt()
    }

    fn min_dist(&self) -> f64 {
        if self.sx >= self.b0 && self.sx <= self.b1 {
            self.sigma + self.sy
        } else {
            self.dist_at(self.b0).min(self.dist_at(self.b1))
        }
    }
}

/// A queue entry: 16 bytes, so the heap sifts cheaply. `code` is a window's
/// index in the arena (`code & 1 == 0`) or a pseudo-source vertex
/// (`code & 1 == 1`), shifted left by one.
#[derive(Clone, Copy)]
struct Item {
    key: f64,
    code: u64,
}

impl PartialEq for Item {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Item {}
impl PartialOrd for Item {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Item {
    // Min-heap on (key, code): BinaryHeap is a max-heap, so reverse.
    fn cmp(&self, o: &Self) -> Ordering {
        o.key.total_cmp(&self.key).then(o.code.cmp(&self.code))
    }
}

/// Statistics of one propagation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ExactStats {
    /// Windows created.
    pub windows: u64,
    /// Windows propagated across a face (the rest were discarded).
    pub propagated: u64,
    /// Largest size of the event queue.
    pub peak_queue: usize,
}

pub(crate) struct Propagation<'a> {
    topo: &'a Topology,
    pub dist: Vec<f64>,
    /// Every accepted window; the queue and the slots refer to it by index.
    arena: Vec<Window>,
    /// Accepted windows per (face, edge) slot, `3 * face + edge`.
    slots: Vec<Vec<u32>>,
    /// Reused buffers of the pairwise trimming.
    pieces: Vec<Window>,
    next: Vec<Window>,
    cuts: Vec<f64>,
    heap: BinaryHeap<Item>,
    pub stats: ExactStats,
}

/// Points x where two windows on the same edge give equal distances:
/// σ + |x − s| = σ' + |x − s'| on the edge line, squared twice into a
/// quadratic (spurious roots only add harmless cuts).
fn crossings(w: &Window, o: &Window) -> ([f64; 2], usize) {
    let (a, b, a2, b2) = (w.sx, w.sy, o.sx, o.sy);
    let c = o.sigma - w.sigma;
    let alpha = 2.0 * (a2 - a);
    let gamma = a * a + b * b - a2 * a2 - b2 * b2 - c * c;
    // (αx + γ)² = 4c² ((x − a')² + b'²)
    let qa = alpha * alpha - 4.0 * c * c;
    let qb = 2.0 * alpha * gamma + 8.0 * c * c * a2;
    let qc = gamma * gamma - 4.0 * c * c * (a2 * a2 + b2 * b2);
    let scale = qa.abs().max(qb.abs()).max(qc.abs());
    if scale == 0.0 {
        return ([0.0; 2], 0);
    }
    if qa.abs() <= 1e-12 * scale {
        return if qb != 0.0 {
            ([-qc / qb, 0.0], 1)
        } else {
            ([0.0; 2], 0)
        };
    }
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 {
        return ([0.0; 2], 0);
    }
    let r = disc.sqrt();
    // Numerically stable pair of roots.
    let q = -0.5 * (qb + qb.signum() * r);
    if q != 0.0 {
        ([q / qa, qc / q], 2)
    } else {
        ([q / qa, 0.0], 1)
    }
}

/// Joins touching pieces of one window (same source) back together.
fn merge(pieces: &mut Vec<Window>, le: f64) {
    if pieces.len() < 2 {
        return;
    }
    pieces.sort_by(|x, y| x.b0.total_cmp(&y.b0));
    let mut k = 0;
    for i in 1..pieces.len() {
        let p = pieces[i];
        let last = &mut pieces[k];
        if p.b0 - last.b1 <= 1e-14 * le
            && p.sx == last.sx
            && p.sy == last.sy
            && p.sigma == last.sigma
        {
            last.b1 = last.b1.max(p.b1);
        } else {
            k += 1;
            pieces[k] = p;
        }
    }
    pieces.truncate(k + 1);
}

/// Relative slack of the pruning tests, so that a window is never
/// discarded because of rounding in its own contribution.
const SLACK: f64 = 1e-12;

impl<'a> Propagation<'a> {
    pub(crate) fn new(topo: &'a Topology) -> Self {
        Self {
            topo,
            dist: vec![f64::INFINITY; topo.ring.len()],
            arena: Vec::new(),
            slots: vec![Vec::new(); 3 * topo.faces.len()],
            pieces: Vec::new(),
            next: Vec::new(),
            cuts: Vec::new(),
            heap: BinaryHeap::new(),
            stats: ExactStats::default(),
        }
    }

    /// Runs from the given sources until the queue is empty, or until every
    /// vertex of `targets` (when given) is final.
    pub(crate) fn run(&mut self, sources: &[usize], targets: Option<&[usize]>) {
        for &s in sources {
            self.dist[s] = 0.0;
            self.push_vertex(s, 0.0);
        }
        while let Some(item) = self.heap.pop() {
            if let Some(t) = targets {
                // Every remaining event is at least `item.key` away, so a
                // target with a distance at most that is final.
                if t.iter().all(|&v| self.dist[v] <= item.key) {
                    break;
                }
            }
            let id = (item.code >> 1) as usize;
            if item.code & 1 == 1 {
                // A vertex event is stale once the vertex got closer.
                if item.key <= self.dist[id] {
                    self.expand_vertex(id, item.key);
                }
            } else {
                let w = self.arena[id];
                self.propagate(&w);
            }
        }
    }

    fn push_vertex(&mut self, v: usize, d: f64) {
        self.heap.push(Item {
            key: d,
            code: ((v as u64) << 1) | 1,
        });
        self.stats.peak_queue = self.stats.peak_queue.max(self.heap.len());
    }

    fn push_window(&mut self, w: Window) {
        let id = self.arena.len();
        self.arena.push(w);
        self.slots[3 * w.face + w.edge].push(id as u32);
        self.heap.push(Item {
            key: w.min_dist(),
            code: (id as u64) << 1,
        });
        self.stats.peak_queue = self.stats.peak_queue.max(self.heap.len());
    }

    /// Lowers the distance of `v`; a pseudo-source vertex is queued for
    /// expansion.
    fn relax(&mut self, v: usize, d: f64) {
        if d < self.dist[v] {
            self.dist[v] = d;
            if self.topo.pseudo_source[v] {
                self.push_vertex(v, d);
            }
        }
    }

    /// Emits a window from vertex `v` (distance `d`) through every face
    /// around it, onto the edge opposite `v`.
    fn expand_vertex(&mut self, v: usize, d: f64) {
        for &(f, k) in &self.topo.ring[v] {
            let l = self.topo.len[f];
            // Edge k of f is opposite v. Its endpoints get d + spoke length.
            let f_ = self.topo.faces[f];
            let (a, b) = (f_[(k + 1) % 3], f_[(k + 2) % 3]);
            self.relax(a, d + l[(k + 2) % 3]);
            self.relax(b, d + l[(k + 1) % 3]);
            let Some((g, j)) = self.topo.adj[f][k] else {
                continue;
            };
            // v in the frame of edge j of g: x from that edge's start
            // vertex (b for a consistently oriented mesh, else a), y
            // towards f (away from g).
            let lb = l[(k + 1) % 3]; // |v b|
            let la = l[(k + 2) % 3]; // |v a|
            let le = l[k];
            let (near, far) = if self.topo.faces[g][(j + 1) % 3] == b {
                (lb, la)
            } else {
                (la, lb)
            };
            let sx = (near * near - far * far + le * le) / (2.0 * le);
            let sy = (near * near - sx * sx).max(0.0).sqrt();
            self.add_window(Window {
                face: g,
                edge: j,
                b0: 0.0,
                b1: le,
                sx,
                sy,
                sigma: d,
            });
        }
    }

    fn add_window(&mut self, w: Window) {
        let le = self.topo.len[w.face][w.edge];
        if !(w.b1 - w.b0 > 1e-12 * le) {
            return;
        }
        let f = self.topo.faces[w.face];
        let (e0, e1) = (f[(w.edge + 1) % 3], f[(w.edge + 2) % 3]);
        // Endpoint vertices lit by the window get its distance.
        if w.b0 <= 1e-12 * le {
            self.relax(e0, w.dist_at(0.0));
        }
        if w.b1 >= le * (1.0 - 1e-12) {
            self.relax(e1, w.dist_at(le));
        }
        let mut w = w;
        if !self.trim(&mut w) {
            return;
        }
        self.trim_by_accepted(w);
        let pieces = std::mem::take(&mut self.pieces);
        for &piece in &pieces {
            self.stats.windows += 1;
            self.push_window(piece);
        }
        self.pieces = pieces;
    }

    /// The parts of `w` where no window already accepted on the same
    /// face-edge is at least as short. Exact: a ray of `w` through a point
    /// where an accepted window `w'` is no longer can be rerouted through
    /// `w'` (bending there, so not shorter than `w'`'s own continuation),
    /// and accepted windows are only ever removed where something strictly
    /// shorter covers them. `W' − W` changes sign only at the roots of a
    /// quadratic (a hyperbola meets the edge line), so each piece between
    /// roots is kept or dropped whole, after checking its ends and middle.
    /// Leaves the surviving pieces in `self.pieces`.
    fn trim_by_accepted(&mut self, w: Window) {
        let le = self.topo.len[w.face][w.edge];
        let mut pieces = std::mem::take(&mut self.pieces);
        let mut next = std::mem::take(&mut self.next);
        let mut cuts = std::mem::take(&mut self.cuts);
        pieces.clear();
        pieces.push(w);
        for &oi in &self.slots[3 * w.face + w.edge] {
            let o = &self.arena[oi as usize];
            next.clear();
            for &p in &pieces {
                let (lo, hi) = (p.b0.max(o.b0), p.b1.min(o.b1));
                if hi - lo <= 1e-12 * le {
                    next.push(p);
                    continue;
                }
                cuts.clear();
                cuts.extend([p.b0, lo, hi, p.b1]);
                let (r, nr) = crossings(&p, o);
                cuts.extend(r[..nr].iter().copied().filter(|&x| x > lo && x < hi));
                cuts.sort_by(f64::total_cmp);
                cuts.dedup_by(|a, b| (*a - *b).abs() <= 1e-14 * le);
                for seg in cuts.windows(2) {
                    let (a, b) = (seg[0], seg[1]);
                    if b - a <= 1e-12 * le {
                        continue;
                    }
                    let inside = a >= lo - 1e-14 * le && b <= hi + 1e-14 * le;
                    let dominated = inside && {
                        let tol = SLACK * (p.dist_at(a) + le);
                        [a, 0.5 * (a + b), b]
                            .iter()
                            .all(|&x| o.dist_at(x) <= p.dist_at(x) + tol)
                    };
                    if !dominated {
                        let mut q = p;
                        q.b0 = a;
                        q.b1 = b;
                        next.push(q);
                    }
                }
            }
            merge(&mut next, le);
            std::mem::swap(&mut pieces, &mut next);
            if pieces.is_empty() {
                break;
            }
        }
        self.pieces = pieces;
        self.next = next;
        self.cuts = cuts;
    }

    /// Trims a window to the part no endpoint vertex of its edge
    /// dominates; false when nothing is left.
    ///
    /// A point x of the window is dominated by e0 when D(e0) + x < W(x):
    /// every path through x can be rerouted through e0 (along the edge to
    /// x, then on the same straight unfolded segment) and made strictly
    /// shorter, so no geodesic crosses the window at x. Because W(x) − x
    /// never increases, the points dominated by e0 form an interval at the
    /// e0 end, bounded by the root of D(e0) + x = σ + |s − (x, 0)|, which
    /// is x* = (sx² + sy² − c²) / (2 (c + sx)) with c = D(e0) − σ; the same
    /// holds mirrored for e1. A geodesic point is never dominated (its
    /// distance is already the shortest), so trimming keeps the result
    /// exact; a margin of 1e-10 edge lengths absorbs rounding.
    fn trim(&self, w: &mut Window) -> bool {
        let f = self.topo.faces[w.face];
        let le = self.topo.len[w.face][w.edge];
        let (e0, e1) = (f[(w.edge + 1) % 3], f[(w.edge + 2) % 3]);
        let margin = 1e-10 * le;
        let tol = SLACK * (w.dist_at(w.b0).max(w.dist_at(w.b1)) + le);
        let d0 = self.dist[e0];
        if d0.is_finite() {
            if d0 + w.b1 < w.dist_at(w.b1) - tol {
                return false;
            }
            if d0 + w.b0 < w.dist_at(w.b0) - tol {
                let c = d0 - w.sigma;
                let den = 2.0 * (c + w.sx);
                if den > 0.0 {
                    let x = (w.sx * w.sx + w.sy * w.sy - c * c) / den - margin;
                    if x > w.b0 {
                        w.b0 = x.min(w.b1);
                    }
                }
            }
        }
        let d1 = self.dist[e1];
        if d1.is_finite() {
            if d1 + (le - w.b0) < w.dist_at(w.b0) - tol {
                return false;
            }
            if d1 + (le - w.b1) < w.dist_at(w.b1) - tol {
                // Mirror: x' = le − x, source at le − sx.
                let c = d1 - w.sigma;
                let sxm = le - w.sx;
                let den = 2.0 * (c + sxm);
                if den > 0.0 {
                    let xm = (sxm * sxm + w.sy * w.sy - c * c) / den - margin;
                    let x = le - xm;
                    if x < w.b1 {
                        w.b1 = x.max(w.b0);
                    }
                }
            }
        }
        w.b1 - w.b0 > 1e-12 * le
    }

    fn propagate(&mut self, w: &Window) {
        let mut w = *w;
        if !self.trim(&mut w) {
            return;
        }
        let w = &w;
        self.stats.propagated += 1;
        let t = self.topo;
        let f = t.faces[w.face];
        let k = w.edge;
        let l = t.len[w.face];
        let le = l[k];
        let (e0, e1, v3) = (f[(k + 1) % 3], f[(k + 2) % 3], f[k]);
        // The third vertex in the window frame: below the edge (y < 0).
        let a = l[(k + 2) % 3]; // |e0 v3| (edge k+2 joins corners k and k+1)
        let b = l[(k + 1) % 3]; // |e1 v3|
        let px = (a * a - b * b + le * le) / (2.0 * le);
        let py = -(a * a - px * px).max(0.0).sqrt();
        let s = [w.sx, w.sy];
        // Where the ray from s through v3 crosses the edge line (y = 0).
        let xv = s[0] + (px - s[0]) * s[1] / (s[1] - py);
        // v3 is lit when its ray crosses the window, boundary rays included
        // (a geodesic along an edge through a flat vertex lies on one): it
        // must be relaxed here, since a child on a boundary edge is never
        // created.
        let eps = 1e-12 * le;
        if xv >= w.b0 - eps && xv <= w.b1 + eps {
            let d = w.sigma + ((px - s[0]).powi(2) + (py - s[1]).powi(2)).sqrt();
            self.relax(v3, d);
        }
        let pos = |vid: usize| -> [f64; 2] {
            if vid == e0 {
                [0.0, 0.0]
            } else if vid == e1 {
                [le, 0.0]
            } else {
                [px, py]
            }
        };
        // Left part of the wedge (x < xv) exits through edge e0–v3, which is
        // edge k+2 of f; the right part through e1–v3, edge k+1.
        let parts = [
            ((k + 2) % 3, w.b0, w.b1.min(xv), e1),
            ((k + 1) % 3, w.b0.max(xv), w.b1, e0),
        ];
        for (exit, x_lo, x_hi, other) in parts {
            if !(x_hi > x_lo) {
                continue;
            }
            let Some((g, j)) = t.adj[w.face][exit] else {
                continue;
            };
            // Edge j of g runs from A to B, both on the exit edge.
            let gf = t.faces[g];
            let (pa, pb) = (pos(gf[(j + 1) % 3]), pos(gf[(j + 2) % 3]));
            let lc = l[exit];
            let u = [(pb[0] - pa[0]) / lc, (pb[1] - pa[1]) / lc];
            // Normal pointing into f (towards the vertex not on this edge).
            let po = pos(other);
            let mut nrm = [-u[1], u[0]];
            if (po[0] - pa[0]) * nrm[0] + (po[1] - pa[1]) * nrm[1] < 0.0 {
                nrm = [u[1], -u[0]];
            }
            let rel = [s[0] - pa[0], s[1] - pa[1]];
            let sx = rel[0] * u[0] + rel[1] * u[1];
            let sy = (rel[0] * nrm[0] + rel[1] * nrm[1]).max(0.0);
            // Parameters along A->B of the rays through x_lo and x_hi; an
            // end at v3 (the split point) is set exactly.
            let param = |x: f64| -> f64 {
                let dir = [x - s[0], -s[1]];
                let cr = dir[0] * u[1] - dir[1] * u[0];
                let num = dir[0] * rel[1] - dir[1] * rel[0];
                // t with A + t u on the ray: cross(dir, A + t u − s) = 0,
                // i.e. t = cross(dir, s − A) / cross(dir, u).
                num / cr
            };
            let v3_param = if gf[(j + 1) % 3] == v3 { 0.0 } else { lc };
            let t_lo = if x_lo == xv { v3_param } else { param(x_lo) };
            let t_hi = if x_hi == xv { v3_param } else { param(x_hi) };
            let (mut b0, mut b1) = if t_lo <= t_hi {
                (t_lo, t_hi)
            } else {
                (t_hi, t_lo)
            };
            if !(b0.is_finite() && b1.is_finite()) {
                continue;
            }
            b0 = b0.clamp(0.0, lc);
            b1 = b1.clamp(0.0, lc);
            self.add_window(Window {
                face: g,
                edge: j,
                b0,
                b1,
                sx,
                sy,
                sigma: w.sigma,
            });
        }
    }
}
