//! `cargo xtask pictures`: pictures of one test pair per collection, into
//! `docs/pictures/<collection>/`: colour and texture transfer (source,
//! fmaps-init, fmaps-zoomout, and the default pipeline, Smooth Shells),
//! error heat maps, the default's C, the spectral embedding
//! and the cumulative curves of the methods `cargo xtask eval` knows for
//! that pair (fmaps, published maps, pyFM when its maps are present).

use std::path::PathBuf;

use anyhow::Context;
use fmaps::eval::{EvalParams, MapReport, evaluate};
use fmaps::geodesic::ExactSolver;
use fmaps::mesh_io::TriMesh;
use fmaps::pipeline::{MatchParams, Refinement, match_prepared, prepare};
use fmaps_viz::{self as viz, Axis, BLACK, Image, View, WHITE, plot};
use serde_json::json;

use crate::util::{bcicp_dir, collections_or_default, root};

/// Options of `cargo xtask pictures`.
#[derive(clap::Args)]
pub struct Args {
    /// Collections (default: FAUST and TOSCA_Isometric; also the splits
    /// and generated collections of `cargo xtask eval`).
    #[arg(long = "collection")]
    collections: Vec<String>,
    /// Which test pair (0-based line of test_pairs.txt).
    #[arg(long, default_value_t = 0)]
    pair: usize,
    /// Dataset directory (default: FMAPS_DATA or ../shared/datasets).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Output directory (default: docs/pictures).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Where pyFM's maps are (as for `cargo xtask eval`).
    #[arg(long, default_value = "target/peers")]
    peer_dir: PathBuf,
}

/// The camera of a collection: FAUST stands along y and faces +z; TOSCA
/// stands along z and is seen from the side, a little from above.
fn view_of(collection: &str) -> View {
    if collection.starts_with("TOSCA") {
        View {
            up: Axis::Z,
            yaw: 60f64.to_radians(),
            pitch: 20f64.to_radians(),
            ..View::default()
        }
    } else {
        View::default()
    }
}

/// `img` with a caption above it.
fn captioned(img: &Image, caption: &str) -> Image {
    let mut out = Image::new(img.width(), img.height() + 28, WHITE);
    out.blit(img, 0, 28);
    let x = (img.width() as i64 - 16 * caption.chars().count() as i64).max(0) / 2;
    out.text(x, 6, caption, 2, BLACK);
    out
}

/// Source with `colors`, and the target coloured through each map.
fn transfer_row(
    a: &TriMesh,
    b: &TriMesh,
    colors: &[[u8; 3]],
    maps: &[(&str, &[usize])],
    view: &View,
) -> anyhow::Result<Image> {
    let mut panels = vec![captioned(
        &viz::render(a.vertices(), a.faces(), colors, view)?,
        "source",
    )];
    for (name, t_ab) in maps {
        let ct = viz::push_colors(t_ab, colors, b.n_vertices(), b.faces());
        panels.push(captioned(
            &viz::render(b.vertices(), b.faces(), &ct, view)?,
            name,
        ));
    }
    Ok(Image::hstack(&panels, WHITE))
}

pub fn pictures(args: &Args) -> anyhow::Result<()> {
    let bcicp = bcicp_dir(args.data.as_deref())?;
    let collections = collections_or_default(&args.collections);
    let out_root = args
        .out
        .clone()
        .unwrap_or_else(|| root().join("docs/pictures"));
    let ep = EvalParams::default();
    for cname in &collections {
        let (c, pairs) = crate::eval::collection_pairs(&bcicp, cname)?;
        let (a, b) = pairs
            .into_iter()
            .nth(args.pair)
            .with_context(|| format!("{cname} has no test pair {}", args.pair))?;
        let out = out_root.join(cname);
        std::fs::create_dir_all(&out)?;
        let (ma, mb) = (c.read_mesh(&a)?, c.read_mesh(&b)?);
        // The eval methods of the same names: fmaps-init is the default
        // pipeline without refinement, fmaps-zoomout ZoomOut 50:150:5 from
        // the default starts.
        let mut params = MatchParams::unrefined();
        params.refinement = Refinement::default_zoomout();
        params.starts.sizes =
            fmaps::pipeline::default_starts(fmaps::pipeline::RefinerKind::Zoomout, usize::MAX);
        let (pa, pb) = (prepare(&ma, &params)?, prepare(&mb, &params)?);
        let r = match_prepared(&pa, &pb, &params)?;
        let r_init = match_prepared(&pa, &pb, &MatchParams::unrefined())?;
        // `fmaps match` without flags (fmaps-smooth-shells in the tables).
        let r_def = match_prepared(&pa, &pb, &MatchParams::default())?;
        let gt = c.ground_truth(&a, &b, ma.n_vertices(), mb.n_vertices())?;
        let gt_source = fmaps::mesh_io::read_vts(c.vts_path(&a, false))?;
        let solver = ExactSolver::new(&mb)?;
        let eval = |t: &[usize]| -> anyhow::Result<MapReport> {
            Ok(evaluate(&mb, &solver, t, &gt, None, &ep)?)
        };
        let (init, refined, default) = (eval(&r_init.t_ab)?, eval(&r.t_ab)?, eval(&r_def.t_ab)?);
        let view = view_of(cname);
        let mut written = Vec::new();
        let mut save = |img: &Image, name: &str| -> anyhow::Result<()> {
            let p = out.join(name);
            img.save_png(&p)?;
            written.push(name.to_string());
            Ok(())
        };
        let maps: [(&str, &[usize]); 3] = [
            ("fmaps-init", &r_init.t_ab),
            ("fmaps-zoomout", &r.t_ab),
            ("default (smooth shells)", &r_def.t_ab),
        ];
        let colors = viz::position_colors(ma.vertices());
        save(
            &transfer_row(&ma, &mb, &colors, &maps, &view)?,
            "color-transfer.png",
        )?;
        let uv = fmaps::pictures::camera_uv(&ma, &view);
        save(
            &transfer_row(&ma, &mb, &viz::checkerboard(&uv, 10), &maps, &view)?,
            "texture-transfer.png",
        )?;
        let vmax = 0.1;
        let mut panels = Vec::new();
        for (name, rep) in [
            ("fmaps-init", &init),
            ("fmaps-zoomout", &refined),
            ("default", &default),
        ] {
            let per_vertex = fmaps::pictures::vertex_values(&ma, &gt_source, &rep.errors);
            let colors = viz::scalar_colors(&per_vertex, 0.0, vmax);
            panels.push(captioned(
                &viz::render(ma.vertices(), ma.faces(), &colors, &view)?,
                &format!("{name}: {:.2}", 100.0 * rep.mean_error),
            ));
        }
        panels.push(captioned(
            &viz::colorbar(view.height, 0.0, vmax, "error / sqrt(area)"),
            "",
        ));
        save(&Image::hstack(&panels, WHITE), "error.png")?;
        save(
            &plot::heatmap(
                &format!(
                    "C_BA of the default ({0} x {0}), {1:.1}% < 0.1",
                    r_def.c_ba.nrows(),
                    100.0 * r_def.metrics.sparsity
                ),
                &r_def.c_ba,
                1.0,
            ),
            "fmap.png",
        )?;
        let mut emb = Vec::new();
        for (mesh, p, name) in [(&ma, &pa, a.as_str()), (&mb, &pb, b.as_str())] {
            emb.push(captioned(
                &fmaps::pictures::spectral_embedding(mesh, &p.basis, [1, 2, 3], &View::default())?,
                name,
            ));
        }
        save(&Image::hstack(&emb, WHITE), "spectral-embedding.png")?;

        // Cumulative curves: ours and every other method with a map for this pair.
        let mut series = vec![
            curve(
                &format!("fmaps-init ({:.2})", 100.0 * init.mean_error),
                &init,
            ),
            curve(
                &format!("fmaps-zoomout ({:.2})", 100.0 * refined.mean_error),
                &refined,
            ),
            curve(
                &format!("default, smooth shells ({:.2})", 100.0 * default.mean_error),
                &default,
            ),
        ];
        let mut others = serde_json::Map::new();
        let mut methods: Vec<String> = c.published_methods()?;
        methods.push("pyfm:fm_orient_zoomout".into());
        for m in &methods {
            let t = if let Some(stage) = m.strip_prefix("pyfm:") {
                let p = root()
                    .join(&args.peer_dir)
                    .join(format!("pyfm-{cname}/maps/{stage}/{a}_{b}.map"));
                p.exists()
                    .then(|| fmaps::mesh_io::read_map(&p))
                    .transpose()?
            } else {
                c.published_maps(m)?.read(&a, &b)?
            };
            let Some(t) = t else { continue };
            let rep = eval(&t)?;
            others.insert(m.clone(), json!(rep.mean_error));
            series.push(curve(&format!("{m} ({:.2})", 100.0 * rep.mean_error), &rep));
        }
        save(
            &plot::cumulative_curves(&format!("{a} -> {b} ({cname})"), ep.max_threshold, &series),
            "curves.png",
        )?;
        let summary = json!({
            "collection": cname, "pair": [a, b], "n_vertices": [ma.n_vertices(), mb.n_vertices()],
            "mean_error_init": init.mean_error, "mean_error_zoomout": refined.mean_error,
            "mean_error_default": default.mean_error, "orientation_default": r_def.orientation, "other_methods": others, "pictures": written,
            "command": "cargo xtask pictures",
        });
        std::fs::write(
            out.join("pair.json"),
            serde_json::to_string_pretty(&summary)? + "\n",
        )?;
        println!(
            "{cname} {a} -> {b}: mean error x100 fmaps-init {:.2}, fmaps-zoomout {:.2}, default (smooth shells) {:.2}{}",
            100.0 * init.mean_error,
            100.0 * refined.mean_error,
            100.0 * default.mean_error,
            others
                .iter()
                .map(|(m, e)| format!(", {m} {:.2}", 100.0 * e.as_f64().unwrap_or(f64::NAN)))
                .collect::<String>()
        );
        for p in &written {
            println!("  {}", out.join(p).display());
        }
    }
    Ok(())
}

fn curve(label: &str, r: &MapReport) -> plot::Series {
    plot::Series {
        label: label.to_string(),
        x: r.thresholds.clone(),
        y: r.curve.clone(),
    }
}
