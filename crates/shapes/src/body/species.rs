//! Bodies of other kinds than the template's: species-like proportions
//! and postures (long arms and short legs, on all fours, a large belly, a
//! short neck, a heavy tail), each in two poses, for benchmarks of
//! non-isometric matching with exact ground truth (every shape keeps its
//! vertices' rest positions on the template, as [`Body::shape`] does).
//!
//! ```
//! use fmaps_shapes::body::Body;
//! use fmaps_shapes::body::species::{SPECIES, species_shape};
//!
//! let body = Body::template();
//! let quadruped = SPECIES.iter().position(|s| s.name == "quadruped").unwrap();
//! let shape = species_shape(&body, quadruped, 0, 0.06)?;
//! assert!(shape.mesh.validate().is_closed_manifold());
//! # Ok::<(), fmaps_shapes::Error>(())
//! ```

use super::{Body, BodyPose, Build, GeneratedShape, bones};
use crate::Result;

/// A kind of body: its proportions and its usual posture.
#[derive(Debug, Clone, Copy)]
pub struct Species {
    /// Short name (`upright`, `ape`, `quadruped`, `bear`, `kangaroo`,
    /// `gibbon`).
    pub name: &'static str,
    /// Proportions.
    pub build: fn() -> Build,
    /// Posture at rest.
    pub posture: fn() -> BodyPose,
}

/// The species of the generated collection, in a fixed order.
pub const SPECIES: [Species; 6] = [
    Species {
        name: "upright",
        build: upright,
        posture: BodyPose::rest,
    },
    Species {
        name: "ape",
        build: ape,
        posture: knuckle_walking,
    },
    Species {
        name: "quadruped",
        build: quadruped,
        posture: on_all_fours,
    },
    Species {
        name: "bear",
        build: bear,
        posture: bear_standing,
    },
    Species {
        name: "kangaroo",
        build: kangaroo,
        posture: kangaroo_crouch,
    },
    Species {
        name: "gibbon",
        build: gibbon,
        posture: hanging,
    },
];

fn with(f: impl FnOnce(&mut Build)) -> Build {
    let mut b = Build::average();
    f(&mut b);
    b
}

/// Close to the template: a little slimmer, a little longer in the leg.
fn upright() -> Build {
    with(|b| {
        b.torso_girth = 0.9;
        b.leg_length = 1.1;
        b.tail_length = 0.8;
    })
}

/// Long arms, short legs and neck, a broad torso, a short tail.
fn ape() -> Build {
    with(|b| {
        b.arm_length = 1.55;
        b.arm_girth = 1.2;
        b.leg_length = 0.7;
        b.neck_length = 0.65;
        b.torso_girth = 1.25;
        b.head_size = 1.1;
        b.tail_length = 0.6;
    })
}

/// A long torso and neck, a long thin tail, legs and arms of one length.
fn quadruped() -> Build {
    with(|b| {
        b.torso_length = 1.3;
        b.torso_girth = 0.9;
        b.neck_length = 1.45;
        b.head_size = 0.9;
        b.arm_length = 1.1;
        b.arm_girth = 1.1;
        b.tail_length = 1.5;
        b.tail_girth = 0.8;
    })
}

/// A large belly, a thick body and limbs, short legs and neck.
fn bear() -> Build {
    with(|b| {
        b.belly = 1.6;
        b.torso_girth = 1.3;
        b.neck_length = 0.6;
        b.head_size = 1.15;
        b.leg_length = 0.75;
        b.leg_girth = 1.35;
        b.arm_length = 0.85;
        b.arm_girth = 1.3;
        b.tail_length = 0.6;
    })
}

/// Short thin arms, long strong legs, a long heavy tail.
fn kangaroo() -> Build {
    with(|b| {
        b.arm_length = 0.6;
        b.arm_girth = 0.8;
        b.leg_length = 1.45;
        b.leg_girth = 1.2;
        b.tail_length = 1.6;
        b.tail_girth = 1.4;
        b.neck_length = 1.2;
        b.head_size = 0.85;
        b.torso_length = 1.1;
    })
}

/// Very long thin arms, a slender body, short legs.
fn gibbon() -> Build {
    with(|b| {
        b.arm_length = 1.6;
        b.arm_girth = 0.75;
        b.leg_length = 0.8;
        b.leg_girth = 0.75;
        b.torso_girth = 0.75;
        b.tail_length = 0.6;
        b.head_size = 0.9;
    })
}

/// Torso tilted forward by `tilt` radians about the pelvis, legs turned
/// back by `legs` (so that they stay near vertical), arms by `arms`
/// (negative: towards the ground), the neck raised by `neck`.
fn tilted(tilt: f64, legs: f64, arms: f64, neck: f64) -> [[f64; 3]; super::N_BONES] {
    use bones::*;
    let mut p = [[0.0; 3]; super::N_BONES];
    p[PELVIS] = [tilt, 0.0, 0.0];
    p[L_THIGH] = [-legs, 0.0, 0.0];
    p[R_THIGH] = [-legs, 0.0, 0.0];
    p[L_ARM] = [arms, 0.0, 0.0];
    p[R_ARM] = [arms, 0.0, 0.0];
    p[NECK] = [-neck, 0.0, 0.0];
    p
}

/// Bent forward, knuckles towards the ground.
fn knuckle_walking() -> BodyPose {
    use bones::*;
    let mut p = tilted(0.7, 0.9, -0.9, 0.5);
    p[L_SHIN] = [0.4, 0.0, 0.0];
    p[R_SHIN] = [0.4, 0.0, 0.0];
    p[HEAD] = [-0.3, 0.0, 0.0];
    BodyPose(p)
}

/// The torso horizontal on four limbs, head raised, tail out behind.
fn on_all_fours() -> BodyPose {
    use bones::*;
    let mut p = tilted(1.45, 1.45, -1.45, 0.9);
    p[HEAD] = [-0.4, 0.0, 0.0];
    p[TAIL] = [-0.5, 0.0, 0.0];
    BodyPose(p)
}

/// Upright, leaning forward a little, arms forward.
fn bear_standing() -> BodyPose {
    use bones::*;
    let mut p = tilted(0.3, 0.3, -0.6, 0.2);
    p[L_FOREARM] = [-0.4, 0.0, 0.0];
    p[R_FOREARM] = [-0.4, 0.0, 0.0];
    BodyPose(p)
}

/// Leaning forward on bent legs, the tail reaching the ground behind.
fn kangaroo_crouch() -> BodyPose {
    use bones::*;
    let mut p = tilted(0.6, 1.3, -0.6, 0.5);
    p[L_SHIN] = [1.2, 0.0, 0.0];
    p[R_SHIN] = [1.2, 0.0, 0.0];
    p[TAIL] = [0.4, 0.0, 0.0];
    p[HEAD] = [-0.3, 0.0, 0.0];
    BodyPose(p)
}

/// Both arms raised above the head (the left higher), legs hanging.
fn hanging() -> BodyPose {
    use bones::*;
    let mut p = [[0.0; 3]; super::N_BONES];
    p[L_ARM] = [0.0, 0.0, 2.4];
    p[R_ARM] = [0.0, 0.0, -2.2];
    p[L_FOREARM] = [0.0, 0.0, 0.3];
    p[R_FOREARM] = [0.0, 0.0, -0.5];
    p[L_SHIN] = [0.5, 0.0, 0.0];
    p[R_SHIN] = [0.3, 0.0, 0.0];
    p[HEAD] = [0.3, 0.0, 0.0];
    BodyPose(p)
}

/// The posture with a stride added: one leg and the opposite arm forward,
/// the other pair back, the head turned.
fn striding(posture: BodyPose) -> BodyPose {
    use bones::*;
    let mut p = posture.0;
    for (bone, delta) in [
        (L_THIGH, -0.35),
        (R_THIGH, 0.3),
        (L_SHIN, 0.3),
        (L_ARM, 0.35),
        (R_ARM, -0.35),
    ] {
        p[bone][0] += delta;
    }
    p[HEAD][1] += 0.4;
    p[TAIL][1] += 0.5;
    BodyPose(p)
}

/// Shape `variant` (0: the species' posture, 1: striding) of species
/// `species` (an index of [`SPECIES`]): the posture jittered by 0.1 and the
/// template remeshed at `spacing` times a factor in 0.95-1.05, both from the
/// seed `1000 + 2 species + variant`, which [`Body::shape`] also gets.
///
/// Errors: a species or variant out of range.
pub fn species_shape(
    body: &Body,
    species: usize,
    variant: usize,
    spacing: f64,
) -> Result<GeneratedShape> {
    let s = SPECIES.get(species).ok_or_else(|| {
        crate::Error::Parameter(format!(
            "species {species}: there are {} species",
            SPECIES.len()
        ))
    })?;
    let pose = match variant {
        0 => (s.posture)(),
        1 => striding((s.posture)()),
        _ => {
            return Err(crate::Error::Parameter(format!(
                "variant {variant}: each species has variants 0 and 1"
            )));
        }
    };
    let seed = (1000 + 2 * species + variant) as u64;
    let factor = 0.95 + 0.1 * ((seed * 7919) % 97) as f64 / 96.0;
    body.shape(
        &(s.build)(),
        &pose.jittered(seed, 0.1),
        spacing * factor,
        seed,
    )
}
