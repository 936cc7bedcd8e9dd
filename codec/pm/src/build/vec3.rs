//! The few `f64` 3-vector operations the simplifier and the criteria share.

pub(super) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(super) fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

pub(super) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Angle between two unit vectors (well conditioned); a right angle if either is zero.
pub(super) fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    if norm(a) == 0.0 || norm(b) == 0.0 {
        return std::f64::consts::FRAC_PI_2;
    }
    let d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    norm(cross(a, b)).atan2(d)
}
