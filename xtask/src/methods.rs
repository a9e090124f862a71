//! The refiners `cargo xtask eval` methods name: `REFINER@PUBLISHED`'s
//! refiner and the Smooth Shells variants `smooth-shells[:KEY=VALUE,..]`.

use anyhow::{Context, bail};

/// The refiner of a `REFINER@PUBLISHED` method: `zoomout` (50 -> 150
/// step 5), `zoomout:START:FINAL:STEP`, `icp` (10 iterations at k = 50),
/// `bijective-zoomout` or `discrete` (discrete optimisation presets, 50 ->
/// 150 step 5).
pub(crate) fn refiner_method(refiner: &str) -> anyhow::Result<fmaps::pipeline::Refinement> {
    use fmaps::pipeline::Refinement;
    Ok(match refiner {
        "zoomout" => Refinement::default_zoomout(),
        "icp" => Refinement::Icp(fmaps::refine::Icp::default()),
        "bijective-zoomout" | "discrete" => Refinement::Custom(std::sync::Arc::new(
            fmaps::refine::DiscreteOp::preset(refiner)?,
        )),
        "bcicp" => Refinement::Custom(std::sync::Arc::new(fmaps::refine::Repair::default())),
        r if r == "smooth-shells" || r.starts_with("smooth-shells:") => {
            Refinement::Custom(std::sync::Arc::new(smooth_shells(r)?))
        }
        r => match r.strip_prefix("zoomout:") {
            Some(spec) => Refinement::ZoomOut {
                zoomout: fmaps::refine::ZoomOut::with_schedule(spec)
                    .with_context(|| format!("method {r}@.."))?,
                samples: None,
            },
            None => bail!(
                "unknown refiner '{r}' in {r}@..: expected zoomout, zoomout:START:FINAL:STEP, icp, bijective-zoomout, discrete, bcicp or smooth-shells"
            ),
        },
    })
}

/// `smooth-shells[:KEY=VALUE,..]`: Smooth Shells with the defaults but the
/// keys given (k_max, levels, samples, init_samples, proposals, finalists,
/// signs, seed, rigid, orientations, input, screen: 0 or 1 for rigid and
/// input; select: 0 orientation score, 1 area distortion and orientation);
/// `smooth-shells:non-isometric` is [`fmaps::refine::SmoothShells::non_isometric`]
/// (`fmaps match --non-isometric`).
fn smooth_shells(spec: &str) -> anyhow::Result<fmaps::refine::SmoothShells> {
    let mut s = fmaps::refine::SmoothShells::default();
    let Some(list) = spec.strip_prefix("smooth-shells:") else {
        return Ok(s);
    };
    let list = match list.strip_prefix("non-isometric") {
        Some(rest) => {
            s = fmaps::refine::SmoothShells::non_isometric();
            match rest.strip_prefix(',') {
                Some(rest) => rest,
                None if rest.is_empty() => return Ok(s),
                None => bail!("{spec}: expected non-isometric[,KEY=VALUE,..]"),
            }
        }
        None => list,
    };
    for kv in list.split(',') {
        let (k, v) = kv
            .split_once('=')
            .with_context(|| format!("{spec}: expected KEY=VALUE, got '{kv}'"))?;
        let n: u64 = v
            .parse()
            .with_context(|| format!("{spec}: '{v}' is not a number"))?;
        let u = n as usize;
        match k {
            "k_max" => s.k_max = u,
            "levels" => s.levels = u,
            "samples" => s.samples = u,
            "init_samples" => s.init_samples = u,
            "proposals" => s.proposals = u,
            "finalists" => s.finalists = u,
            "signs" => s.sign_hypotheses = u,
            "seed" => s.seed = n,
            "rigid" => s.rigid = n != 0,
            "orientations" => s.orientations = u,
            "input" => s.use_input_map = n != 0,
            "screen" => s.screen = u,
            "select" => {
                s.select = match n {
                    0 => fmaps::refine::Select::Orientation,
                    1 => fmaps::refine::Select::AreaAndOrientation,
                    _ => bail!("{spec}: select is 0 (orientation) or 1 (area and orientation)"),
                }
            }
            _ => bail!(
                "{spec}: unknown key '{k}' (k_max, levels, samples, init_samples, proposals, finalists, signs, seed, rigid, orientations, input, screen, select)"
            ),
        }
    }
    Ok(s)
}
