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
pub(crate) struct Window {
    pub face: usize,
    pub edge: usize,
    pub b0: f64,
    pub b1: f64,
    pub sx: f64,
    pub sy: f64,
    pub sigma: f64,
}

impl Window {
    pub fn dist_at(&self, x: f64) -> f64 {
        self.sigma + ((x - self.sx).powi(2) + self.sy * self.sy).sqrt()
    }

    pub fn min_dist(&self) -> f64 {
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
pub(crate) struct Item {
    pub key: f64,
    pub code: u64,
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
    /// Largest number of windows held in memory at once (the window-ordered
    /// scheme keeps every accepted window; VTP only the pending ones).
    pub peak_stored: usize,
}

pub(crate) struct Propagation<'a> {
    topo: &'a Topology,
    pub dist: Vec<f64>,
    /// Every accepted window; the queue and the slots refer to it by index.
    arena: Vec<Window>,
    /// Accepted windows per (face, edge) slot, `3 * face + edge`.
    slots: Vec<Vec<u32>>,
    /// Reused buffers of the pairwise trimming.
    bufs: TrimBuffers,
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
pub(crate) const SLACK: f64 = 1e-12;

impl<'a> Propagation<'a> {
    pub(crate) fn new(topo: &'a Topology) -> Self {
        Self {
            topo,
            dist: vec![f64::INFINITY; topo.ring.len()],
            arena: Vec::new(),
            slots: vec![Vec::new(); 3 * topo.faces.len()],
            bufs: TrimBuffers::default(),
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
        self.stats.peak_stored = self.arena.len();
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
            if let Some(w) = spoke_window(self.topo, f, k, d) {
                self.add_window(w);
            }
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
        if !trim(self.topo, &self.dist, &mut w) {
            return;
        }
        self.trim_by_accepted(w);
        let pieces = std::mem::take(&mut self.bufs.pieces);
        for &piece in &pieces {
            self.stats.windows += 1;
            self.push_window(piece);
        }
        self.bufs.pieces = pieces;
    }

    /// The parts of `w` no window already accepted on the same face-edge
    /// is at least as short at: see [`TrimBuffers::trim`].
    fn trim_by_accepted(&mut self, w: Window) {
        let le = self.topo.len[w.face][w.edge];
        let arena = &self.arena;
        let others = self.slots[3 * w.face + w.edge]
            .iter()
            .map(|&oi| &arena[oi as usize]);
        self.bufs.trim(w, others, le);
    }

    fn propagate(&mut self, w: &Window) {
        let mut w = *w;
        if !trim(self.topo, &self.dist, &mut w) {
            return;
        }
        self.stats.propagated += 1;
        let apex = Apex::new(self.topo, &w);
        // v3 is lit when its ray crosses the window, boundary rays included
        // (a geodesic along an edge through a flat vertex lies on one): it
        // must be relaxed here, since a child on a boundary edge is never
        // created.
        let eps = 1e-12 * apex.le;
        if apex.xv >= w.b0 - eps && apex.xv <= w.b1 + eps {
            let d = w.sigma + apex.dist_from(&w);
            self.relax(apex.v3, d);
        }
        children(self.topo, &w, &apex, (apex.xv, apex.xv), |child| {
            self.add_window(child)
        });
    }
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
pub(crate) fn trim(topo: &Topology, dist: &[f64], w: &mut Window) -> bool {
    let f = topo.faces[w.face];
    let le = topo.len[w.face][w.edge];
    let (e0, e1) = (f[(w.edge + 1) % 3], f[(w.edge + 2) % 3]);
    let (d0, d1) = (dist[e0], dist[e1]);
    if d0 == f64::INFINITY && d1 == f64::INFINITY {
        return w.b1 - w.b0 > 1e-12 * le;
    }
    let margin = 1e-10 * le;
    // W at the window's ends; an end that moves is re-evaluated.
    let (mut f0, f1) = (w.dist_at(w.b0), w.dist_at(w.b1));
    let tol = SLACK * (f0.max(f1) + le);
    if d0.is_finite() {
        if d0 + w.b1 < f1 - tol {
            return false;
        }
        if d0 + w.b0 < f0 - tol {
            let c = d0 - w.sigma;
            let den = 2.0 * (c + w.sx);
            if den > 0.0 {
                let x = (w.sx * w.sx + w.sy * w.sy - c * c) / den - margin;
                if x > w.b0 {
                    w.b0 = x.min(w.b1);
                    f0 = w.dist_at(w.b0);
                }
            }
        }
    }
    if d1.is_finite() {
        if d1 + (le - w.b0) < f0 - tol {
            return false;
        }
        if d1 + (le - w.b1) < f1 - tol {
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

/// The face a window propagates into, seen in the window's frame: its far
/// vertex `v3` at `(px, py)` (`py < 0`), and `xv`, where the ray from the
/// window's source through v3 meets the edge line.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Apex {
    pub v3: usize,
    pub px: f64,
    pub py: f64,
    pub xv: f64,
    pub le: f64,
}

impl Apex {
    pub(crate) fn new(t: &Topology, w: &Window) -> Self {
        let f = t.faces[w.face];
        let k = w.edge;
        let l = t.len[w.face];
        let le = l[k];
        let a = l[(k + 2) % 3]; // |e0 v3| (edge k+2 joins corners k and k+1)
        let b = l[(k + 1) % 3]; // |e1 v3|
        let px = (a * a - b * b + le * le) / (2.0 * le);
        let py = -(a * a - px * px).max(0.0).sqrt();
        Self {
            v3: f[k],
            px,
            py,
            xv: 0.0,
            le,
        }
        .for_window(w)
    }

    /// The same face seen from another window on the same edge.
    pub(crate) fn for_window(&self, w: &Window) -> Self {
        Self {
            xv: w.sx + (self.px - w.sx) * w.sy / (w.sy - self.py),
            ..*self
        }
    }

    /// Distance from the window's (pseudo-)source to v3 in the unfolding.
    pub(crate) fn dist_from(&self, w: &Window) -> f64 {
        ((self.px - w.sx).powi(2) + (self.py - w.sy).powi(2)).sqrt()
    }
}

/// Emits the windows `w` lights on the two other edges of its face, in the
/// frames of the faces beyond them (none across a boundary edge). Rays entering
/// left of `split.0` may reach the left edge (from e0 to v3), rays entering
/// right of `split.1` the right edge; `split = (xv, xv)` keeps every ray.
#[inline]
pub(crate) fn children(
    t: &Topology,
    w: &Window,
    apex: &Apex,
    split: (f64, f64),
    mut emit: impl FnMut(Window),
) {
    let f = t.faces[w.face];
    let k = w.edge;
    let l = t.len[w.face];
    let le = apex.le;
    let (e0, e1, v3) = (f[(k + 1) % 3], f[(k + 2) % 3], f[k]);
    let (px, py, xv) = (apex.px, apex.py, apex.xv);
    let s = [w.sx, w.sy];
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
        ((k + 2) % 3, w.b0, w.b1.min(split.0), e1),
        ((k + 1) % 3, w.b0.max(split.1), w.b1, e0),
    ];
    for (exit, x_lo, x_hi, other) in parts {
        if !(x_hi > x_lo) {
            continue;
        }
        let Some((g, j)) = t.adj(w.face, exit) else {
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
        // Parameters along A->B of the rays through x_lo and x_hi; an end
        // at v3 (the split point) is set exactly.
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
        emit(Window {
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

/// The window a pseudo-source at corner `k` of face `f`, at distance `d`,
/// casts on the opposite edge, in the frame of the face beyond (none when
/// that edge is on the boundary).
pub(crate) fn spoke_window(t: &Topology, f: usize, k: usize, d: f64) -> Option<Window> {
    let (g, j) = t.adj(f, k)?;
    let l = t.len[f];
    let b = t.faces[f][(k + 2) % 3];
    // v in the frame of edge j of g: x from that edge's start vertex (b for
    // a consistently oriented mesh, else a), y towards f (away from g).
    let lb = l[(k + 1) % 3]; // |v b|
    let la = l[(k + 2) % 3]; // |v a|
    let le = l[k];
    let (near, far) = if t.faces[g][(j + 1) % 3] == b {
        (lb, la)
    } else {
        (la, lb)
    };
    let sx = (near * near - far * far + le * le) / (2.0 * le);
    let sy = (near * near - sx * sx).max(0.0).sqrt();
    Some(Window {
        face: g,
        edge: j,
        b0: 0.0,
        b1: le,
        sx,
        sy,
        sigma: d,
    })
}

/// Reused buffers of the pairwise trimming of windows on one edge.
#[derive(Default)]
pub(crate) struct TrimBuffers {
    /// The surviving pieces of the last trimmed window.
    pub pieces: Vec<Window>,
    next: Vec<Window>,
}

impl TrimBuffers {
    /// The parts of `w` where none of `others` (windows on the same
    /// face-edge, of length `le`) is at least as short. Exact: a ray of `w` through a point
    /// where an accepted window `w'` is no longer can be rerouted through
    /// `w'` (bending there, so not shorter than `w'`'s own continuation),
    /// and accepted windows are only ever removed where something strictly
    /// shorter covers them. `W' − W` changes sign only at the roots of a
    /// quadratic (a hyperbola meets the edge line), so each piece between
    /// roots is kept or dropped whole, after checking its ends and middle.
    /// Leaves the surviving pieces in `self.pieces`.
    pub(crate) fn trim<'o>(
        &mut self,
        w: Window,
        others: impl Iterator<Item = &'o Window>,
        le: f64,
    ) {
        let mut pieces = std::mem::take(&mut self.pieces);
        let mut next = std::mem::take(&mut self.next);
        pieces.clear();
        pieces.push(w);
        let (w_lo, w_hi) = (w.b0, w.b1);
        let mut w_max = f64::NAN;
        for o in others {
            // Cheap rejections: no overlap, or `o` longer everywhere on it
            // than `w` anywhere (W is convex, so its maximum is at an end).
            let (lo, hi) = (w_lo.max(o.b0), w_hi.min(o.b1));
            if hi - lo <= 1e-12 * le {
                continue;
            }
            if w_max.is_nan() {
                w_max = w.dist_at(w_lo).max(w.dist_at(w_hi)) * (1.0 + 4.0 * SLACK) + SLACK * le;
            }
            let o_min = if o.sx >= lo && o.sx <= hi {
                o.sigma + o.sy
            } else {
                o.dist_at(lo).min(o.dist_at(hi))
            };
            if o_min > w_max {
                continue;
            }
            next.clear();
            for &p in &pieces {
                let (lo, hi) = (p.b0.max(o.b0), p.b1.min(o.b1));
                if hi - lo <= 1e-12 * le {
                    next.push(p);
                    continue;
                }
                // Cut points: the overlap's ends and the crossings inside.
                let mut cuts = [0.0; 4];
                cuts[0] = lo;
                let mut nc = 1;
                let (r, nr) = crossings(&p, o);
                let (r0, r1) = if nr == 2 && r[1] < r[0] {
                    (r[1], r[0])
                } else {
                    (r[0], r[1])
                };
                for x in [r0, r1].into_iter().take(nr) {
                    if x > cuts[nc - 1] + 1e-14 * le && x < hi - 1e-14 * le {
                        cuts[nc] = x;
                        nc += 1;
                    }
                }
                cuts[nc] = hi;
                nc += 1;
                // Between cuts W' − W keeps its sign: a piece is dropped
                // when W' ≤ W at both its ends and in its middle.
                let below = |x: f64| {
                    let px = p.dist_at(x);
                    o.dist_at(x) <= px + SLACK * (px + le)
                };
                // Cut points are tested lazily, once each (most pieces
                // already fail in the middle).
                let mut at: [Option<bool>; 4] = [None; 4];
                let mut start = p.b0;
                for i in 0..nc - 1 {
                    let (a, b) = (cuts[i], cuts[i + 1]);
                    let dominated = b - a > 1e-12 * le
                        && below(0.5 * (a + b))
                        && *at[i].get_or_insert_with(|| below(a))
                        && *at[i + 1].get_or_insert_with(|| below(b));
                    if dominated {
                        if a - start > 1e-12 * le {
                            let mut q = p;
                            q.b0 = start;
                            q.b1 = a;
                            next.push(q);
                        }
                        start = b;
                    }
                }
                if p.b1 - start > 1e-12 * le {
                    let mut q = p;
                    q.b0 = start;
                    next.push(q);
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
    }
}
