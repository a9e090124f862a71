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
    let m = points.len();
    if m == 0 || n == 0 {
        return Vec::new();
    }
    let n = n.min(m);
    let mut dist = vec![f64::INFINITY; m];
    let mut out = Vec::with_capacity(n);
    let mut cur = first.min(m - 1);
    for _ in 0..n {
        out.push(cur);
        let p = points[cur];
        let mut best = (f64::NEG_INFINITY, 0);
        for (i, q) in points.iter().enumerate() {
            let d = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2);
            if d < dist[i] {
                dist[i] = d;
            }
            if dist[i] > best.0 {
                best = (dist[i], i);
            }
        }
        cur = best.1;
    }
    out
}
