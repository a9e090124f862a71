//! `cargo xtask bench-learn`: DiffusionNet on one benchmark shape, this
//! crate's hand-written forward and backward passes: the operators once
//! (cold), then the forward pass alone and the forward and backward passes
//! together, warmed up, medians of the repeats. The network has the
//! matching defaults (128 WKS inputs, width 128, 4 blocks, 256 outputs,
//! 128 eigenpairs), f64, dropout on.

use std::time::Instant;

use fmaps::eval::Collection;
use fmaps_learn::ShapeOperators;
use fmaps_learn::network::DiffusionNet;
use nalgebra::DMatrix;

use crate::util::{data_dir, machine_header, median};

/// Options of `cargo xtask bench-learn`.
#[derive(clap::Args)]
pub struct Args {
    /// Collection of the shape.
    #[arg(long, default_value = "FAUST")]
    collection: String,
    /// The shape (a name of the collection).
    #[arg(long, default_value = "tr_reg_080")]
    shape: String,
    /// Repeats of each timing (after one warm-up).
    #[arg(long, default_value_t = 5)]
    repeat: usize,
    /// Threads.
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// Datasets folder (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    data: Option<std::path::PathBuf>,
}

pub fn bench_learn(args: &Args) -> anyhow::Result<()> {
    let root = data_dir(args.data.as_deref()).join("bcicp");
    let c = Collection::open(&root, &args.collection)?;
    let mesh = c.read_mesh(&args.shape)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()?;
    println!("{}", machine_header(args.threads));
    pool.install(|| -> anyhow::Result<()> {
        let t = Instant::now();
        let ops = ShapeOperators::compute(&mesh, 128)?;
        let operators = t.elapsed().as_secs_f64();
        let shape = ops.input();
        let n = mesh.n_vertices();
        let net = DiffusionNet::new(128, 128, 4, 256, 1);
        // Inputs and output gradients of unit size (their values do not
        // change the time).
        let mut s = 0x9E3779B97F4A7C15u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let x = DMatrix::from_fn(n, 128, |_, _| next());
        let dy = DMatrix::from_fn(n, 256, |_, _| next());
        let masks = net.draw_masks(n, &mut fmaps_learn::network::SplitMix(2));
        let time = |f: &dyn Fn()| {
            f();
            median(
                (0..args.repeat)
                    .map(|_| {
                        let t = Instant::now();
                        f();
                        t.elapsed().as_secs_f64()
                    })
                    .collect(),
            )
        };
        let forward = time(&|| {
            std::hint::black_box(net.forward(shape, &x, Some(&masks)));
        });
        let both = time(&|| {
            std::hint::black_box(net.backward(shape, &x, Some(&masks), &dy));
        });
        println!(
            "{} {} ({n} vertices), DiffusionNet 128 -> 4 x 128 -> 256, k = 128, f64, medians of {} after a warm-up",
            args.collection, args.shape, args.repeat
        );
        println!("operators (frames, gradients, 128 eigenpairs): {operators:.3} s (once per shape)");
        println!("forward:            {forward:.3} s");
        println!("forward + backward: {both:.3} s");
        Ok(())
    })
}
