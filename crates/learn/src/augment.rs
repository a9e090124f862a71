//! Augmentation of coordinate inputs while training: a random rotation
//! and scale per shape and step (DiffusionNet's usual augmentation of xyz
//! inputs), drawn from the training's generator.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::network::SplitMix;

/// Random rotations and scales of coordinate inputs, one per shape and
/// step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Augment {
    /// Which rotations.
    pub rotation: Rotation,
    /// The scale is uniform in `[scale[0], scale[1]]`.
    pub scale: [f64; 2],
}

/// Rotations of [`Augment`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Rotation {
    /// None.
    None,
    /// About the y axis (the up axis of FAUST, SCAPE and most scans).
    Y,
    /// Uniform over all rotations (a random unit quaternion).
    Any,
}

impl Default for Augment {
    /// Any rotation, scales in [0.9, 1.1].
    fn default() -> Self {
        Augment {
            rotation: Rotation::Any,
            scale: [0.9, 1.1],
        }
    }
}

impl Augment {
    /// `x` (n x 3) rotated and scaled by a draw from `rng`.
    pub fn apply(&self, x: &DMatrix<f64>, rng: &mut SplitMix) -> DMatrix<f64> {
        let r = match self.rotation {
            Rotation::None => nalgebra::Matrix3::identity(),
            Rotation::Y => {
                let a = std::f64::consts::PI * rng.symmetric();
                let (s, c) = a.sin_cos();
                nalgebra::Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
            }
            Rotation::Any => {
                // A normalised 4D Gaussian is a uniform unit quaternion.
                let mut g = || {
                    let (u, v) = (rng.unit_open(), rng.unit());
                    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
                };
                let q = nalgebra::Quaternion::new(g(), g(), g(), g());
                *nalgebra::UnitQuaternion::from_quaternion(q)
                    .to_rotation_matrix()
                    .matrix()
            }
        };
        let s = self.scale[0] + (self.scale[1] - self.scale[0]) * rng.unit();
        let rt = DMatrix::from_fn(3, 3, |i, j| s * r[(j, i)]);
        x * rt
    }
}
