//! The collections `cargo xtask eval` and its companions read: a dataset
//! collection with its `test_pairs.txt`, the literature's splits of FAUST,
//! the generated bodies; and landmarks taken from a pair's ground truth.

use fmaps::eval::Collection;
use fmaps::mesh_io::TriMesh;

/// A collection and its pairs: a dataset collection with its
/// `test_pairs.txt`, or one of the literature's splits of FAUST:
/// `FAUST_r` (shapes tr_reg_080 .. tr_reg_099, all 190 unordered pairs,
/// lower number first) and `FAUST_inter` (the test pairs of two different
/// people: `tr_reg_0SP`, S the person).
pub(crate) fn collection_pairs(
    bcicp: &std::path::Path,
    name: &str,
) -> anyhow::Result<(Collection, Vec<(String, String)>)> {
    match name {
        "generated-iso" | "generated-noniso" | "generated-species" | "generated" => {
            let root = crate::generated::generated_root(false)?;
            let c = Collection::open(&root, "generated")?;
            let pairs = match name {
                "generated-iso" => crate::generated::iso_pairs(),
                "generated-noniso" => crate::generated::noniso_pairs(),
                "generated-species" => crate::generated::species_pairs(),
                _ => c.test_pairs()?,
            };
            Ok((c, pairs))
        }
        "FAUST_r" => {
            let c = Collection::open(bcicp, "FAUST")?;
            let shapes: Vec<String> = (80..100).map(|i| format!("tr_reg_{i:03}")).collect();
            let mut pairs = Vec::new();
            for (i, a) in shapes.iter().enumerate() {
                for b in &shapes[i + 1..] {
                    pairs.push((a.clone(), b.clone()));
                }
            }
            Ok((c, pairs))
        }
        "FAUST_r_ordered" => {
            // The learned papers' protocol: every ordered pair of the test
            // shapes, the 20 self-pairs included (400 pairs).
            let c = Collection::open(bcicp, "FAUST")?;
            let shapes: Vec<String> = (80..100).map(|i| format!("tr_reg_{i:03}")).collect();
            let pairs = shapes
                .iter()
                .flat_map(|a| shapes.iter().map(move |b| (a.clone(), b.clone())))
                .collect();
            Ok((c, pairs))
        }
        "FAUST_inter" => {
            let c = Collection::open(bcicp, "FAUST")?;
            let person = |s: &str| s.strip_prefix("tr_reg_").and_then(|n| n.chars().nth(1));
            let pairs = c
                .test_pairs()?
                .into_iter()
                .filter(|(a, b)| person(a) != person(b))
                .collect();
            Ok((c, pairs))
        }
        _ => {
            let c = Collection::open(bcicp, name)?;
            let pairs = c.test_pairs()?;
            Ok((c, pairs))
        }
    }
}

/// `n` indices into `points` (vertices of `mesh`) spread by farthest-point
/// sampling in space with the points' mean counted as taken (unlike
/// `fmaps::refine::farthest_point_sampling`, which starts from a point):
/// every pick is the point farthest from the mean and the picks so far,
/// so on a body the tips of head, hands, feet and tail come first.
pub(crate) fn farthest_points(mesh: &TriMesh, points: &[usize], n: usize) -> Vec<usize> {
    let v = mesh.vertices();
    let p: Vec<[f64; 3]> = points.iter().map(|&i| v[i]).collect();
    if p.is_empty() {
        return Vec::new();
    }
    let mean = p
        .iter()
        .fold([0.0; 3], |m, x| [m[0] + x[0], m[1] + x[1], m[2] + x[2]]);
    let mean = mean.map(|x| x / p.len() as f64);
    let d2 = |a: [f64; 3], b: [f64; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>();
    let mut nearest: Vec<f64> = p.iter().map(|&x| d2(x, mean)).collect();
    let mut out = Vec::new();
    while out.len() < n.min(p.len()) {
        let next = (0..p.len())
            .max_by(|&i, &j| nearest[i].total_cmp(&nearest[j]))
            .unwrap_or(0);
        out.push(next);
        for (d, x) in nearest.iter_mut().zip(&p) {
            *d = d.min(d2(*x, p[next]));
        }
    }
    out
}
