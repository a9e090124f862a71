//! Times the native backend on one mesh, several runs, one thread by
//! default: `cargo xtask profile eigen --
//! -- MESH.off [K] [RUNS] [SUBSPACE] [BLOCK] [THREADS]` (SUBSPACE or BLOCK
//! 0: the solver's default). Prints each run's iteration and total seconds and the median.
use fmaps::eigensolve::{EigenProblem, EigenSolver, NativeParams, NativeSolver};
use fmaps::laplacian::{LaplacianParams, cotan_laplacian};
use std::time::Instant;

pub fn run(argv: Vec<String>) -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = argv.into_iter().skip(1).collect();
    let path = args
        .first()
        .ok_or("usage: eigen_profile MESH [K] [RUNS] [SUBSPACE] [BLOCK] [THREADS]")?;
    let arg = |i: usize, d: usize| -> Result<usize, Box<dyn std::error::Error>> {
        Ok(args.get(i).map(|s| s.parse()).transpose()?.unwrap_or(d))
    };
    let (k, runs, sub, block, threads) =
        (arg(1, 200)?, arg(2, 5)?, arg(3, 0)?, arg(4, 0)?, arg(5, 1)?);
    let mesh = fmaps::mesh_io::read_mesh(path)?;
    let op = cotan_laplacian(&mesh, &LaplacianParams::default());
    let problem = EigenProblem::new(op.stiffness.view(), &op.mass)?;
    let mut params = NativeParams::default();
    params.subspace = (sub > 0).then_some(sub);
    if block > 0 {
        params.block_size = block;
    }
    params.threads = threads;
    let solver = NativeSolver::new(params);
    let mut totals = Vec::new();
    for run in 0..=runs {
        let t0 = Instant::now();
        let b = solver.solve(&problem, k)?;
        let total = t0.elapsed().as_secs_f64();
        let s = &b.report;
        println!(
            "run {run}: factor {:.3} iterate {:.3} total {:.3} s, {} restarts, {} applications, ortho {:.1e}, max residual {:.1e}, λ_k {:.6e}",
            s.factorization_seconds,
            s.iteration_seconds,
            total,
            s.restarts,
            s.operator_applications,
            b.report.orthonormality_error,
            s.max_residual(),
            b.eigenvalues[k - 1]
        );
        if run > 0 {
            totals.push(total);
        }
    }
    if totals.is_empty() {
        return Ok(());
    }
    totals.sort_by(f64::total_cmp);
    println!(
        "median of {runs} (after one warm-up): {:.3} s",
        totals[totals.len() / 2]
    );
    Ok(())
}
