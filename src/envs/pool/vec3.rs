//! Small fixed-size 3-vector helpers used by every other module of the pool engine.
//!
//! The operations are written to reproduce numpy's evaluation order where pooltool 0.6.0
//! relies on it (`ptmath.coordinate_rotation`, `ptmath.angle`, `norm3d`), so results stay
//! within a few ulps of the reference (docs/envs/pool.md §P9).

/// A 3-vector `[x, y, z]` in the table frame (SI units).
pub type V3 = [f64; 3];

#[inline]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
#[inline]
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
pub fn scale(a: V3, k: f64) -> V3 {
    [a[0] * k, a[1] * k, a[2] * k]
}
#[inline]
pub fn neg(a: V3) -> V3 {
    [-a[0], -a[1], -a[2]]
}
#[inline]
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline]
pub fn norm2(a: V3) -> f64 {
    a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
}
#[inline]
pub fn norm(a: V3) -> f64 {
    norm2(a).sqrt()
}
/// `a / |a|` (NaN for the zero vector, like pooltool's `unit_vector`).
#[inline]
pub fn unit(a: V3) -> V3 {
    let n = norm(a);
    [a[0] / n, a[1] / n, a[2] / n]
}
/// Rotation about +z by `phi` radians (pooltool `ptmath.coordinate_rotation`).
#[inline]
pub fn rotate_z(v: V3, phi: f64) -> V3 {
    let (s, c) = phi.sin_cos();
    rotate_z_cs(v, c, s)
}
/// Rotation about +z given `cos(phi)`, `sin(phi)`.
#[inline]
pub fn rotate_z_cs(v: V3, c: f64, s: f64) -> V3 {
    [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]]
}
/// Planar heading of `v` in `[0, 2π)` (pooltool `ptmath.angle`).
#[inline]
pub fn angle(v: V3) -> f64 {
    let a = v[1].atan2(v[0]);
    if a < 0.0 {
        2.0 * std::f64::consts::PI + a
    } else {
        a
    }
}
#[inline]
pub fn is_finite(v: V3) -> bool {
    v.iter().all(|x| x.is_finite())
}
