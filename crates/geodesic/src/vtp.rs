//! Exact polyhedral geodesics by vertex-oriented triangle propagation, the
//! scheduling of VTP (Qin, Han, Yu, Yu and Zhang, "Fast and exact discrete
//! geodesic computation based on triangle-oriented wavefront propagation",
//! ACM TOG 35(4), 2016), on the windows of [`crate::exact`].
//!
//! Windows are not queued one by one. Each half-edge slot (a face and the
//! edge windows enter it through) holds a list of pending windows, and a
//! priority queue holds *vertices*, as in Dijkstra's algorithm. When the
//! nearest vertex is settled, the lists on the edges around it are
//! propagated across their faces, a whole list at a time, in FIFO order;
//! the children are appended to the lists beyond and propagated in turn
//! while their edge touches a settled vertex.
//!
//! Pruning, every rule exact:
//! - a window is trimmed to the part its edge's endpoints do not dominate
//!   (with the vertex distances of the time its list is propagated);
//! - one angle, two sides: the shortest known path to the face's far
//!   vertex through the edge splits the face, and no ray crosses it;
//! - saddle shadows: a shortest path through a vertex makes an angle of at
//!   least π on both sides, so a saddle casts windows only into the narrow
//!   sector of directions that can continue one. On scanned meshes half
//!   the vertices are saddles with a few degrees of excess angle; casting
//!   all around them made 2.7x more windows (2.3x the time) on FAUST.
//!
//! VTP also trims the windows of a list against each other; here that
//! removed 30% of the windows but cost more than it saved, so it is not
//! done. The order only affects how much is pruned, and every list is
//! eventually propagated, so the distances are exact.

use std::collections::{BinaryHeap, VecDeque};
use std::f64::consts::PI;

use crate::exact::{Apex, ExactStats, Item, SLACK, Window, children, spoke_window, trim};
use crate::topology::{Topology, corner_angle};

const NIL: u32 = u32::MAX;
const OUTSIDE: u8 = 0;
const FRONT: u8 = 1;
const INSIDE: u8 = 2;

#[derive(Clone, Copy)]
struct Node {
    w: Window,
    next: u32,
}

pub(crate) struct Vtp<'a> {
    topo: &'a Topology,
    fans: &'a Fans,
    /// Per vertex, the direction its best path arrives from, and whether
    /// paths of that length arrive from several directions.
    dir: Vec<f64>,
    any_dir: Vec<bool>,
    /// Whether a vertex's last cast went all around (not only its shadow).
    emitted_everywhere: Vec<bool>,
    pub dist: Vec<f64>,
    state: Vec<u8>,
    /// Distance at which each vertex last cast its pseudo-source windows.
    emitted: Vec<f64>,
    heap: BinaryHeap<Item>,
    /// Window storage: per-slot singly linked lists and a free list.
    nodes: Vec<Node>,
    free: u32,
    head: Vec<u32>,
    queued: Vec<bool>,
    fifo: VecDeque<u32>,
    /// Per slot, the shortest path to the far vertex found through it and
    /// where it crosses the edge: `(length, x)`.
    best_top: Vec<(f64, f64)>,
    /// Settled pseudo-source vertices whose distance dropped: they cast
    /// their windows again.
    recast: Vec<usize>,
    /// Reused per list: the windows left after trimming, and for each its
    /// path to the far vertex `(length, crossing x, x of the straight
    /// ray)`.
    kept: Vec<Window>,
    d3s: Vec<(f64, f64, f64)>,
    /// Early stop: per slot the nearest distance of its pending windows,
    /// and a heap of (minimum, slot) with stale entries.
    track: bool,
    slot_min: Vec<f64>,
    pending: BinaryHeap<Item>,
    pub stats: ExactStats,
}

impl<'a> Vtp<'a> {
    pub(crate) fn new(topo: &'a Topology, fans: &'a Fans) -> Self {
        let n = topo.ring.len();
        let slots = 3 * topo.faces.len();
        Self {
            topo,
            fans,
            dir: vec![0.0; n],
            any_dir: vec![false; n],
            emitted_everywhere: vec![false; n],
            d3s: Vec::new(),
            dist: vec![f64::INFINITY; n],
            state: vec![OUTSIDE; n],
            emitted: vec![f64::INFINITY; n],
            heap: BinaryHeap::new(),
            nodes: Vec::new(),
            free: NIL,
            head: vec![NIL; slots],
            queued: vec![false; slots],
            fifo: VecDeque::new(),
            best_top: vec![(f64::INFINITY, 0.0); slots],
            recast: Vec::new(),
            kept: Vec::new(),
            track: false,
            slot_min: Vec::new(),
            pending: BinaryHeap::new(),
            stats: ExactStats::default(),
        }
    }

    /// Propagates from `sources` over the whole mesh.
    /// Propagates from `sources` over the whole mesh, or until every vertex
    /// of `targets` (when given) is final.
    ///
    /// Early stop: every later distance descends from a pending window (and
    /// is at least that window's nearest distance) or from a vertex still
    /// in the queue (at least its key), so a target whose distance is at
    /// most the smallest of those is final. The pending windows' minima are
    /// tracked per slot in a second, lazily cleaned heap, only when
    /// targets are given.
    pub(crate) fn run(&mut self, sources: &[usize], targets: Option<&[usize]>) {
        self.track = targets.is_some();
        if self.track {
            self.slot_min = vec![f64::INFINITY; self.head.len()];
        }
        for &s in sources {
            self.dist[s] = 0.0;
        }
        for &s in sources {
            if self.state[s] != INSIDE {
                self.settle(s, true);
            }
        }
        self.drain();
        loop {
            if let Some(t) = targets {
                let bound = self.lower_bound();
                if t.iter().all(|&v| self.dist[v] <= bound) {
                    break;
                }
            }
            let Some(item) = self.heap.pop() else {
                break;
            };
            let v = item.code as usize;
            if self.state[v] == INSIDE || item.key > self.dist[v] {
                continue;
            }
            self.settle(v, false);
            self.drain();
        }
    }

    /// A lower bound of every distance still to be found (tracking on).
    fn lower_bound(&mut self) -> f64 {
        while let Some(top) = self.heap.peek() {
            let v = top.code as usize;
            if self.state[v] == INSIDE || top.key > self.dist[v] {
                self.heap.pop();
            } else {
                break;
            }
        }
        while let Some(top) = self.pending.peek() {
            if top.key != self.slot_min[top.code as usize] {
                self.pending.pop();
            } else {
                break;
            }
        }
        let a = self.heap.peek().map_or(f64::INFINITY, |i| i.key);
        let b = self.pending.peek().map_or(f64::INFINITY, |i| i.key);
        a.min(b)
    }

    /// Marks `v` settled, casts its windows if it is a source or a
    /// pseudo-source, and queues the lists around it.
    fn settle(&mut self, v: usize, source: bool) {
        let t = self.topo;
        self.state[v] = INSIDE;
        for &(u, _) in &t.neighbours[v] {
            if self.state[u] == OUTSIDE {
                self.state[u] = FRONT;
            }
        }
        if source || t.pseudo_source[v] {
            self.cast(v, source);
        }
        for &(f, kv) in &t.ring[v] {
            // The two edges of f at v, entering f.
            self.enqueue(3 * f + (kv + 1) % 3);
            self.enqueue(3 * f + (kv + 2) % 3);
            // The edge opposite v, both ways, once the face beyond it is
            // reached.
            if let Some((g, j)) = t.adj(f, kv)
                && self.state[t.faces[g][j]] != OUTSIDE
            {
                self.enqueue(3 * f + kv);
                self.enqueue(3 * g + j);
            }
        }
    }

    /// Windows of pseudo-source `v` onto the edges opposite it, and its
    /// spokes to its neighbours. A shortest path through a vertex makes an
    /// angle of at least π on both sides, so beyond an interior saddle v
    /// reached from direction φ only the shadow, the directions
    /// [φ + π, φ + θ − π] of v's total angle θ, can continue a shortest
    /// path: windows and spokes are cast into it alone (everywhere for a
    /// source, a boundary vertex, or when paths arrive from several
    /// directions).
    fn cast(&mut self, v: usize, source: bool) {
        let d = self.dist[v];
        let everywhere = source || !self.fans.ordered[v] || self.any_dir[v];
        if !(d < self.emitted[v] || (everywhere && !self.emitted_everywhere[v])) {
            return;
        }
        self.emitted[v] = d;
        self.emitted_everywhere[v] = everywhere;
        let t = self.topo;
        let fans = self.fans;
        let total = fans.total[v];
        // The shadow, widened by a rounding margin: [lo, lo + width] (mod θ).
        let margin = 1e-9;
        let lo = (self.dir[v] + PI - margin).rem_euclid(total);
        let width = total - 2.0 * PI + 2.0 * margin;
        let in_shadow = |a: f64| everywhere || (a - lo).rem_euclid(total) <= width;
        for &(f, k) in &t.ring[v] {
            let (l, fv, c) = (t.len[f], t.faces[f], 3 * f + k);
            // Corner sector [phi, phi + gamma]: from the edge to corner cf
            // to the edge to corner cs (the edge from v to one is opposite
            // the other).
            let (phi, gamma) = (fans.phi[c], fans.gamma[c]);
            let (cf, cs) = if fans.first_next[c] {
                ((k + 1) % 3, (k + 2) % 3)
            } else {
                ((k + 2) % 3, (k + 1) % 3)
            };
            if in_shadow(phi) {
                self.relax(fv[cf], d + l[cs], fans.toward(3 * f + cf, v, fv));
            }
            if in_shadow(phi + gamma) {
                self.relax(fv[cs], d + l[cf], fans.toward(3 * f + cs, v, fv));
            }
            let Some(w) = spoke_window(t, f, k, d) else {
                continue;
            };
            if everywhere {
                self.append(w);
                continue;
            }
            // The parts of the shadow inside this corner, as angles from
            // the edge to corner cf (the shadow may wrap around θ).
            for shift in [-total, 0.0, total] {
                let (a0, a1) = (
                    (lo + shift - phi).max(0.0),
                    (lo + shift + width - phi).min(gamma),
                );
                if a1 < a0 {
                    continue;
                }
                // Where rays from v at those angles meet the opposite edge,
                // in the window's frame (v at (sx, sy), the edge on y = 0).
                let le = l[k];
                let from_origin = t.faces[w.face][(w.edge + 1) % 3] == fv[cf];
                let ang = |a: f64| {
                    if from_origin {
                        (-w.sx).atan2(w.sy) + a
                    } else {
                        (le - w.sx).atan2(w.sy) - a
                    }
                };
                let x = |a: f64| (w.sx + w.sy * ang(a).tan()).clamp(0.0, le);
                let (x0, x1) = (x(a0), x(a1));
                let mut piece = w;
                piece.b0 = x0.min(x1);
                piece.b1 = x0.max(x1);
                if piece.b1 - piece.b0 > 1e-12 * le {
                    self.append(piece);
                }
            }
        }
    }

    /// Lowers the distance of `v` to `d`, reached from direction `dir` (a
    /// cumulative angle in v's fan, pointing back along the path). Paths
    /// of (nearly) the same length from different directions make every
    /// direction count when v casts windows.
    fn relax(&mut self, v: usize, d: f64, dir: f64) {
        let old = self.dist[v];
        let tie = 1e-12 * d;
        if d < old - tie {
            self.dist[v] = d;
            self.dir[v] = dir;
            self.any_dir[v] = false;
        } else if d <= old + tie {
            if !self.any_dir[v] && circular_gap(dir, self.dir[v], self.fans.total[v]) > 1e-9 {
                self.any_dir[v] = true;
                if self.state[v] == INSIDE && self.topo.pseudo_source[v] {
                    self.recast.push(v);
                }
            }
            if d >= old {
                return;
            }
            self.dist[v] = d;
        } else {
            return;
        }
        if self.state[v] != INSIDE {
            self.heap.push(Item {
                key: d,
                code: v as u64,
            });
            self.stats.peak_queue = self.stats.peak_queue.max(self.heap.len());
        } else if self.topo.pseudo_source[v] {
            self.recast.push(v);
        }
    }

    /// Adds a window to its slot's list, and queues the list when its edge
    /// touches a settled vertex.
    fn append(&mut self, w: Window) {
        let slot = 3 * w.face + w.edge;
        let node = Node {
            w,
            next: self.head[slot],
        };
        let id = if self.free != NIL {
            let id = self.free;
            self.free = self.nodes[id as usize].next;
            self.nodes[id as usize] = node;
            id
        } else {
            self.nodes.push(node);
            self.stats.peak_stored = self.nodes.len();
            (self.nodes.len() - 1) as u32
        };
        self.head[slot] = id;
        self.stats.windows += 1;
        if self.track {
            let m = w.min_dist();
            if m < self.slot_min[slot] {
                self.slot_min[slot] = m;
                self.pending.push(Item {
                    key: m,
                    code: slot as u64,
                });
            }
        }
        let f = self.topo.faces[w.face];
        if self.state[f[(w.edge + 1) % 3]] == INSIDE || self.state[f[(w.edge + 2) % 3]] == INSIDE {
            self.enqueue(slot);
        }
    }

    fn enqueue(&mut self, slot: usize) {
        if !self.queued[slot] && self.head[slot] != NIL {
            self.queued[slot] = true;
            self.fifo.push_back(slot as u32);
        }
    }

    fn drain(&mut self) {
        loop {
            if let Some(v) = self.recast.pop() {
                self.cast(v, false);
            } else if let Some(slot) = self.fifo.pop_front() {
                self.queued[slot as usize] = false;
                self.propagate_list(slot as usize);
            } else {
                break;
            }
        }
    }

    /// Propagates every window of a slot's list across its face.
    fn propagate_list(&mut self, slot: usize) {
        let t = self.topo;
        // The pending windows, trimmed by the vertices of their edge. (Also
        // trimming them against each other, as VTP does, prunes 30% of the
        // windows but costs more than it saves once saddles cast into
        // their shadows only.)
        let mut kept = std::mem::take(&mut self.kept);
        kept.clear();
        if self.track {
            self.slot_min[slot] = f64::INFINITY;
        }
        let mut id = std::mem::replace(&mut self.head[slot], NIL);
        while id != NIL {
            let Node { mut w, next } = self.nodes[id as usize];
            self.nodes[id as usize].next = self.free;
            self.free = id;
            id = next;
            if trim(t, &self.dist, &mut w) {
                kept.push(w);
            }
        }
        let Some(first) = kept.first() else {
            self.kept = kept;
            return;
        };
        let base = Apex::new(t, first);
        // The shortest path to the far vertex v3 through this edge: a ray
        // of a window when v3 is in its light, else bent at the window's
        // nearer end (a longer but real path).
        let (mut best, mut best_x) = self.best_top[slot];
        let mut d3s = std::mem::take(&mut self.d3s);
        d3s.clear();
        for w in &kept {
            let a = base.for_window(w);
            let c = a.xv.clamp(w.b0, w.b1);
            let d3 = if c == a.xv {
                w.sigma + a.dist_from(w)
            } else {
                w.dist_at(c) + ((a.px - c).powi(2) + a.py * a.py).sqrt()
            };
            if d3 < best {
                (best, best_x) = (d3, c);
            }
            d3s.push((d3, c, a.xv));
        }
        self.best_top[slot] = (best, best_x);
        // v3 gets the shortest of these paths, with the direction it
        // arrives from (towards the source, or towards the bend).
        let v3 = base.v3;
        // Directions matter only where windows are cast: interior saddles.
        let directed = t.pseudo_source[v3] && self.fans.ordered[v3];
        for (w, &(d3, c, xv)) in kept.iter().zip(&d3s) {
            if d3 <= best * (1.0 + 1e-12) && d3 < self.dist[v3] * (1.0 + 1e-12) {
                let dir = if directed {
                    let target = if c == xv { (w.sx, w.sy) } else { (c, 0.0) };
                    self.fans.direction(slot, &base, target)
                } else {
                    0.0
                };
                self.relax(v3, d3, dir);
            }
        }
        // One angle, two sides: that path runs straight from the edge at
        // best_x to v3 and splits the face. A ray of w entering on one side
        // of best_x and leaving through the edge on the other side crosses
        // it at some p, where the path is not longer than w's (it is not
        // longer at v3, and w reaches v3 at most |p v3| after p); the ray
        // is then no geodesic beyond p (the shorter path would have to bend
        // at p). So the left child keeps only rays entering left of best_x,
        // the right child only those right of it. Near-ties keep both.
        for (w, &(d3, _, xv)) in kept.iter().zip(&d3s) {
            self.stats.propagated += 1;
            let a = Apex { xv, ..base };
            let a = &a;
            let split = if best < d3 - SLACK * (d3 + a.le) {
                (a.xv.min(best_x), a.xv.max(best_x))
            } else {
                (a.xv, a.xv)
            };
            // Children are trimmed when their list is propagated, with the
            // vertex distances of that later time.
            children(t, w, a, split, |child| self.append(child));
        }
        self.kept = kept;
        self.d3s = d3s;
    }
}

/// The position of vertex `v` among the corners of face `f`.
fn corner_of(f: [usize; 3], v: usize) -> usize {
    if f[0] == v {
        0
    } else if f[1] == v {
        1
    } else {
        2
    }
}

/// Distance between two angles on a circle of circumference `total`.
fn circular_gap(a: f64, b: f64, total: f64) -> f64 {
    let d = (a - b).rem_euclid(total);
    d.min(total - d)
}

/// The faces around each interior vertex in cyclic order, as cumulative
/// angles: directions at a vertex are measured as the angle swept from a
/// fixed edge, so that the shadow of a saddle can be found.
#[derive(Debug, Clone)]
pub(crate) struct Fans {
    /// Per face corner `3 f + k`: where the corner's sector starts.
    phi: Vec<f64>,
    /// Per face corner: its angle.
    gamma: Vec<f64>,
    /// Per face corner: the sector starts at the edge to corner `k + 1`
    /// (else at the edge to corner `k + 2`).
    first_next: Vec<bool>,
    /// Per vertex: total angle, and whether its faces form one closed fan
    /// (false on the boundary and at non-manifold vertices).
    total: Vec<f64>,
    ordered: Vec<bool>,
}

impl Fans {
    pub(crate) fn new(t: &Topology) -> Self {
        let n = t.ring.len();
        let m = 3 * t.faces.len();
        let mut fans = Self {
            phi: vec![0.0; m],
            gamma: (0..m).map(|c| corner_angle(t.len[c / 3], c % 3)).collect(),
            first_next: vec![true; m],
            total: vec![2.0 * PI; n],
            ordered: vec![false; n],
        };
        for v in 0..n {
            let Some(&(f0, k0)) = t.ring[v].first() else {
                continue;
            };
            let (mut f, mut k) = (f0, k0);
            let mut first = t.faces[f][(k + 1) % 3];
            let mut acc = 0.0;
            let mut steps = 0;
            let closed = loop {
                let c = 3 * f + k;
                fans.phi[c] = acc;
                fans.first_next[c] = t.faces[f][(k + 1) % 3] == first;
                acc += fans.gamma[c];
                steps += 1;
                let second = if fans.first_next[c] {
                    t.faces[f][(k + 2) % 3]
                } else {
                    t.faces[f][(k + 1) % 3]
                };
                // Across the edge (v, second): opposite `first`.
                let Some((g, _)) = t.adj(f, corner_of(t.faces[f], first)) else {
                    break false;
                };
                if g == f0 {
                    break steps == t.ring[v].len();
                }
                if steps >= t.ring[v].len() {
                    break false;
                }
                f = g;
                k = corner_of(t.faces[g], v);
                first = second;
            };
            fans.ordered[v] = closed;
            fans.total[v] = if closed { acc } else { 2.0 * PI };
        }
        fans
    }

    /// The direction at corner `c`'s vertex (in face f) of the edge to
    /// vertex `u`, another corner of f.
    fn toward(&self, c: usize, u: usize, f: [usize; 3]) -> f64 {
        let k = c % 3;
        let first = if self.first_next[c] {
            f[(k + 1) % 3]
        } else {
            f[(k + 2) % 3]
        };
        if first == u {
            self.phi[c]
        } else {
            self.phi[c] + self.gamma[c]
        }
    }

    /// The direction at the far vertex of a window's face (corner `c`,
    /// at `apex` in the window's frame) towards `target` in that frame.
    fn direction(&self, c: usize, apex: &Apex, target: (f64, f64)) -> f64 {
        // Angle at v3 from the edge to e0 (at the frame's origin).
        let u = (-apex.px, -apex.py);
        let q = (target.0 - apex.px, target.1 - apex.py);
        let beta = (u.0 * q.1 - u.1 * q.0)
            .abs()
            .atan2(u.0 * q.0 + u.1 * q.1)
            .clamp(0.0, self.gamma[c]);
        // e0 is corner k + 1 of the face.
        if self.first_next[c] {
            self.phi[c] + beta
        } else {
            self.phi[c] + self.gamma[c] - beta
        }
    }
}
