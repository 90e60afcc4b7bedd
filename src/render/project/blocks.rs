//! Eqs. (1)-(3) over blocks of Gaussians: the loops of the projection's forward and backward,
//! compiled for each instruction set ([`Simd`]) and chosen at run time.
//!
//! A block is [`LANES`] consecutive Gaussians of a chunk. Per block, in three loops:
//! 1. Gaussian by Gaussian, the inputs are copied into one array per component, with the C
//!    library's exponentials of the scales (Eq. 1; the backward reads the forward's);
//! 2. one loop over the lanes runs the geometry ([`geom_core`], and in the backward
//!    [`backward_geom`]): branch-free, so the compiler vectorises it (the lanes past the
//!    chunk's end hold a zero quaternion and are culled);
//! 3. Gaussian by Gaussian again, the drawn ones get their opacity and intensity (Eq. 2; C
//!    library exponentials, SH directions) or their gradients (from the forward's opacity and
//!    intensity), and the results are written.
//!
//! Every lane calls the per-Gaussian functions with the same inputs, so every path gives the
//! bits of the per-Gaussian code ([`super::project_geom`]);
//! `every_simd_path_projects_alike_and_as_the_per_gaussian_code` forces each path the machine
//! has and compares them with a Gaussian-by-Gaussian loop.

use super::{backward_appearance, backward_geom, geom_core, intensity, CamConsts, ProjectSaved};
use crate::gaussians::model::N_FEATURES;
use crate::gaussians::Gaussians;
use crate::math::activations::sigmoid;
use crate::real::Real;
use crate::render::{RenderSettings, SplatGrads, Splats};
use crate::simd::Simd;

/// Gaussians per block: a vector of f32 lanes with AVX-512.
pub(super) const LANES: usize = 16;

/// A chunk's share of [`crate::render::Splats`] (the forward's output).
pub(super) struct SplatsOut<'a, R: Real> {
    pub mean2d: &'a mut [[R; 2]],
    pub conic: &'a mut [[R; 3]],
    pub depth: &'a mut [R],
    pub radius: &'a mut [u32],
    pub opacity: &'a mut [R],
    pub color: &'a mut [R],
    /// exp(log_scale) of the drawn Gaussians, for the backward ([`ProjectSaved::scale`]).
    pub scale: &'a mut [[R; 3]],
}

/// A chunk's share of the parameter gradients (the backward's output, zero on entry).
pub(super) struct ParamsOut<'a, R: Real> {
    pub means: &'a mut [[R; 3]],
    pub log_scales: &'a mut [[R; 3]],
    pub quats: &'a mut [[R; 4]],
    pub opacity_logits: &'a mut [R],
    pub features: &'a mut [[R; N_FEATURES]],
}

/// One block's geometric inputs, one array per component.
struct BlockIn<R: Real> {
    mean: [[R; LANES]; 3],
    scale: [[R; LANES]; 3],
    quat: [[R; LANES]; 4],
}

impl<R: Real> BlockIn<R> {
    /// Every lane zero: a zero quaternion, culled.
    fn zeros() -> Self {
        let z = [R::zero(); LANES];
        BlockIn {
            mean: [z; 3],
            scale: [z; 3],
            quat: [z; 4],
        }
    }

    /// Lane `l` takes Gaussian `i` of `g`, with its exp(log_scale) `scale` (Eq. 1).
    #[inline(always)]
    fn load(&mut self, l: usize, g: &Gaussians<R>, i: usize, scale: [R; 3]) {
        for a in 0..3 {
            self.mean[a][l] = g.means[i][a];
            self.scale[a][l] = scale[a];
        }
        for a in 0..4 {
            self.quat[a][l] = g.quats[i][a];
        }
    }

    #[inline(always)]
    fn lane(&self, l: usize) -> ([R; 3], [R; 3], [R; 4]) {
        let (m, s, q) = (&self.mean, &self.scale, &self.quat);
        (
            [m[0][l], m[1][l], m[2][l]],
            [s[0][l], s[1][l], s[2][l]],
            [q[0][l], q[1][l], q[2][l], q[3][l]],
        )
    }
}

/// Which pass a chunk runs, with its inputs and outputs.
pub(super) enum Pass<'a, R: Real> {
    /// The forward into the chunk's share of the splats (zero on entry).
    Forward(SplatsOut<'a, R>),
    /// The backward from the splat gradients `d` into the chunk's share of the parameter
    /// gradients (zero on entry).
    Backward {
        splats: &'a Splats<R>,
        saved: &'a ProjectSaved<R>,
        d: &'a SplatGrads<R>,
        out: ParamsOut<'a, R>,
    },
}

/// `pass` over the Gaussians `base..` of one chunk (as many as its outputs hold), with the
/// loops compiled for `simd` (or the widest supported narrower set).
pub(super) fn run_chunk<R: Real>(
    simd: Simd,
    cc: &CamConsts<R>,
    settings: &RenderSettings,
    g: &Gaussians<R>,
    base: usize,
    pass: Pass<'_, R>,
) {
    #[cfg(target_arch = "x86_64")]
    match simd.or_narrower() {
        // SAFETY: `or_narrower` returns a set the CPU supports.
        Simd::Avx512 => return unsafe { run_avx512(cc, settings, g, base, pass) },
        Simd::Avx2 => return unsafe { run_avx2(cc, settings, g, base, pass) },
        Simd::Scalar => {}
    }
    let _ = simd;
    run_any(cc, settings, g, base, pass)
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real](
        cc: &CamConsts<R>,
        settings: &RenderSettings,
        g: &Gaussians<R>,
        base: usize,
        pass: Pass<'_, R>,
    );
    run_avx2 => { run_any(cc, settings, g, base, pass) }
    run_avx512 => { run_any(cc, settings, g, base, pass) }
}

#[inline(always)]
fn run_any<R: Real>(
    cc: &CamConsts<R>,
    settings: &RenderSettings,
    g: &Gaussians<R>,
    base: usize,
    pass: Pass<'_, R>,
) {
    match (pass, cc.parallel) {
        (Pass::Forward(out), true) => forward_blocks::<R, true>(cc, settings, g, base, out),
        (Pass::Forward(out), false) => forward_blocks::<R, false>(cc, settings, g, base, out),
        (
            Pass::Backward {
                splats,
                saved,
                d,
                out,
            },
            true,
        ) => backward_blocks::<R, true>(cc, settings, g, splats, saved, d, base, out),
        (
            Pass::Backward {
                splats,
                saved,
                d,
                out,
            },
            false,
        ) => backward_blocks::<R, false>(cc, settings, g, splats, saved, d, base, out),
    }
}

#[inline(always)]
fn forward_blocks<R: Real, const PARALLEL: bool>(
    cc: &CamConsts<R>,
    settings: &RenderSettings,
    g: &Gaussians<R>,
    base: usize,
    out: SplatsOut<'_, R>,
) {
    let (mode, active) = (settings.color, settings.active_features);
    let n = out.depth.len();
    for k0 in (0..n).step_by(LANES) {
        let m = LANES.min(n - k0);
        let mut inp = BlockIn::<R>::zeros();
        for l in 0..m {
            let i = base + k0 + l;
            let ls = g.log_scales[i];
            inp.load(l, g, i, [ls[0].exp(), ls[1].exp(), ls[2].exp()]);
        }
        // Eqs. (1) and (3), lane by lane (vectorised).
        let z = [R::zero(); LANES];
        let (mut depth, mut mean2d, mut conic) = (z, [z; 2], [z; 3]);
        let mut radius = [0u32; LANES];
        for l in 0..LANES {
            let (mean, scale, quat) = inp.lane(l);
            let (geo, cull) = geom_core::<R, true, PARALLEL>(cc, mean, scale, quat);
            depth[l] = geo.t[2];
            for a in 0..2 {
                mean2d[a][l] = geo.mean2d[a];
            }
            for a in 0..3 {
                conic[a][l] = geo.conic[a];
            }
            // A drawn splat has radius >= 1; a culled one 0.
            radius[l] = if cull.is_none() { geo.radius } else { 0 };
        }
        for l in 0..m {
            let (i, k) = (base + k0 + l, k0 + l);
            out.depth[k] = depth[l];
            if radius[l] == 0 {
                continue;
            }
            out.mean2d[k] = [mean2d[0][l], mean2d[1][l]];
            out.conic[k] = [conic[0][l], conic[1][l], conic[2][l]];
            out.radius[k] = radius[l];
            out.scale[k] = inp.lane(l).1;
            out.opacity[k] = sigmoid(g.opacity_logits[i]);
            out.color[k] = intensity(mode, active, cc.centre, g.means[i], &g.features[i]);
        }
    }
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn backward_blocks<R: Real, const PARALLEL: bool>(
    cc: &CamConsts<R>,
    settings: &RenderSettings,
    g: &Gaussians<R>,
    splats: &Splats<R>,
    saved: &ProjectSaved<R>,
    d: &SplatGrads<R>,
    base: usize,
    out: ParamsOut<'_, R>,
) {
    let zero = R::zero();
    let n = out.means.len();
    for k0 in (0..n).step_by(LANES) {
        let m = LANES.min(n - k0);
        // Only the Gaussians the forward drew have gradients; the other lanes stay culled.
        let mut inp = BlockIn::<R>::zeros();
        let z = [zero; LANES];
        let (mut gm, mut gc) = ([z; 2], [z; 3]);
        for l in 0..m {
            let i = base + k0 + l;
            if splats.radius.get(i).is_none_or(|&r| r == 0) {
                continue;
            }
            inp.load(l, g, i, saved.scale[i]);
            let dm = d.mean2d.get(i).copied().unwrap_or([zero; 2]);
            let dc = d.conic.get(i).copied().unwrap_or([zero; 3]);
            for a in 0..2 {
                gm[a][l] = dm[a];
            }
            for a in 0..3 {
                gc[a][l] = dc[a];
            }
        }
        // Eqs. (1) and (3) up to Sigma2D and their VJP, lane by lane (vectorised).
        let (mut dmu, mut dls, mut dq) = ([z; 3], [z; 3], [z; 4]);
        let mut live = [false; LANES];
        for l in 0..LANES {
            let (mean, scale, quat) = inp.lane(l);
            // Drawn by the forward: its screen-space tests passed on the same inputs.
            let (geo, cull) = geom_core::<R, false, PARALLEL>(cc, mean, scale, quat);
            live[l] = cull.is_none();
            let (m_, s_, q_) = backward_geom::<R, PARALLEL>(
                cc,
                &geo,
                [gm[0][l], gm[1][l]],
                [gc[0][l], gc[1][l], gc[2][l]],
            );
            for a in 0..3 {
                dmu[a][l] = m_[a];
                dls[a][l] = s_[a];
            }
            for a in 0..4 {
                dq[a][l] = q_[a];
            }
        }
        for l in 0..m {
            if !live[l] {
                continue;
            }
            let (i, k) = (base + k0 + l, k0 + l);
            let (dmean, dlogit, dfeat) = backward_appearance(
                cc,
                settings,
                g.means[i],
                &g.features[i],
                splats.opacity[i],
                splats.color[i],
                d.opacity.get(i).copied().unwrap_or(zero),
                d.color.get(i).copied().unwrap_or(zero),
            );
            out.means[k] = [
                dmean[0] + dmu[0][l],
                dmean[1] + dmu[1][l],
                dmean[2] + dmu[2][l],
            ];
            out.log_scales[k] = [dls[0][l], dls[1][l], dls[2][l]];
            out.quats[k] = [dq[0][l], dq[1][l], dq[2][l], dq[3][l]];
            out.opacity_logits[k] = dlogit;
            out.features[k] = dfeat;
        }
    }
}
