//! Arithmetic on 3-vectors as `[f64; 3]`, the coordinates of a
//! [`TriMesh`](crate::TriMesh) vertex: the workspace's one copy, so every
//! crate computes an edge, a normal or an area with the same operations in
//! the same order (and so gets the same bits).

/// `a − b`.
#[inline]
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + b`.
#[inline]
pub fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `s a`.
#[inline]
pub fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// The dot product, summed in coordinate order.
#[inline]
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The cross product `a × b`.
#[inline]
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The Euclidean length.
#[inline]
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// `a` scaled to unit length (NaN for the zero vector).
#[inline]
pub fn normalized(a: [f64; 3]) -> [f64; 3] {
    let n = norm(a);
    [a[0] / n, a[1] / n, a[2] / n]
}

/// Rodrigues' rotation of `p` about the unit `axis` by `angle` (radians,
/// counter-clockwise looking down the axis).
pub fn rotate(p: [f64; 3], axis: [f64; 3], angle: f64) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    let kxp = cross(axis, p);
    let kp = dot(axis, p);
    [
        p[0] * c + kxp[0] * s + axis[0] * kp * (1.0 - c),
        p[1] * c + kxp[1] * s + axis[1] * kp * (1.0 - c),
        p[2] * c + kxp[2] * s + axis[2] * kp * (1.0 - c),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identities_with_exact_answers() {
        let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        assert_eq!(cross(x, y), z);
        assert_eq!(cross(y, x), scale(z, -1.0));
        assert_eq!(dot([1.0, 2.0, 3.0], [4.0, -5.0, 6.0]), 12.0);
        assert_eq!(norm([3.0, 4.0, 12.0]), 13.0);
        assert_eq!(add(sub(x, y), y), x);
        assert_eq!(normalized([0.0, 0.0, 2.5]), z);
        // A quarter turn about z takes x to y (to rounding of cos(π/2)).
        let r = rotate(x, z, std::f64::consts::FRAC_PI_2);
        assert!(norm(sub(r, y)) < 1e-15, "{r:?}");
    }
}
