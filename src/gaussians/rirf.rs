//! Eq. (2): radiative intensity response function (RIRF), and the view-dependent SH colour of
//! the 3DGS baseline.
//!
//! - Paper: i = Sigmoid(sum_k lambda_k f_k) ([`rirf_paper`]).
//! - X-Gaussian code: i = max(0, 0.5 + sum_k lambda_k f_k) ([`rirf_xgaussian`]); the gradient
//!   is zero where the value is clamped (v < 0), as in 3DGS's `computeColorFromSH`.
//! - SH (3DGS / UniSpine code at HEAD): i = max(0, 0.5 + sum_k Y_k(d) f_k) with d the unit
//!   direction from the camera centre to the mean ([`sh_basis`], [`sh_basis_vjp`]).
//!
//! lambda = the 16 real-SH normalisation constants with the signs of 3DGS's SH evaluation and
//! the direction terms dropped: (C0, -C1, C1, -C1, C2[0..5], C3[0..7]). The constants are the
//! full-precision values of 3DGS `cuda_rasterizer/auxiliary.h` (a test checks the 8-digit
//! values of X-Gaussian's copy).
//! Only the first `active` features (1, 4, 9 or 16: SH degree 0..3, progressive enabling)
//! take part; the others get zero gradient.

#![allow(clippy::needless_range_loop)] // small fixed-size matrix loops read best indexed

use serde::{Deserialize, Serialize};

use crate::gaussians::model::N_FEATURES;
use crate::real::Real;

crate::choice! {
/// How a Gaussian's intensity is computed from its 16 features.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ColorMode {
    /// The paper's Eq. (2): i = Sigmoid(sum_k lambda_k f_k).
    #[default]
    RirfPaper = "rirf-paper",
    /// X-Gaussian's code: i = max(0, 0.5 + sum_k lambda_k f_k).
    RirfXgaussian = "rirf-xgaussian",
    /// View-dependent SH colour (3DGS baseline): i = max(0, 0.5 + SH(dir) . f), dir from the
    /// camera centre to the mean.
    Sh = "sh",
}
}

/// Real SH constant of degree 0, 1 / (2 sqrt(pi)).
pub const SH_C0: f64 = 0.282_094_791_773_878_14;
/// Real SH constant of degree 1, sqrt(3) / (2 sqrt(pi)).
pub const SH_C1: f64 = 0.488_602_511_902_919_9;
/// Degree-2 constants (3DGS order and signs).
pub const SH_C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
/// Degree-3 constants (3DGS order and signs).
pub const SH_C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// Eq. (2) lambda: the 16 signed SH constants (X-Gaussian `computeColorFromSH` with the
/// direction terms removed).
pub const LAMBDA: [f64; N_FEATURES] = [
    SH_C0, -SH_C1, SH_C1, -SH_C1, SH_C2[0], SH_C2[1], SH_C2[2], SH_C2[3], SH_C2[4], SH_C3[0],
    SH_C3[1], SH_C3[2], SH_C3[3], SH_C3[4], SH_C3[5], SH_C3[6],
];

/// True for the allowed numbers of active features: 1, 4, 9, 16.
pub fn valid_active(active: usize) -> bool {
    matches!(active, 1 | 4 | 9 | 16)
}

/// sum_{k < active} lambda_k f_k.
#[inline(always)]
pub fn rirf_sum<R: Real>(f: &[R; N_FEATURES], active: usize) -> R {
    let mut s = R::zero();
    for k in 0..active {
        s += R::c(LAMBDA[k]) * f[k];
    }
    s
}

/// Eq. (2), paper form: i = sigmoid(sum_k lambda_k f_k).
#[inline(always)]
pub fn rirf_paper<R: Real>(f: &[R; N_FEATURES], active: usize) -> R {
    crate::math::activations::sigmoid(rirf_sum(f, active))
}

/// VJP of [`rirf_paper`]: d i -> d f (zero for inactive features). `i` is the forward output.
#[inline(always)]
pub fn rirf_paper_vjp<R: Real>(i: R, active: usize, gi: R) -> [R; N_FEATURES] {
    let gs = gi * crate::math::activations::sigmoid_grad_from_output(i);
    let mut g = [R::zero(); N_FEATURES];
    for k in 0..active {
        g[k] = gs * R::c(LAMBDA[k]);
    }
    g
}

/// Eq. (2), X-Gaussian code form: i = max(0, 0.5 + sum_k lambda_k f_k).
#[inline(always)]
pub fn rirf_xgaussian<R: Real>(f: &[R; N_FEATURES], active: usize) -> R {
    (R::c(0.5) + rirf_sum(f, active)).max(R::zero())
}

/// VJP of [`rirf_xgaussian`]: zero where 0.5 + sum < 0 (clamped), else lambda_k gi.
#[inline(always)]
pub fn rirf_xgaussian_vjp<R: Real>(f: &[R; N_FEATURES], active: usize, gi: R) -> [R; N_FEATURES] {
    let mut g = [R::zero(); N_FEATURES];
    if R::c(0.5) + rirf_sum(f, active) >= R::zero() {
        for k in 0..active {
            g[k] = gi * R::c(LAMBDA[k]);
        }
    }
    g
}

/// Real SH basis Y_k(d) of 3DGS (`computeColorFromSH`, signs included) for a unit direction d.
#[inline(always)]
pub fn sh_basis<R: Real>(d: [R; 3]) -> [R; N_FEATURES] {
    let [x, y, z] = d;
    let c = |v: f64| R::c(v);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, xz) = (x * y, y * z, x * z);
    let two = c(2.0);
    let three = c(3.0);
    let four = c(4.0);
    [
        c(SH_C0),
        -c(SH_C1) * y,
        c(SH_C1) * z,
        -c(SH_C1) * x,
        c(SH_C2[0]) * xy,
        c(SH_C2[1]) * yz,
        c(SH_C2[2]) * (two * zz - xx - yy),
        c(SH_C2[3]) * xz,
        c(SH_C2[4]) * (xx - yy),
        c(SH_C3[0]) * y * (three * xx - yy),
        c(SH_C3[1]) * xy * z,
        c(SH_C3[2]) * y * (four * zz - xx - yy),
        c(SH_C3[3]) * z * (two * zz - three * xx - three * yy),
        c(SH_C3[4]) * x * (four * zz - xx - yy),
        c(SH_C3[5]) * z * (xx - yy),
        c(SH_C3[6]) * x * (xx - three * yy),
    ]
}

/// sum_{k < active} g_k * grad Y_k(d): the VJP of [`sh_basis`] with respect to d (treating the
/// three components as independent; the projection onto the sphere is applied by the caller).
#[inline(always)]
pub fn sh_basis_vjp<R: Real>(d: [R; 3], active: usize, g: &[R; N_FEATURES]) -> [R; 3] {
    let [x, y, z] = d;
    let c = |v: f64| R::c(v);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, xz) = (x * y, y * z, x * z);
    let (two, three, four, six, eight) = (c(2.0), c(3.0), c(4.0), c(6.0), c(8.0));
    let zero = R::zero();
    // Gradients of each basis function (d/dx, d/dy, d/dz).
    let grads: [[R; 3]; N_FEATURES] = [
        [zero, zero, zero],
        [zero, -c(SH_C1), zero],
        [zero, zero, c(SH_C1)],
        [-c(SH_C1), zero, zero],
        [c(SH_C2[0]) * y, c(SH_C2[0]) * x, zero],
        [zero, c(SH_C2[1]) * z, c(SH_C2[1]) * y],
        [
            -two * c(SH_C2[2]) * x,
            -two * c(SH_C2[2]) * y,
            four * c(SH_C2[2]) * z,
        ],
        [c(SH_C2[3]) * z, zero, c(SH_C2[3]) * x],
        [two * c(SH_C2[4]) * x, -two * c(SH_C2[4]) * y, zero],
        [
            six * c(SH_C3[0]) * xy,
            c(SH_C3[0]) * (three * xx - three * yy),
            zero,
        ],
        [c(SH_C3[1]) * yz, c(SH_C3[1]) * xz, c(SH_C3[1]) * xy],
        [
            -two * c(SH_C3[2]) * xy,
            c(SH_C3[2]) * (four * zz - xx - three * yy),
            eight * c(SH_C3[2]) * yz,
        ],
        [
            -six * c(SH_C3[3]) * xz,
            -six * c(SH_C3[3]) * yz,
            c(SH_C3[3]) * (six * zz - three * xx - three * yy),
        ],
        [
            c(SH_C3[4]) * (four * zz - three * xx - yy),
            -two * c(SH_C3[4]) * xy,
            eight * c(SH_C3[4]) * xz,
        ],
        [
            two * c(SH_C3[5]) * xz,
            -two * c(SH_C3[5]) * yz,
            c(SH_C3[5]) * (xx - yy),
        ],
        [
            c(SH_C3[6]) * (three * xx - three * yy),
            -six * c(SH_C3[6]) * xy,
            zero,
        ],
    ];
    let mut out = [zero; 3];
    for k in 0..active {
        for a in 0..3 {
            out[a] += g[k] * grads[k][a];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fd;

    #[test]
    fn color_mode_names_are_the_serde_names() {
        for c in [
            ColorMode::RirfPaper,
            ColorMode::RirfXgaussian,
            ColorMode::Sh,
        ] {
            assert_eq!(serde_json::to_value(c).unwrap(), c.name());
        }
    }

    fn feats(seed: u64) -> [f64; N_FEATURES] {
        let mut s = seed;
        std::array::from_fn(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.8
        })
    }

    #[test]
    fn lambda_matches_xgaussian_constants() {
        // X-Gaussian `cuda_rasterizer/auxiliary.h` (caiyuanhao1998/X-Gaussian), to 8 digits.
        let want = [
            0.28209479,
            -0.48860251,
            0.48860251,
            -0.48860251,
            1.09254843,
            -1.09254843,
            0.31539157,
            -1.09254843,
            0.54627422,
            -0.59004359,
            2.89061144,
            -0.45704580,
            0.37317633,
            -0.45704580,
            1.44530572,
            -0.59004359,
        ];
        for k in 0..16 {
            assert!((LAMBDA[k] - want[k]).abs() < 6e-9, "{k}");
        }
        assert!((SH_C0 - 0.5 / std::f64::consts::PI.sqrt()).abs() < 1e-16);
        assert!((SH_C1 - 3f64.sqrt() * SH_C0).abs() < 1e-15);
    }

    #[test]
    fn rirf_vjps_match_fd_and_inactive_features_get_zero() {
        for active in [1, 4, 9, 16] {
            let f = feats(active as u64);
            let gi = 0.7;
            let num = fd::central_diff5(
                |v| gi * rirf_paper(&std::array::from_fn(|k| v[k]), active),
                &f,
                1e-3,
            );
            let an = rirf_paper_vjp(rirf_paper(&f, active), active, gi);
            assert!(fd::rel_err_maxabs(&an, &num) < 1e-9);
            assert!(an[active..].iter().all(|&x| x == 0.0));
            let num = fd::central_diff5(
                |v| gi * rirf_xgaussian(&std::array::from_fn(|k| v[k]), active),
                &f,
                1e-3,
            );
            let an = rirf_xgaussian_vjp(&f, active, gi);
            assert!(fd::rel_err_maxabs(&an, &num) < 1e-9);
        }
        // Clamped: value 0, zero gradient.
        let mut f = [0.0; N_FEATURES];
        f[0] = -5.0;
        assert_eq!(rirf_xgaussian(&f, 1), 0.0);
        assert!(rirf_xgaussian_vjp(&f, 16, 1.0).iter().all(|&x| x == 0.0));
    }

    #[test]
    fn sh_basis_vjp_matches_fd() {
        let d = [0.3, -0.5, 0.8];
        let g = feats(99);
        for active in [1, 4, 9, 16] {
            let num = fd::central_diff5(
                |v| {
                    let b = sh_basis([v[0], v[1], v[2]]);
                    (0..active).map(|k| b[k] * g[k]).sum()
                },
                &d,
                1e-3,
            );
            let an = sh_basis_vjp(d, active, &g);
            assert!(
                fd::rel_err_maxabs(&an, &num) < 1e-9,
                "{active} {an:?} {num:?}"
            );
        }
        // Degree 0 is isotropic, degree 1 at +z is C1 in slot 2.
        let b = sh_basis([0.0, 0.0, 1.0f64]);
        assert_eq!(b[0], SH_C0);
        assert_eq!(b[2], SH_C1);
    }
}
