//! The generated benchmark collection (`cargo xtask generate`, and on
//! demand by `cargo xtask eval --collection generated-iso|generated-noniso`):
//! bodies of [`fmaps::shapes::body`] with exact ground truth, written in
//! the layout of the remeshed FAUST/TOSCA benchmark so that every tool
//! (`fmaps eval`, `cargo xtask eval`, the Python peers) reads them as it
//! reads FAUST.
//!
//! Six individuals (pseudo-random [`Build`](fmaps::shapes::body::Build)s: limbs and tail 0.6-1.6 times
//! the template, girths and head 0.7-1.4, ...), each in four poses (rest,
//! walking, crouching, reaching, each jittered per individual); every shape
//! remeshed independently (grid spacing 0.039-0.047, random grid offset:
//! about 4,300-6,100 vertices), turned about the vertical axis and moved at
//! random. Ground truth:
//! 5,000-odd template points (the vertices of one more mesh of the
//! template) to the nearest vertex of each shape's rest positions, as
//! FAUST's and TOSCA's `.vts` do; `.sym.vts` the same for the mirrored
//! template points.
//!
//! - `generated-iso`: the same individual in two poses (36 pairs).
//! - `generated-noniso`: two different individuals (30 pairs, both orders
//!   of each pair of individuals with different poses).
//! - `generated-species`: two different species of
//!   [`fmaps::shapes::body::species`] (upright, ape, quadruped on all fours,
//!   bear with a large belly, kangaroo, gibbon; each in its posture and
//!   striding): 30 pairs, both orders of each pair of species, one in
//!   each variant; shapes `species_<s>_<v>`, remeshed at spacing
//!   0.041-0.045.

use std::path::{Path, PathBuf};

use anyhow::Context;
use fmaps::shapes::body::species::{SPECIES, species_shape};
use fmaps::shapes::body::{Body, mirrored, nearest_vertices};

use crate::util::root;

/// Bump when the generator or the layout changes: the collection is
/// rebuilt when its stamp differs.
const VERSION: &str = "generated-bodies v3";
/// Individuals and poses.
pub const INDIVIDUALS: usize = 6;
pub const POSES: usize = 4;

/// Options of `cargo xtask generate`.
#[derive(clap::Args)]
pub struct Args {
    /// Rebuild even when the stamp is current.
    #[arg(long)]
    force: bool,
}

/// Name of a shape.
pub fn shape_name(individual: usize, pose: usize) -> String {
    format!("body_{individual}_{pose}")
}

/// Name of a species shape.
pub fn species_name(species: usize, variant: usize) -> String {
    format!("species_{species}_{variant}")
}

/// The benchmark root (`bcicp`-like) holding the `generated` collection,
/// built first when missing or stale.
pub fn generated_root(force: bool) -> anyhow::Result<PathBuf> {
    let bcicp = root().join("target/generated/bcicp");
    let dir = bcicp.join("generated");
    let stamp = dir.join("STAMP");
    if !force && std::fs::read_to_string(&stamp).ok().as_deref() == Some(VERSION) {
        return Ok(bcicp);
    }
    eprintln!("generating {} ...", dir.display());
    write_collection(&dir).with_context(|| format!("writing {}", dir.display()))?;
    std::fs::write(&stamp, VERSION)?;
    Ok(bcicp)
}

/// `cargo xtask generate`.
pub fn generate(args: &Args) -> anyhow::Result<()> {
    let bcicp = generated_root(args.force)?;
    println!(
        "{}: {} shapes, pairs in test_pairs.txt (iso, non-iso, species); evaluate with cargo xtask eval --collection generated-iso --collection generated-noniso --collection generated-species",
        bcicp.join("generated").display(),
        INDIVIDUALS * POSES + 2 * SPECIES.len()
    );
    Ok(())
}

fn write_collection(dir: &Path) -> anyhow::Result<()> {
    use rayon::prelude::*;
    let shapes_dir = dir.join("vtx_5k");
    let corres = shapes_dir.join("corres");
    std::fs::create_dir_all(&corres)?;
    let body = Body::template();
    let points = body.truth_points()?;
    let mirror: Vec<[f64; 3]> = points.iter().map(|&p| mirrored(p)).collect();
    // (individual, pose) of the bodies, then (species, variant) offset by
    // INDIVIDUALS.
    let jobs: Vec<(usize, usize)> = (0..INDIVIDUALS)
        .flat_map(|i| (0..POSES).map(move |p| (i, p)))
        .chain((0..SPECIES.len()).flat_map(|s| (0..2).map(move |v| (INDIVIDUALS + s, v))))
        .collect();
    jobs.par_iter()
        .try_for_each(|&(i, p)| -> anyhow::Result<()> {
            let (shape, name) = if i < INDIVIDUALS {
                (body.collection_shape(i, p)?, shape_name(i, p))
            } else {
                let s = i - INDIVIDUALS;
                (species_shape(&body, s, p, 0.043)?, species_name(s, p))
            };
            fmaps::mesh_io::write_mesh(shapes_dir.join(format!("{name}.off")), &shape.mesh)?;
            fmaps::mesh_io::write_vts(
                corres.join(format!("{name}.vts")),
                &nearest_vertices(&points, &shape.rest),
            )?;
            fmaps::mesh_io::write_vts(
                corres.join(format!("{name}.sym.vts")),
                &nearest_vertices(&mirror, &shape.rest),
            )?;
            Ok(())
        })?;
    let mut lines = String::new();
    for (a, b) in iso_pairs()
        .into_iter()
        .chain(noniso_pairs())
        .chain(species_pairs())
    {
        lines.push_str(&format!("{a}\t{b}\n"));
    }
    std::fs::write(dir.join("test_pairs.txt"), lines)?;
    Ok(())
}

/// Same individual, two poses: every pose pair of every individual.
pub fn iso_pairs() -> Vec<(String, String)> {
    let mut out = Vec::new();
    for i in 0..INDIVIDUALS {
        for p in 0..POSES {
            for q in p + 1..POSES {
                out.push((shape_name(i, p), shape_name(i, q)));
            }
        }
    }
    out
}

/// Two individuals: for each pair i < j, i -> j and j -> i in different
/// poses.
pub fn noniso_pairs() -> Vec<(String, String)> {
    let mut out = Vec::new();
    for i in 0..INDIVIDUALS {
        for j in i + 1..INDIVIDUALS {
            out.push((
                shape_name(i, (i + j) % POSES),
                shape_name(j, (i + 2 * j + 1) % POSES),
            ));
            out.push((
                shape_name(j, (i + j + 1) % POSES),
                shape_name(i, (2 * i + j) % POSES),
            ));
        }
    }
    out
}

/// Two species: for each pair s < t, s -> t and t -> s, one shape of each
/// variant.
pub fn species_pairs() -> Vec<(String, String)> {
    let mut out = Vec::new();
    let n = SPECIES.len();
    for s in 0..n {
        for t in s + 1..n {
            let v = (s + t) % 2;
            out.push((species_name(s, v), species_name(t, 1 - v)));
            out.push((species_name(t, v), species_name(s, 1 - v)));
        }
    }
    out
}
