//! Scratch: tune native parameters.
use fmaps::eigensolve::*;
use fmaps::laplacian::*;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let mesh = fmaps::mesh_io::read_mesh(&a[1]).unwrap();
    let k: usize = a[2].parse().unwrap();
    let op = cotan_laplacian(&mesh, &LaplacianParams::default());
    let p = EigenProblem::new(op.stiffness.view(), &op.mass).unwrap();
    for spec in &a[3..] {
        let f: Vec<&str> = spec.split(',').collect();
        let params = NativeParams {
            block_size: f[0].parse().unwrap(),
            subspace: f.get(1).and_then(|x| x.parse::<f64>().ok()).map(|r| (r * k as f64) as usize),
            factorization: match f.get(2).copied() { Some("simp") => Factorization::Simplicial, Some("sup") => Factorization::Supernodal, _ => Factorization::Auto },
            threads: f.get(3).and_then(|x| x.parse().ok()).unwrap_or(1),
            ..Default::default()
        };
        let t = std::time::Instant::now();
        let b = NativeSolver::new(params).solve(&p, k).unwrap();
        println!("{spec}: total {:.3} fact {:.3} it {:.3} restarts {} applies {} res {:.1e}", t.elapsed().as_secs_f64(), b.report.factorization_seconds, b.report.iteration_seconds, b.report.restarts, b.report.operator_applications, b.report.max_residual());
    }
}
