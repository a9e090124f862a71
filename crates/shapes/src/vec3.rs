//! Small 3-vector helpers of the generated shapes (`creature`,
//! `body`, `isosurface`).

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn normalized(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    [a[0] / n, a[1] / n, a[2] / n]
}

pub(crate) fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Rodrigues' rotation of `p` about the unit `axis` by `angle`.
pub(crate) fn rotate(p: [f64; 3], axis: [f64; 3], angle: f64) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    let kxp = cross(axis, p);
    let kp = dot(axis, p);
    [
        p[0] * c + kxp[0] * s + axis[0] * kp * (1.0 - c),
        p[1] * c + kxp[1] * s + axis[1] * kp * (1.0 - c),
        p[2] * c + kxp[2] * s + axis[2] * kp * (1.0 - c),
    ]
}
