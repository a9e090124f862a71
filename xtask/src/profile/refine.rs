//! Times ZoomOut 50:150:5 and ICP on one FAUST pair, repeatedly, for
//! profiling: `cargo xtask profile refine --
//! A.off B.off [zoomout|zoomout1|icp|fit] [repeats]`.
use std::time::Instant;

use fmaps::pipeline::{MatchParams, match_prepared, prepare};
use fmaps::refine::{Icp, Refiner, ZoomOut};

pub fn run(argv: Vec<String>) -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = argv.into_iter().collect();
    let ma = fmaps::mesh_io::read_mesh(&args[1])?;
    let mb = fmaps::mesh_io::read_mesh(&args[2])?;
    let which = args.get(3).map_or("zoomout", |s| s.as_str());
    let reps: usize = args.get(4).map_or(3, |s| s.parse().unwrap());
    let params = MatchParams::unrefined();
    let (pa, pb) = (prepare(&ma, &params)?, prepare(&mb, &params)?);
    let init = match_prepared(&pa, &pb, &params)?;
    if which == "fit" {
        // The initial map alone (operators, solve, point map).
        for _ in 0..reps {
            let t = Instant::now();
            let r = match_prepared(&pa, &pb, &params)?;
            println!(
                "fit {:.3} s (operators {:.3}, solve {:.3}, point map {:.3})",
                t.elapsed().as_secs_f64(),
                r.times.operators,
                r.times.solve,
                r.times.point_map
            );
        }
        return Ok(());
    }
    let refiner: Box<dyn Refiner> = match which {
        "icp" => Box::new(Icp::default()),
        "zoomout1" => Box::new(ZoomOut {
            k_start: 30,
            k_final: 200,
            step: 1,
            ..ZoomOut::default()
        }),
        _ => Box::new(ZoomOut::default()),
    };
    for _ in 0..reps {
        let t = Instant::now();
        let r = refiner.refine(&fmaps::refine::RefineInput::new(
            &init.c_ba, &pb.basis, &pa.basis,
        ))?;
        println!(
            "{} {:.3} s (nn {:.3} s, map checksum {})",
            refiner.name(),
            t.elapsed().as_secs_f64(),
            r.report.nn_seconds,
            r.t_ba.iter().sum::<usize>()
        );
    }
    Ok(())
}
