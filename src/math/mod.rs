//! Maths shared by forward and backward passes: quaternions, covariances, 2x2 inverses,
//! activations, each with its exact vector-Jacobian product (VJP), plus the central
//! finite-difference helpers every backward pass is checked with ([`fd`]) and inline `floor` /
//! `ceil` ([`round`]).
//!
//! Small fixed-size matrices are plain row-major arrays (`[[R; 3]; 3]`): no allocation, and the
//! same code runs in f32 and f64 through [`crate::real::Real`].

#![allow(clippy::needless_range_loop)] // small fixed-size matrix loops read best indexed

pub mod activations;
pub mod covariance;
pub mod fd;
pub mod inverse2;
pub mod quat;
pub mod round;

use crate::real::Real;

/// 3x3 row-major matrix.
pub type Mat3<R> = [[R; 3]; 3];

/// A * B for 3x3 matrices.
#[inline(always)]
pub fn mat3_mul<R: Real>(a: &Mat3<R>, b: &Mat3<R>) -> Mat3<R> {
    let mut c = [[R::zero(); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    c
}

/// A^T for a 3x3 matrix.
#[inline(always)]
pub fn mat3_t<R: Real>(a: &Mat3<R>) -> Mat3<R> {
    let mut c = [[R::zero(); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[j][i];
        }
    }
    c
}

/// A v for a 3x3 matrix.
#[inline(always)]
pub fn mat3_vec<R: Real>(a: &Mat3<R>, v: [R; 3]) -> [R; 3] {
    [
        a[0][0] * v[0] + a[0][1] * v[1] + a[0][2] * v[2],
        a[1][0] * v[0] + a[1][1] * v[1] + a[1][2] * v[2],
        a[2][0] * v[0] + a[2][1] * v[1] + a[2][2] * v[2],
    ]
}

/// A^T v for a 3x3 matrix.
#[inline(always)]
pub fn mat3_t_vec<R: Real>(a: &Mat3<R>, v: [R; 3]) -> [R; 3] {
    [
        a[0][0] * v[0] + a[1][0] * v[1] + a[2][0] * v[2],
        a[0][1] * v[0] + a[1][1] * v[1] + a[2][1] * v[2],
        a[0][2] * v[0] + a[1][2] * v[1] + a[2][2] * v[2],
    ]
}

/// Cast a 3x3 f64 matrix to `R`.
#[inline(always)]
pub fn mat3_cast<R: Real>(a: &[[f64; 3]; 3]) -> Mat3<R> {
    a.map(|r| r.map(R::c))
}
