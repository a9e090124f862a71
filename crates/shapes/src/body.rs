//! Generated bodies for matching benchmarks with exact ground truth: a
//! skeleton (pelvis, chest, neck, head with a snout, two arms, two legs
//! with feet, a two-bone tail), a smooth implicit surface around it, and
//! linear blend skinning that changes the proportions of each body part
//! and poses the joints.
//!
//! - **One template.** [`Body::template`] is the canonical body at rest;
//!   its surface is the zero set of [`Body::implicit`] (tapered capsules
//!   around the bones, blended by a smooth minimum). Its left and right
//!   sides differ by a few percent only (an arm slightly longer, a thigh
//!   slightly thicker, the head tilted), so a left/right flip is a real
//!   failure mode of a matcher, yet the truth is unambiguous.
//! - **Independent remeshing.** [`Body::rest_mesh`] meshes the template
//!   surface on a grid of a given spacing and offset (marching tetrahedra,
//!   then relaxation): every shape gets its own vertex count and
//!   connectivity.
//! - **Proportions and pose.** [`Body::deform`] moves a rest mesh with a
//!   [`Build`] (length and girth of torso, arms, legs, tail; neck length;
//!   head size; each 0.6-1.6) and a [`BodyPose`] (a rotation per joint):
//!   every bone gets the affine map "scale along and across the bone, then
//!   rotate about its joint", composed down the skeleton, and every vertex
//!   the blend of its bones' maps with weights from its distance to each
//!   bone. Two builds give a non-isometric pair; one build in two poses a
//!   near-isometric pair.
//! - **Ground truth.** Each shape keeps its vertices' positions on the
//!   template ([`GeneratedShape::rest`]); [`nearest_vertices`] of template
//!   points gives the `.vts` correspondence used by the benchmarks (the
//!   same protocol as FAUST/TOSCA: template points to their nearest
//!   vertex), and their mirror images the symmetric truth.
//!
//! ```
//! use fmaps_shapes::body::{Body, BodyPose, Build};
//!
//! let body = Body::template();
//! let shape = body.shape(&Build::random(7), &BodyPose::walking(), 0.06, 3)?;
//! let report = shape.mesh.validate();
//! assert!(report.is_closed_manifold() && report.genus == Some(0));
//! assert_eq!(shape.rest.len(), shape.mesh.n_vertices());
//! # Ok::<(), fmaps_shapes::Error>(())
//! ```

use crate::isosurface::{Grid, marching_tetrahedra, relax};
use crate::smoothstep;
use fmaps_mesh_io::TriMesh;
use fmaps_mesh_io::vec3::{dot, normalized, rotate, sub};
use fmaps_simd::SplitMix;

use crate::Result;
use geometry::{Affine, capsule_distance, mat_mul, rotation_matrix, smooth_min};

/// Number of bones of the template skeleton.
pub const N_BONES: usize = 18;

/// What a bone belongs to (which [`Build`] factors scale it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Part {
    Torso,
    Neck,
    Head,
    Arm,
    Hand,
    Leg,
    Foot,
    Tail,
}

/// A bone: a segment from its joint (`start`) to `end` at rest.
#[derive(Debug, Clone, Copy)]
struct Bone {
    parent: Option<usize>,
    start: [f64; 3],
    end: [f64; 3],
    part: Part,
}

/// A tapered capsule around a segment, owned by a bone.
#[derive(Debug, Clone, Copy)]
struct Capsule {
    bone: usize,
    a: [f64; 3],
    b: [f64; 3],
    ra: f64,
    rb: f64,
}

/// Bone indices, for poses.
pub mod bones {
    /// Lower torso (the root).
    pub const PELVIS: usize = 0;
    /// Upper torso.
    pub const CHEST: usize = 1;
    /// Neck.
    pub const NECK: usize = 2;
    /// Head.
    pub const HEAD: usize = 3;
    /// Left upper arm, forearm, hand (the right ones are +3).
    pub const L_ARM: usize = 4;
    /// Left forearm.
    pub const L_FOREARM: usize = 5;
    /// Right upper arm.
    pub const R_ARM: usize = 7;
    /// Right forearm.
    pub const R_FOREARM: usize = 8;
    /// Left thigh, shin, foot (the right ones are +3).
    pub const L_THIGH: usize = 10;
    /// Left shin.
    pub const L_SHIN: usize = 11;
    /// Right thigh.
    pub const R_THIGH: usize = 13;
    /// Right shin.
    pub const R_SHIN: usize = 14;
    /// Tail base.
    pub const TAIL: usize = 16;
    /// Tail tip.
    pub const TAIL_TIP: usize = 17;
}

/// The template body: skeleton and surface at rest.
#[derive(Debug, Clone)]
pub struct Body {
    bones: Vec<Bone>,
    capsules: Vec<Capsule>,
    /// Width of the smooth minimum that blends the capsules.
    blend: f64,
    /// Width of the skinning weights' fall-off.
    skin: f64,
    /// Index in `capsules` of the belly (scaled by [`Build::belly`]).
    belly: usize,
}

/// Proportions of a body: each factor multiplies the template's (1 = the
/// template).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Build {
    /// Length of pelvis and chest.
    pub torso_length: f64,
    /// Width and depth of the torso.
    pub torso_girth: f64,
    /// Length of the neck.
    pub neck_length: f64,
    /// Size of the head (all directions).
    pub head_size: f64,
    /// Length of upper arms and forearms.
    pub arm_length: f64,
    /// Thickness of the arms.
    pub arm_girth: f64,
    /// Length of thighs and shins.
    pub leg_length: f64,
    /// Thickness of the legs.
    pub leg_girth: f64,
    /// Length of the tail.
    pub tail_length: f64,
    /// Thickness of the tail.
    pub tail_girth: f64,
    /// Size of the belly: its bulge away from the belly's axis, forward and
    /// sideways, is scaled by this factor (1 = the template's).
    pub belly: f64,
}

impl Build {
    /// The template's proportions.
    pub fn average() -> Build {
        Build {
            torso_length: 1.0,
            torso_girth: 1.0,
            neck_length: 1.0,
            head_size: 1.0,
            arm_length: 1.0,
            arm_girth: 1.0,
            leg_length: 1.0,
            leg_girth: 1.0,
            tail_length: 1.0,
            tail_girth: 1.0,
            belly: 1.0,
        }
    }

    /// Pseudo-random proportions (log-uniform): limb and tail lengths in
    /// 0.6-1.6, girths and head size in 0.7-1.4, torso length in
    /// 0.75-1.3, neck length in 0.6-1.5; the template's belly (see
    /// [`species`] for bellies and postures of other kinds of body).
    pub fn random(seed: u64) -> Build {
        let mut rng = SplitMix(seed ^ 0xB0D1);
        let mut f = |lo: f64, hi: f64| (lo.ln() + rng.unit() * (hi.ln() - lo.ln())).exp();
        Build {
            torso_length: f(0.75, 1.3),
            torso_girth: f(0.7, 1.4),
            neck_length: f(0.6, 1.5),
            head_size: f(0.7, 1.4),
            arm_length: f(0.6, 1.6),
            arm_girth: f(0.7, 1.4),
            leg_length: f(0.6, 1.6),
            leg_girth: f(0.7, 1.4),
            tail_length: f(0.6, 1.6),
            tail_girth: f(0.7, 1.4),
            belly: 1.0,
        }
    }

    /// Scale along and across a bone of this part.
    fn scales(&self, part: Part) -> (f64, f64) {
        match part {
            Part::Torso => (self.torso_length, self.torso_girth),
            Part::Neck => (self.neck_length, self.torso_girth.sqrt()),
            Part::Head => (self.head_size, self.head_size),
            Part::Arm => (self.arm_length, self.arm_girth),
            Part::Hand => (self.arm_length.sqrt(), self.arm_girth),
            Part::Leg => (self.leg_length, self.leg_girth),
            Part::Foot => (self.leg_length.sqrt(), self.leg_girth),
            Part::Tail => (self.tail_length, self.tail_girth),
        }
    }
}

/// A pose: per bone, the rotation at its joint relative to its parent, as
/// a rotation vector (axis times angle in radians; x to the body's left,
/// y up, z forward). The template stands with arms lowered to the sides
/// ("A pose"), legs straight and the tail down and back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyPose(pub [[f64; 3]; N_BONES]);

impl BodyPose {
    /// The template's pose.
    pub fn rest() -> BodyPose {
        BodyPose([[0.0; 3]; N_BONES])
    }

    /// Mid-stride: left leg forward, right back, knees bent, arms swinging
    /// against the legs, head turned, tail swaying.
    pub fn walking() -> BodyPose {
        use bones::*;
        let mut p = [[0.0; 3]; N_BONES];
        p[L_THIGH] = [-0.5, 0.0, 0.0];
        p[L_SHIN] = [0.35, 0.0, 0.0];
        p[R_THIGH] = [0.35, 0.0, 0.0];
        p[R_SHIN] = [0.6, 0.0, 0.0];
        p[L_ARM] = [0.4, 0.0, 0.0];
        p[L_FOREARM] = [-0.5, 0.0, 0.0];
        p[R_ARM] = [-0.45, 0.0, 0.0];
        p[R_FOREARM] = [-0.3, 0.0, 0.0];
        p[HEAD] = [0.0, 0.4, 0.0];
        p[TAIL] = [0.0, 0.5, 0.0];
        p[TAIL_TIP] = [0.0, 0.6, 0.0];
        BodyPose(p)
    }

    /// Crouching: hips and knees bent, torso leaning forward, arms
    /// reaching forward, tail raised.
    pub fn crouching() -> BodyPose {
        use bones::*;
        let mut p = [[0.0; 3]; N_BONES];
        p[L_THIGH] = [-1.0, 0.0, 0.1];
        p[R_THIGH] = [-0.9, 0.0, -0.1];
        p[L_SHIN] = [1.2, 0.0, 0.0];
        p[R_SHIN] = [1.1, 0.0, 0.0];
        p[CHEST] = [0.45, 0.0, 0.0];
        p[L_ARM] = [-0.9, 0.0, 0.3];
        p[R_ARM] = [-0.8, 0.0, -0.3];
        p[L_FOREARM] = [-0.4, 0.0, 0.0];
        p[R_FOREARM] = [-0.5, 0.0, 0.0];
        p[NECK] = [-0.3, 0.0, 0.0];
        p[TAIL] = [-0.7, 0.0, 0.0];
        p[TAIL_TIP] = [-0.5, 0.0, 0.0];
        BodyPose(p)
    }

    /// Arms raised (the left higher), torso twisted and bent sideways,
    /// one leg lifted sideways, tail curled.
    pub fn reaching() -> BodyPose {
        use bones::*;
        let mut p = [[0.0; 3]; N_BONES];
        p[L_ARM] = [0.0, 0.0, 1.5];
        p[L_FOREARM] = [0.0, 0.0, 0.4];
        p[R_ARM] = [0.0, 0.0, -1.0];
        p[R_FOREARM] = [-0.7, 0.0, 0.0];
        p[CHEST] = [0.0, 0.4, 0.2];
        p[HEAD] = [0.25, -0.3, 0.0];
        p[L_THIGH] = [0.0, 0.0, 0.45];
        p[L_SHIN] = [0.3, 0.0, 0.0];
        p[TAIL] = [0.0, -0.6, 0.0];
        p[TAIL_TIP] = [0.0, -0.9, 0.0];
        BodyPose(p)
    }

    /// This pose with every joint's rotation perturbed by up to `amount`
    /// radians about each axis (pseudo-random, from `seed`).
    pub fn jittered(&self, seed: u64, amount: f64) -> BodyPose {
        let mut rng = SplitMix(seed ^ 0x9051);
        let mut p = self.0;
        for r in p.iter_mut().skip(1) {
            for x in r.iter_mut() {
                *x += amount * (2.0 * rng.unit() - 1.0);
            }
        }
        BodyPose(p)
    }
}

/// A generated shape: the posed mesh and, per vertex, its position on the
/// template at rest (where the ground truth is defined).
#[derive(Debug, Clone)]
pub struct GeneratedShape {
    /// The shape.
    pub mesh: TriMesh,
    /// Vertex `i`'s position on the template surface.
    pub rest: Vec<[f64; 3]>,
}

impl Body {
    /// The template body: 1.9 units tall, standing at the origin (pelvis),
    /// facing +z, its left side at +x.
    pub fn template() -> Body {
        let mut bones = Vec::with_capacity(N_BONES);
        let mut capsules = Vec::new();
        let mut add = |parent: Option<usize>,
                       start: [f64; 3],
                       end: [f64; 3],
                       ra: f64,
                       rb: f64,
                       part: Part|
         -> usize {
            let id = bones.len();
            bones.push(Bone {
                parent,
                start,
                end,
                part,
            });
            capsules.push(Capsule {
                bone: id,
                a: start,
                b: end,
                ra,
                rb,
            });
            id
        };
        let pelvis = add(
            None,
            [0.0, 0.0, 0.0],
            [0.0, 0.3, 0.0],
            0.15,
            0.14,
            Part::Torso,
        );
        let chest = add(
            Some(pelvis),
            [0.0, 0.3, 0.0],
            [0.0, 0.62, 0.0],
            0.14,
            0.16,
            Part::Torso,
        );
        let neck = add(
            Some(chest),
            [0.0, 0.62, 0.0],
            [0.0, 0.76, 0.01],
            0.055,
            0.05,
            Part::Neck,
        );
        // The head tilts a little to the left: one of the small asymmetries.
        let head = add(
            Some(neck),
            [0.0, 0.76, 0.01],
            [0.012, 0.98, 0.03],
            0.1,
            0.095,
            Part::Head,
        );
        debug_assert_eq!((chest, head), (bones::CHEST, bones::HEAD));
        // Arms: the left one 3% longer. Legs: the right thigh 4% thicker.
        for (side, long) in [(1.0, 1.03), (-1.0, 1.0)] {
            let s = [0.17 * side, 0.58, 0.0];
            let e = [s[0] + 0.25 * side * long, s[1] - 0.22 * long, 0.0];
            let upper = add(Some(chest), s, e, 0.05, 0.04, Part::Arm);
            let w = [e[0] + 0.2 * side * long, e[1] - 0.2 * long, 0.03 * long];
            let fore = add(Some(upper), e, w, 0.04, 0.032, Part::Arm);
            let tip = [w[0] + 0.08 * side, w[1] - 0.09, w[2] + 0.02];
            add(Some(fore), w, tip, 0.036, 0.028, Part::Hand);
        }
        for (side, thick) in [(1.0, 1.0), (-1.0, 1.04)] {
            let s = [0.09 * side, 0.02, 0.0];
            let k = [0.12 * side, -0.42, 0.0];
            let thigh = add(Some(pelvis), s, k, 0.08 * thick, 0.055 * thick, Part::Leg);
            let a = [0.13 * side, -0.84, -0.01];
            let shin = add(Some(thigh), k, a, 0.05 * thick, 0.035, Part::Leg);
            let toe = [0.14 * side, -0.9, 0.15];
            add(Some(shin), a, toe, 0.038, 0.03, Part::Foot);
        }
        let tail = add(
            Some(pelvis),
            [0.0, 0.0, -0.13],
            [0.0, -0.12, -0.4],
            0.05,
            0.035,
            Part::Tail,
        );
        add(
            Some(tail),
            [0.0, -0.12, -0.4],
            [0.0, -0.2, -0.65],
            0.037,
            0.026,
            Part::Tail,
        );
        debug_assert_eq!(bones.len(), N_BONES);
        // Extra volumes: shoulders and belly on the chest, hips on the
        // pelvis, a snout on the head (front and back differ).
        capsules.push(Capsule {
            bone: bones::CHEST,
            a: [-0.16, 0.56, 0.0],
            b: [0.16, 0.56, 0.0],
            ra: 0.075,
            rb: 0.075,
        });
        let belly = capsules.len();
        capsules.push(Capsule {
            bone: bones::CHEST,
            a: [0.0, 0.36, 0.04],
            b: [0.0, 0.48, 0.05],
            ra: 0.13,
            rb: 0.13,
        });
        capsules.push(Capsule {
            bone: bones::PELVIS,
            a: [-0.085, 0.03, -0.01],
            b: [0.085, 0.03, -0.01],
            ra: 0.11,
            rb: 0.11,
        });
        capsules.push(Capsule {
            bone: bones::HEAD,
            a: [0.0, 0.85, 0.05],
            b: [0.0, 0.83, 0.14],
            ra: 0.055,
            rb: 0.035,
        });
        Body {
            bones,
            capsules,
            blend: 0.035,
            skin: 0.04,
            belly,
        }
    }

    /// The template's signed function: negative inside, zero on the
    /// surface (a smooth minimum of the capsules' distances).
    pub fn implicit(&self, p: [f64; 3]) -> f64 {
        let mut d = f64::INFINITY;
        for c in &self.capsules {
            d = smooth_min(d, capsule_distance(c, p), self.blend);
        }
        d
    }

    /// A mesh of the template surface on a grid of the given spacing and
    /// offset (fractions of the spacing in `[0, 1)`), relaxed; its largest
    /// connected component (a grid much coarser than 0.05 can cut the
    /// tips of tail and hands off).
    pub fn rest_mesh(&self, spacing: f64, offset: [f64; 3]) -> Result<TriMesh> {
        let f = |p: [f64; 3]| self.implicit(p);
        let grid = Grid {
            min: [-1.1, -1.2, -1.0],
            max: [1.1, 1.3, 0.6],
            spacing,
            offset: offset.map(|o| o.clamp(0.0, 0.999) * spacing),
        };
        let raw = marching_tetrahedra(&f, &grid)?;
        relax(&largest_component(&raw)?, &f, 12)
    }

    /// The rest mesh moved to a build and a pose (linear blend skinning of
    /// the bones' affine maps).
    pub fn deform(&self, rest: &TriMesh, build: &Build, pose: &BodyPose) -> Result<TriMesh> {
        let maps = self.bone_maps(build, pose);
        let v = rest
            .vertices()
            .iter()
            .map(|&rest_x| {
                let w = self.weights(rest_x);
                let x = self.bulge(rest_x, build.belly);
                let mut y = [0.0; 3];
                for (b, wb) in w.iter().enumerate() {
                    if *wb > 0.0 {
                        let t = maps[b].apply(x);
                        for a in 0..3 {
                            y[a] += wb * t[a];
                        }
                    }
                }
                y
            })
            .collect();
        Ok(TriMesh::new(v, rest.faces().to_vec())?)
    }

    /// A shape: the template remeshed (grid `spacing`, offset from
    /// `seed`), deformed to `build` and `pose`, then turned about the
    /// vertical (y) axis and moved (also from `seed`) so that extrinsic
    /// coordinates do not give the correspondence away.
    pub fn shape(
        &self,
        build: &Build,
        pose: &BodyPose,
        spacing: f64,
        seed: u64,
    ) -> Result<GeneratedShape> {
        let mut rng = SplitMix(seed ^ 0x5EED);
        let offset = [rng.unit(), rng.unit(), rng.unit()];
        let rest = self.rest_mesh(spacing, offset)?;
        let posed = self.deform(&rest, build, pose)?;
        // A turn about the vertical axis (y stays up, so that pictures of
        // the shapes need no per-shape view) by a pseudo-random angle.
        let _ = [rng.unit(), rng.unit(), rng.unit()];
        let axis = [0.0, 1.0, 0.0];
        let angle = 6.0 * rng.unit();
        let shift = [rng.unit(), rng.unit(), rng.unit()];
        let (v, f) = posed.into_parts();
        let v = v
            .into_iter()
            .map(|p| {
                let r = rotate(p, axis, angle);
                [r[0] + shift[0], r[1] + shift[1], r[2] + shift[2]]
            })
            .collect();
        Ok(GeneratedShape {
            mesh: TriMesh::new(v, f)?,
            rest: rest.vertices().to_vec(),
        })
    }

    /// Shape `pose` (0 rest, 1 walking, 2 crouching, 3 reaching) of
    /// individual `individual` of the generated benchmark collection
    /// (`cargo xtask generate`, `fmaps demo`): the build
    /// `Build::random(1000 + individual)`, the pose preset jittered by
    /// 0.12 and a grid spacing of 0.039-0.047, both from the seed
    /// `4 individual + pose`, which [`Body::shape`] also gets.
    pub fn collection_shape(&self, individual: usize, pose: usize) -> Result<GeneratedShape> {
        let presets = [
            BodyPose::rest,
            BodyPose::walking,
            BodyPose::crouching,
            BodyPose::reaching,
        ];
        let preset = presets.get(pose).ok_or_else(|| {
            crate::Error::Parameter(format!("pose {pose}: the collection has poses 0..=3"))
        })?;
        let seed = (individual * presets.len() + pose) as u64;
        let build = Build::random(1000 + individual as u64);
        let spacing = 0.039 + 0.008 * ((seed * 7919) % 97) as f64 / 96.0;
        self.shape(&build, &preset().jittered(seed, 0.12), spacing, seed)
    }

    /// The points the collection's ground truth is defined on: the
    /// vertices of one more mesh of the template at rest (5,000-odd); a
    /// shape's ground truth is [`nearest_vertices`] of them (or of their
    /// [`mirrored`] images, for the symmetric truth) among its `rest`
    /// positions.
    pub fn truth_points(&self) -> Result<Vec<[f64; 3]>> {
        Ok(self.rest_mesh(0.043, [0.5, 0.5, 0.5])?.vertices().to_vec())
    }

    /// Skinning weights of a rest point: per bone, `exp(-(d_b - d_min) /
    /// skin)` of its distance to the bone's capsules, normalised; weights
    /// below 1e-6 dropped.
    fn weights(&self, x: [f64; 3]) -> [f64; N_BONES] {
        let mut d = [f64::INFINITY; N_BONES];
        for c in &self.capsules {
            d[c.bone] = d[c.bone].min(capsule_distance(c, x));
        }
        let dmin = d.iter().copied().fold(f64::INFINITY, f64::min);
        let mut w = d.map(|db| (-(db - dmin) / self.skin).exp());
        // A bone moves only what lies beyond its joint: points behind the
        // joint (on the parent's side) fade out over `skin` on either side.
        for (wb, b) in w.iter_mut().zip(&self.bones) {
            if b.parent.is_some() {
                let axis = normalized(sub(b.end, b.start));
                let t = dot(sub(x, b.start), axis);
                *wb *= smoothstep((t + self.skin) / (2.0 * self.skin));
            }
        }
        for wb in &mut w {
            if *wb < 1e-6 {
                *wb = 0.0;
            }
        }
        let s: f64 = w.iter().sum();
        w.map(|wb| wb / s)
    }

    /// A rest point moved by a belly of size `belly`: its offset across the
    /// belly capsule's axis scaled by `1 + (belly - 1) w`, where `w` is 1
    /// on the capsule's surface in front of its axis and falls off
    /// smoothly to 0 with the distance beyond that surface (over 0.3),
    /// beyond the capsule's ends (over 0.15) and towards the back. Points
    /// move across the axis only, and their offset stays monotonic in the
    /// distance from it: no fold for bellies up to twice the template's.
    fn bulge(&self, x: [f64; 3], belly: f64) -> [f64; 3] {
        if belly == 1.0 {
            return x;
        }
        let c = &self.capsules[self.belly];
        let ab = sub(c.b, c.a);
        let length = dot(ab, ab).sqrt();
        let t = dot(sub(x, c.a), ab) / (length * length);
        let q = [c.a[0] + t * ab[0], c.a[1] + t * ab[1], c.a[2] + t * ab[2]];
        let d = sub(x, q);
        let r = dot(d, d).sqrt();
        let radius = c.ra + t.clamp(0.0, 1.0) * (c.rb - c.ra);
        let outside = (t.max(1.0) - 1.0 - t.min(0.0)) * length;
        let fall = smoothstep(1.0 - (r - radius).max(0.0) / 0.3) * smoothstep(1.0 - outside / 0.15);
        let front = smoothstep(0.5 + d[2] / radius);
        let s = 1.0 + (belly - 1.0) * fall * front;
        [q[0] + s * d[0], q[1] + s * d[1], q[2] + s * d[2]]
    }

    /// Each bone's affine map `x -> J' + R S (x - J)` for a build and a
    /// pose (forward kinematics: a bone's joint moves with its parent).
    fn bone_maps(&self, build: &Build, pose: &BodyPose) -> Vec<Affine> {
        let mut maps: Vec<Affine> = Vec::with_capacity(self.bones.len());
        for (i, b) in self.bones.iter().enumerate() {
            let local = rotation_matrix(pose.0[i]);
            let (rot, joint) = match b.parent {
                Some(p) => (mat_mul(&maps[p].rot, &local), maps[p].apply(b.start)),
                None => (local, b.start),
            };
            let (along, across) = build.scales(b.part);
            let d = normalized(sub(b.end, b.start));
            let mut s = [[0.0; 3]; 3];
            for r in 0..3 {
                for c in 0..3 {
                    let dd = d[r] * d[c];
                    s[r][c] = along * dd + across * (if r == c { 1.0 } else { 0.0 } - dd);
                }
            }
            maps.push(Affine {
                rot,
                lin: mat_mul(&rot, &s),
                origin: b.start,
                joint,
            });
        }
        maps
    }
}

/// The largest connected component (a coarse grid can cut a thin tip
/// off; the benchmark shapes must be connected).
fn largest_component(mesh: &TriMesh) -> Result<TriMesh> {
    let n = mesh.n_vertices();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for t in mesh.faces() {
        for (a, b) in [(t[0], t[1]), (t[1], t[2])] {
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            if ra != rb {
                parent[ra] = rb;
            }
        }
    }
    let mut size = vec![0usize; n];
    for v in 0..n {
        size[find(&mut parent, v)] += 1;
    }
    let biggest = (0..n).max_by_key(|&r| size[r]).unwrap_or(0);
    if size[biggest] == n {
        return Ok(mesh.clone());
    }
    let mut new_index = vec![usize::MAX; n];
    let mut vertices = Vec::with_capacity(size[biggest]);
    for v in 0..n {
        if find(&mut parent, v) == biggest {
            new_index[v] = vertices.len();
            vertices.push(mesh.vertices()[v]);
        }
    }
    let faces = mesh
        .faces()
        .iter()
        .filter(|t| new_index[t[0]] != usize::MAX)
        .map(|t| t.map(|v| new_index[v]))
        .collect();
    Ok(TriMesh::new(vertices, faces)?)
}

/// For each point, the index of the nearest vertex (for ground truth of
/// generated shapes: template points to a shape's rest positions).
///
/// Exact, with ties to the smallest index: a k-d tree (`kiddo`) bounds the
/// search, and every vertex within that bound (plus a relative margin for
/// the tree's own rounding) is compared with the squared distance computed
/// here, so the answer is the brute-force argmin whatever the tree does.
/// Empty `vertices` give index 0 for every point.
pub fn nearest_vertices(points: &[[f64; 3]], vertices: &[[f64; 3]]) -> Vec<usize> {
    use kiddo::SquaredEuclidean;
    use kiddo::immutable::float::kdtree::ImmutableKdTree;

    if vertices.is_empty() {
        return vec![0; points.len()];
    }
    let squared = |p: [f64; 3], v: [f64; 3]| {
        let d = sub(p, v);
        dot(d, d)
    };
    let tree: ImmutableKdTree<f64, u64, 3, 32> = ImmutableKdTree::new_from_slice(vertices);
    points
        .iter()
        .map(|&p| {
            let first = tree.nearest_one::<SquaredEuclidean>(&p);
            let bound = squared(p, vertices[first.item as usize]);
            let margin = bound * 1e-12 + f64::MIN_POSITIVE;
            let mut best = (f64::INFINITY, usize::MAX);
            for n in tree.within_unsorted::<SquaredEuclidean>(&p, bound + margin) {
                let j = n.item as usize;
                let d2 = squared(p, vertices[j]);
                if d2 < best.0 || (d2 == best.0 && j < best.1) {
                    best = (d2, j);
                }
            }
            // A NaN point finds nothing within a NaN bound; it gets 0, as in
            // a plain scan where no distance compares smaller than infinity.
            if best.1 == usize::MAX { 0 } else { best.1 }
        })
        .collect()
}

/// The left/right mirror image of a template point (x -> -x).
pub fn mirrored(p: [f64; 3]) -> [f64; 3] {
    [-p[0], p[1], p[2]]
}

mod geometry;
pub mod species;

#[cfg(test)]
mod tests;
