//! Farthest point sampling for the sub-sampled ZoomOut.

/// `n` vertices spread over a point set by farthest point sampling in
/// Euclidean distance (Gonzalez's greedy 2-approximation of the k-center
/// problem): start at `first`, then repeatedly take the point farthest
/// from those taken (ties: the smallest index). Deterministic; O(n · N).
/// Returns all points (in sampling order) if `n >= points.len()`.
///
/// ```
/// let pts: Vec<[f64; 3]> = (0..10).map(|i| [i as f64, 0.0, 0.0]).collect();
/// assert_eq!(fmaps_refine::farthest_point_sampling(&pts, 3, 0), vec![0, 9, 4]);
/// ```
pub fn farthest_point_sampling(points: &[[f64; 3]], n: usize, first: usize) -> Vec<usize> {
    farthest_point_sampling_with_nearest(points, n, first).0
}

/// [`farthest_point_sampling`] and, for every point, the position in the
/// sample list of its nearest sample (Euclidean; ties: the earlier
/// sample), which the sampling computes anyway. The sub-sampled ZoomOut
/// uses it to start its one full-size search from each vertex's nearest
/// sample's image ([`crate::Subsample::nearest_b`]).
///
/// ```
/// let pts: Vec<[f64; 3]> = (0..10).map(|i| [i as f64, 0.0, 0.0]).collect();
/// let (samples, nearest) = fmaps_refine::farthest_point_sampling_with_nearest(&pts, 3, 0);
/// assert_eq!(samples, vec![0, 9, 4]);
/// // Points 0-2 are nearest to sample 0 (vertex 0), 3-6 to vertex 4
/// // (position 2; 2 is as far from 0 as from 4: the earlier wins), 7-9
/// // to vertex 9.
/// assert_eq!(nearest, vec![0, 0, 0, 2, 2, 2, 2, 1, 1, 1]);
/// ```
pub fn farthest_point_sampling_with_nearest(
    points: &[[f64; 3]],
    n: usize,
    first: usize,
) -> (Vec<usize>, Vec<usize>) {
    let m = points.len();
    if m == 0 || n == 0 {
        return (Vec::new(), Vec::new());
    }
    let n = n.min(m);
    let sq = |p: [f64; 3], q: [f64; 3]| {
        (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2)
    };
    // Every point's squared distance to its nearest sample, and the
    // samples' Voronoi cells: a new sample p can only come nearer to the
    // points of a cell (centre s, radius r) when |p - s| < 2r (else
    // |q - p| >= |p - s| - |q - s| >= |q - s| for all q of the cell), so
    // the other cells are not visited. The distances compared are the
    // plain algorithm's, so the samples are the same.
    let mut dist = vec![f64::INFINITY; m];
    let mut nearest = vec![0usize; m];
    let mut out = Vec::with_capacity(n);
    let mut cells: Vec<Cell> = Vec::with_capacity(n);
    let mut cur = first.min(m - 1);
    for s in 0..n {
        out.push(cur);
        let p = points[cur];
        let mut joined = Vec::new();
        let mut scan = |members: Vec<usize>, dist: &mut [f64], keep: &mut Vec<usize>| {
            for i in members {
                let d = sq(points[i], p);
                if d < dist[i] {
                    dist[i] = d;
                    nearest[i] = s;
                    joined.push(i);
                } else {
                    keep.push(i);
                }
            }
        };
        if s == 0 {
            scan((0..m).collect(), &mut dist, &mut Vec::new());
        } else {
            for cell in cells.iter_mut() {
                let reach = 2.0 * cell.radius * (1.0 + 1e-9);
                if sq(points[cell.centre], p) >= reach * reach {
                    continue;
                }
                let members = std::mem::take(&mut cell.members);
                let mut keep = Vec::with_capacity(members.len());
                scan(members, &mut dist, &mut keep);
                cell.members = keep;
                cell.update(&dist);
            }
        }
        let mut new = Cell {
            centre: cur,
            members: joined,
            radius: 0.0,
            farthest: (f64::NEG_INFINITY, usize::MAX),
        };
        new.update(&dist);
        cells.push(new);
        // The farthest point from the samples (ties: the smallest index).
        let mut best = (f64::NEG_INFINITY, usize::MAX);
        for c in &cells {
            if c.farthest.0 > best.0 || (c.farthest.0 == best.0 && c.farthest.1 < best.1) {
                best = c.farthest;
            }
        }
        cur = best.1;
    }
    (out, nearest)
}

/// A sample's Voronoi cell in [`farthest_point_sampling_with_nearest`].
struct Cell {
    centre: usize,
    members: Vec<usize>,
    /// Largest distance (not squared) of a member from the centre.
    radius: f64,
    /// The member farthest from the centre, (squared distance, index),
    /// ties: the smallest index.
    farthest: (f64, usize),
}

impl Cell {
    fn update(&mut self, dist: &[f64]) {
        let mut f = (f64::NEG_INFINITY, usize::MAX);
        for &i in &self.members {
            let d = dist[i];
            if d > f.0 || (d == f.0 && (i) < f.1) {
                f = (d, i);
            }
        }
        self.farthest = f;
        self.radius = f.0.max(0.0).sqrt();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plain O(n · N) algorithm the cells must reproduce.
    fn plain(points: &[[f64; 3]], n: usize, first: usize) -> (Vec<usize>, Vec<usize>) {
        let m = points.len();
        let mut dist = vec![f64::INFINITY; m];
        let mut nearest = vec![0; m];
        let mut out = Vec::new();
        let mut cur = first.min(m - 1);
        for s in 0..n.min(m) {
            out.push(cur);
            let p = points[cur];
            let mut best = (f64::NEG_INFINITY, 0);
            for (i, q) in points.iter().enumerate() {
                let d = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2);
                if d < dist[i] {
                    dist[i] = d;
                    nearest[i] = s;
                }
                if dist[i] > best.0 {
                    best = (dist[i], i);
                }
            }
            cur = best.1;
        }
        (out, nearest)
    }

    #[test]
    fn the_cells_give_the_plain_algorithms_samples() {
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        // Random points, a grid (many equal distances: the ties) and
        // repeated points.
        let random: Vec<[f64; 3]> = (0..3000).map(|_| [rnd(), rnd(), 0.1 * rnd()]).collect();
        let grid: Vec<[f64; 3]> = (0..900)
            .map(|i| [(i % 30) as f64, (i / 30) as f64, 0.0])
            .collect();
        let repeated: Vec<[f64; 3]> = (0..200).map(|i| [(i % 7) as f64, 0.0, 1.0]).collect();
        for (points, n, first) in [
            (&random, 500, 0),
            (&random, 3000, 17),
            (&grid, 300, 0),
            (&grid, 900, 5),
            (&repeated, 50, 3),
        ] {
            assert_eq!(
                farthest_point_sampling_with_nearest(points, n, first),
                plain(points, n, first),
                "{} points, {n} samples from {first}",
                points.len()
            );
        }
    }
}
