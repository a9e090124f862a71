//! On a real benchmark mesh (skipped with a message when the dataset is
//! absent): the mesh loads clean and the spectrum meets the basis contract;
//! with the `arpack` feature, both backends agree to 1e-10.

fn data_dir() -> Option<std::path::PathBuf> {
    fmaps_tests::data_dir("bcicp/FAUST/vtx_5k/tr_reg_000.off")
}

#[test]
fn faust_mesh_spectrum() {
    let Some(dir) = data_dir() else {
        fmaps_tests::missing_data("FAUST (bcicp/FAUST/vtx_5k)");
        return;
    };
    let mesh = fmaps::mesh_io::read_mesh(dir.join("bcicp/FAUST/vtx_5k/tr_reg_000.off")).unwrap();
    let r = mesh.validate();
    assert!(r.is_clean() && r.genus == Some(0), "{r:?}");
    let gt =
        fmaps::mesh_io::read_vts(dir.join("bcicp/FAUST/vtx_5k/corres/tr_reg_000.vts")).unwrap();
    fmaps::mesh_io::check_indices(&gt, mesh.n_vertices(), None).unwrap();

    let s = fmaps::spectrum(&mesh, 60, &fmaps::SpectrumParams::default()).unwrap();
    let b = &s.basis;
    assert!(b.eigenvalues[0].abs() < 1e-8 && b.eigenvalues[1] > 1.0);
    assert!(b.report.orthonormality_error < 1e-10);
    assert!(b.report.max_residual() < 1e-6 * b.eigenvalues[59]);

    #[cfg(feature = "arpack")]
    {
        let mut p = fmaps::SpectrumParams::default();
        p.backend = fmaps::Backend::Arpack;
        let a = fmaps::spectrum(&mesh, 60, &p).unwrap();
        for i in 1..60 {
            let (x, y) = (b.eigenvalues[i], a.basis.eigenvalues[i]);
            assert!((x - y).abs() < 1e-10 * y, "λ_{i}: native {x}, arpack {y}");
        }
    }
}
