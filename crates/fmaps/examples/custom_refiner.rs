//! A third-party refiner written against the public API alone: ZoomOut
//! (Melzi et al., "ZoomOut: spectral upsampling for efficient shape
//! correspondence", SIGGRAPH Asia 2019, Algorithm 1) in its plain form —
//! convert the k x k map to a point map, re-fit the (k + step) x (k +
//! step) map to that point map, repeat — on the public conversions of
//! `fmaps-solve` (the built-in [`ZoomOut`](fmaps::refine::ZoomOut) is the
//! fast version of the same loop). It passes the exported conformance
//! check and gives the same map as the built-in one, then runs through
//! [`fmaps::match_shapes`] as `Refinement::Custom`:
//! `cargo run --release -p fmaps --example custom_refiner`.

use std::sync::Arc;
use std::time::Instant;

use fmaps::pipeline::{MatchParams, Refinement, match_shapes};
use fmaps::refine::{
    Error, Iteration, RefineInput, RefineReport, Refined, Refiner, Result, ZoomOut, conformance,
};
use fmaps::shapes::creature_pair;
use fmaps::solve::{fmap_from_point_map, point_map_from_fmap};

/// ZoomOut from `k_start` to `k_final` in steps of `step`.
#[derive(Debug)]
struct PlainZoomOut {
    k_start: usize,
    k_final: usize,
    step: usize,
}

impl Refiner for PlainZoomOut {
    fn name(&self) -> String {
        format!(
            "plain-zoomout {}:{}:{}",
            self.k_start, self.k_final, self.step
        )
    }

    fn k_needed(&self) -> usize {
        self.k_final
    }

    fn refine(&self, input: &RefineInput<'_>) -> Result<Refined> {
        let (c_ab, basis_a, basis_b) = (input.c_ab, input.basis_a, input.basis_b);
        let t0 = Instant::now();
        let (kf, k0) = (self.k_final, self.k_start);
        if k0 == 0 || self.step == 0 || kf < k0 || c_ab.nrows() < k0 || c_ab.ncols() < k0 {
            return Err(Error::InvalidParameter(format!(
                "{}: needs 0 < k_start <= k_final, step > 0 and a map of at least {k0} x {k0}",
                self.name()
            )));
        }
        let need = kf.max(c_ab.nrows()).max(c_ab.ncols());
        if basis_a.k() < need || basis_b.k() < need {
            return Err(Error::NotEnoughEigenpairs {
                shape: if basis_a.k() < need { "A" } else { "B" },
                needed: need,
                available: basis_a.k().min(basis_b.k()),
            });
        }
        let mut c = c_ab.view((0, 0), (k0, k0)).into_owned();
        let mut iterations = Vec::new();
        let mut k = k0;
        let t_ba = loop {
            let t = Instant::now();
            let t_ba = point_map_from_fmap(&c, basis_a, basis_b)?;
            if k == kf {
                break t_ba;
            }
            k = (k + self.step).min(kf);
            let (a, b) = (basis_a.truncate(k), basis_b.truncate(k));
            c = fmap_from_point_map(&t_ba, &a, &b)?;
            iterations.push(Iteration {
                k: (k, k),
                changed: 0,
                seconds: t.elapsed().as_secs_f64(),
            });
        };
        Ok(Refined {
            c_ab: c,
            t_ba,
            report: RefineReport {
                method: self.name(),
                nn_searches: iterations.len() + 1,
                iterations,
                converged: true,
                nn_seconds: 0.0,
                seconds: t0.elapsed().as_secs_f64(),
            },
        })
    }
}

/// Checks the conformance, then matches the built-in pair with it (also
/// called by the workspace test `tests/extension_points.rs`).
pub fn main() -> std::result::Result<(), Box<dyn std::error::Error>> {
    let plain = PlainZoomOut {
        k_start: 20,
        k_final: 50,
        step: 5,
    };
    conformance::check(&plain)?;
    println!("{}: passes fmaps_refine::conformance::check", plain.name());

    // The pipeline with it and with the built-in ZoomOut of the same
    // schedule, on the built-in pair (known truth).
    let pair = creature_pair(3);
    let run = |refine: Refinement| -> std::result::Result<Vec<usize>, Box<dyn std::error::Error>> {
        let mut params = MatchParams::default();
        params.k_process = 80;
        params.descriptors.eigenpairs = 60;
        params.k = 20;
        params.refinement = refine;
        Ok(match_shapes(&pair.source, &pair.target, &params)?.t_ab)
    };
    let custom = run(Refinement::Custom(Arc::new(plain)))?;
    let builtin = run(Refinement::ZoomOut {
        zoomout: ZoomOut {
            k_start: 20,
            k_final: 50,
            step: 5,
            ..ZoomOut::default()
        },
        samples: None,
    })?;
    let exact = |t: &[usize]| t.iter().zip(&pair.truth).filter(|(a, b)| a == b).count();
    let same = custom.iter().zip(&builtin).filter(|(a, b)| a == b).count();
    println!(
        "match_shapes with Refinement::Custom: {} of {} vertices on their true image (built-in ZoomOut: {}); the two maps agree on {} vertices",
        exact(&custom),
        pair.truth.len(),
        exact(&builtin),
        same
    );
    // Two implementations of one algorithm: they must agree (up to
    // near-ties flipped by rounding).
    if same * 100 < 99 * custom.len() {
        return Err(format!("plain and built-in ZoomOut agree on only {same} vertices").into());
    }
    Ok(())
}
