//! `BestOf` keeps the refinement whose map distorts the surface least,
//! whatever the order of its refiners.

use std::sync::Arc;

use fmaps_refine::{
    BestOf, RefineInput, RefineReport, Refined, Refiner, Result, ShapeGeometry, ZoomOut,
    area_distortion,
};
use nalgebra::DMatrix;

mod common;
use common::{basis, bumpy};

/// A refiner that returns a torn map: every vertex sent where the vertex
/// half the mesh away goes (the identity shifted).
#[derive(Debug)]
struct Torn;

impl Refiner for Torn {
    fn name(&self) -> String {
        "torn".into()
    }

    fn refine(&self, input: &RefineInput<'_>) -> Result<Refined> {
        let n = input.basis_b.n();
        Ok(Refined {
            c_ab: input.c_ab.clone(),
            t_ba: (0..n).map(|i| (i + n / 2) % n).collect(),
            report: RefineReport {
                method: self.name(),
                iterations: Vec::new(),
                converged: true,
                nn_searches: 0,
                nn_seconds: 0.0,
                seconds: 0.0,
            },
        })
    }
}

#[test]
fn the_least_distorting_map_is_kept_in_any_order() {
    let mesh = bumpy(0.08);
    let b = basis(&mesh, 30);
    let geo = || ShapeGeometry {
        vertices: mesh.vertices(),
        faces: mesh.faces(),
    };
    let c = DMatrix::<f64>::identity(10, 10);
    let input = RefineInput::new(&c, &b, &b).with_geometry(geo(), geo());
    let zoomout = ZoomOut::with_schedule("10:20:5").unwrap();
    let alone = zoomout.refine(&input).unwrap();
    let score = |t: &[usize]| {
        area_distortion(
            t,
            mesh.vertices(),
            mesh.faces(),
            mesh.vertices(),
            mesh.faces(),
        )
        .unwrap()
    };
    // The self-map refined stays the identity; the torn one stretches.
    assert!(score(&alone.t_ba) < 1e-9);
    assert!(score(&Torn.refine(&input).unwrap().t_ba) > 0.1);
    for order in [
        vec![
            Arc::new(Torn) as Arc<dyn Refiner>,
            Arc::new(zoomout.clone()),
        ],
        vec![
            Arc::new(zoomout.clone()) as Arc<dyn Refiner>,
            Arc::new(Torn),
        ],
    ] {
        let best = BestOf::new(order).unwrap();
        let r = best.refine(&input).unwrap();
        assert_eq!(r.t_ba, alone.t_ba);
        assert_eq!(r.c_ab, alone.c_ab);
        assert!(
            r.report.method.contains("kept zoomout"),
            "{}",
            r.report.method
        );
        assert_eq!(best.k_needed(), zoomout.k_needed());
    }
    // No refiner, or no geometry to score with: errors.
    assert!(BestOf::new(Vec::new()).is_err());
    let best = BestOf::new(vec![Arc::new(Torn) as Arc<dyn Refiner>]).unwrap();
    assert!(best.refine(&RefineInput::new(&c, &b, &b)).is_err());
}
