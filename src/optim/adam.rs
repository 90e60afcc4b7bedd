//! Adam over the parameter groups of a [`Gaussians`] set, as `torch.optim.Adam` computes it
//! (3DGS `training_setup`: `Adam(groups, lr=0.0, eps=1e-15)`, betas (0.9, 0.999)).
//!
//! Per element, with the group's step count t (1-based after the increment):
//! ```text
//! m <- b1 m + (1 - b1) g,   v <- b2 v + (1 - b2) g^2
//! p <- p - (lr / (1 - b1^t)) m / (sqrt(v) / sqrt(1 - b2^t) + eps)
//! ```
//! which is torch's single-tensor (non-capturable) update. The bias corrections are computed in
//! f64 and rounded to the parameter precision once per step.
//!
//! Six groups, as 3DGS: `xyz` (means), `f_dc` (feature 0), `f_rest` (features 1..15),
//! `opacity`, `scaling`, `rotation`. Each group has its own step count because upstream skips
//! a group's step when its tensor was just replaced (densification replaces all of them, the
//! opacity reset only the opacity); torch keeps `state['step']` across those replacements.
//! Moments are stored as two more [`Gaussians`] of the same length as the parameters;
//! [`crate::densify`] keeps them aligned with every clone, split and prune.

use rayon::prelude::*;

use crate::gaussians::model::N_FEATURES;
use crate::gaussians::Gaussians;
use crate::par::CHUNK;
use crate::real::Real;
use crate::simd::Simd;

/// Number of parameter groups.
pub const N_GROUPS: usize = 6;

/// A parameter group (3DGS names).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Group {
    Xyz = 0,
    FDc = 1,
    FRest = 2,
    Opacity = 3,
    Scaling = 4,
    Rotation = 5,
}

/// Adam constants.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdamConfig {
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
}

impl Default for AdamConfig {
    fn default() -> Self {
        AdamConfig {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        }
    }
}

/// Learning rate of each group, indexed by [`Group`].
pub type GroupLr = [f64; N_GROUPS];

/// Adam state: first and second moments and a step count per group.
#[derive(Clone, Debug, PartialEq)]
pub struct Adam<R: Real> {
    pub cfg: AdamConfig,
    pub m: Gaussians<R>,
    pub v: Gaussians<R>,
    pub steps: [u64; N_GROUPS],
}

/// Precomputed per-group constants of one step.
#[derive(Clone, Copy)]
struct Consts<R: Real> {
    on: bool,
    b1: R,
    b2: R,
    omb1: R,
    omb2: R,
    step_size: R,
    bc2_sqrt: R,
    eps: R,
}

/// The order of the last multiply and divide of an Adam update (the two round differently).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Form {
    /// `p - step_size * (m / denom)`: torch's `param.addcdiv_(exp_avg, denom, value=-step_size)`
    /// (the Gaussians).
    Addcdiv,
    /// `p - (step_size * m) / denom` (the neural fields; their runs and goldens were made with
    /// this order).
    ScaledMoment,
}

impl<R: Real> Consts<R> {
    /// The constants of step `t` (1-based) with learning rate `lr`: the bias corrections in
    /// f64, rounded once.
    fn new(cfg: &AdamConfig, t: u64, lr: f64, on: bool) -> Self {
        let t = t as i32;
        let bc1 = 1.0 - cfg.beta1.powi(t);
        let bc2 = 1.0 - cfg.beta2.powi(t);
        Consts {
            on,
            b1: R::c(cfg.beta1),
            b2: R::c(cfg.beta2),
            omb1: R::c(1.0 - cfg.beta1),
            omb2: R::c(1.0 - cfg.beta2),
            step_size: R::c(lr / bc1),
            bc2_sqrt: R::c(bc2.sqrt()),
            eps: R::c(cfg.eps),
        }
    }
}

/// The update of one element ([`Form::ScaledMoment`] when `SCALED`, else [`Form::Addcdiv`]).
#[inline(always)]
fn upd<R: Real, const SCALED: bool>(c: &Consts<R>, p: &mut R, m: &mut R, v: &mut R, g: R) {
    *m = c.b1 * *m + c.omb1 * g;
    *v = c.b2 * *v + c.omb2 * g * g;
    let denom = v.sqrt() / c.bc2_sqrt + c.eps;
    if SCALED {
        *p -= c.step_size * *m / denom;
    } else {
        *p -= c.step_size * (*m / denom);
    }
}

/// Adam update of elements `range` of every row of a chunk of an array-valued group.
#[inline(always)]
fn rows_kernel<R: Real, const N: usize>(
    c: &Consts<R>,
    pc: &mut [[R; N]],
    mc: &mut [[R; N]],
    vc: &mut [[R; N]],
    gc: &[[R; N]],
    range: std::ops::Range<usize>,
) {
    for j in 0..pc.len() {
        for a in range.clone() {
            upd::<R, false>(c, &mut pc[j][a], &mut mc[j][a], &mut vc[j][a], gc[j][a]);
        }
    }
}

/// Adam update of every element of a chunk of a contiguous group (each element independent,
/// so the loop vectorises across elements).
#[inline(always)]
fn flat_kernel<R: Real, const SCALED: bool>(
    c: &Consts<R>,
    pc: &mut [R],
    mc: &mut [R],
    vc: &mut [R],
    gc: &[R],
) {
    for (((p, m), v), &g) in pc.iter_mut().zip(mc.iter_mut()).zip(vc.iter_mut()).zip(gc) {
        upd::<R, SCALED>(c, p, m, v, g);
    }
}

/// Per-element constants of a row whose elements belong to different groups (lane `a` of each
/// array: the constants of element `a`'s group). One array per constant, so that the loop over
/// a row's elements vectorises (over an array of [`Consts`] the compiler left part of it scalar).
#[derive(Clone, Copy)]
struct RowConsts<R: Real, const N: usize> {
    b1: [R; N],
    b2: [R; N],
    omb1: [R; N],
    omb2: [R; N],
    step_size: [R; N],
    bc2_sqrt: [R; N],
    eps: [R; N],
}

impl<R: Real, const N: usize> RowConsts<R, N> {
    /// Element `a` takes the constants `of(a)`.
    fn new(of: impl Fn(usize) -> Consts<R>) -> Self {
        let c: [Consts<R>; N] = std::array::from_fn(of);
        RowConsts {
            b1: c.map(|c| c.b1),
            b2: c.map(|c| c.b2),
            omb1: c.map(|c| c.omb1),
            omb2: c.map(|c| c.omb2),
            step_size: c.map(|c| c.step_size),
            bc2_sqrt: c.map(|c| c.bc2_sqrt),
            eps: c.map(|c| c.eps),
        }
    }

    /// The constants of element `a`.
    #[inline(always)]
    fn lane(&self, a: usize) -> Consts<R> {
        Consts {
            on: true,
            b1: self.b1[a],
            b2: self.b2[a],
            omb1: self.omb1[a],
            omb2: self.omb2[a],
            step_size: self.step_size[a],
            bc2_sqrt: self.bc2_sqrt[a],
            eps: self.eps[a],
        }
    }
}

/// Adam update of every element of every row of a chunk, each element with the constants of
/// its group ([`RowConsts`]), in one pass over the rows (the loop over a row's elements
/// vectorises).
#[inline(always)]
fn mixed_rows_kernel<R: Real, const N: usize>(
    c: &RowConsts<R, N>,
    pc: &mut [[R; N]],
    mc: &mut [[R; N]],
    vc: &mut [[R; N]],
    gc: &[[R; N]],
) {
    for (((p, m), v), g) in pc.iter_mut().zip(mc.iter_mut()).zip(vc.iter_mut()).zip(gc) {
        for a in 0..N {
            upd::<R, false>(&c.lane(a), &mut p[a], &mut m[a], &mut v[a], g[a]);
        }
    }
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real, const N: usize](
        c: &RowConsts<R, N>,
        pc: &mut [[R; N]],
        mc: &mut [[R; N]],
        vc: &mut [[R; N]],
        gc: &[[R; N]],
    );
    mixed_rows_kernel_avx2 => { mixed_rows_kernel(c, pc, mc, vc, gc) }
    mixed_rows_kernel_avx512 => { mixed_rows_kernel(c, pc, mc, vc, gc) }
}

/// Adam update of every element of an array-valued group whose elements 0..`split` belong to
/// group `lo` and the rest to group `hi`, both on, in one pass with the instruction set `simd`
/// (supported). The same bits as two [`group_step`]s.
#[allow(clippy::too_many_arguments)]
fn split_step<R: Real, const N: usize>(
    simd: Simd,
    lo: &Consts<R>,
    hi: &Consts<R>,
    split: usize,
    p: &mut [[R; N]],
    m: &mut [[R; N]],
    v: &mut [[R; N]],
    g: &[[R; N]],
) {
    let c = RowConsts::<R, N>::new(|a| if a < split { *lo } else { *hi });
    par_chunks4(p, m, v, g, |pc, mc, vc, gc| match simd {
        // SAFETY: the caller passes a supported instruction set.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512 => unsafe { mixed_rows_kernel_avx512(&c, pc, mc, vc, gc) },
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => unsafe { mixed_rows_kernel_avx2(&c, pc, mc, vc, gc) },
        _ => mixed_rows_kernel(&c, pc, mc, vc, gc),
    });
}

/// `f` on the matching `CHUNK`-element chunks of the parameters, moments and gradients, in
/// parallel (each element is independent: the same bits for any thread count).
fn par_chunks4<T: Send + Sync>(
    p: &mut [T],
    m: &mut [T],
    v: &mut [T],
    g: &[T],
    f: impl Fn(&mut [T], &mut [T], &mut [T], &[T]) + Sync + Send,
) {
    p.par_chunks_mut(CHUNK)
        .zip(m.par_chunks_mut(CHUNK))
        .zip(v.par_chunks_mut(CHUNK))
        .zip(g.par_chunks(CHUNK))
        .for_each(|(((pc, mc), vc), gc)| f(pc, mc, vc, gc));
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real, const N: usize](
        c: &Consts<R>,
        pc: &mut [[R; N]],
        mc: &mut [[R; N]],
        vc: &mut [[R; N]],
        gc: &[[R; N]],
        range: std::ops::Range<usize>,
    );
    rows_kernel_avx2 => { rows_kernel(c, pc, mc, vc, gc, range) }
    rows_kernel_avx512 => { rows_kernel(c, pc, mc, vc, gc, range) }
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real, const SCALED: bool](
        c: &Consts<R>,
        pc: &mut [R],
        mc: &mut [R],
        vc: &mut [R],
        gc: &[R],
    );
    flat_kernel_avx2 => { flat_kernel::<R, SCALED>(c, pc, mc, vc, gc) }
    flat_kernel_avx512 => { flat_kernel::<R, SCALED>(c, pc, mc, vc, gc) }
}

/// Adam update of elements `range` of every row of one array-valued group, with the
/// instruction set `simd` (supported; every path gives the same bits: each element does the
/// same operations). A group updated whole runs as one flat array.
fn group_step<R: Real, const N: usize>(
    simd: Simd,
    c: &Consts<R>,
    p: &mut [[R; N]],
    m: &mut [[R; N]],
    v: &mut [[R; N]],
    g: &[[R; N]],
    range: std::ops::Range<usize>,
) {
    if !c.on {
        return;
    }
    if range == (0..N) {
        return flat_step(
            simd,
            Form::Addcdiv,
            c,
            p.as_flattened_mut(),
            m.as_flattened_mut(),
            v.as_flattened_mut(),
            g.as_flattened(),
        );
    }
    par_chunks4(p, m, v, g, |pc, mc, vc, gc| {
        let r = range.clone();
        match simd {
            // SAFETY: the caller passes a supported instruction set.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { rows_kernel_avx512(c, pc, mc, vc, gc, r) },
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { rows_kernel_avx2(c, pc, mc, vc, gc, r) },
            _ => rows_kernel(c, pc, mc, vc, gc, r),
        }
    });
}

/// Adam update of every element of a flat group with the instruction set `simd` (supported)
/// in the order `form`.
fn flat_step<R: Real>(
    simd: Simd,
    form: Form,
    c: &Consts<R>,
    p: &mut [R],
    m: &mut [R],
    v: &mut [R],
    g: &[R],
) {
    match form {
        Form::Addcdiv => flat_step_as::<R, false>(simd, c, p, m, v, g),
        Form::ScaledMoment => flat_step_as::<R, true>(simd, c, p, m, v, g),
    }
}

/// [`flat_step`] in the order `SCALED` ([`upd`]).
fn flat_step_as<R: Real, const SCALED: bool>(
    simd: Simd,
    c: &Consts<R>,
    p: &mut [R],
    m: &mut [R],
    v: &mut [R],
    g: &[R],
) {
    if !c.on {
        return;
    }
    par_chunks4(p, m, v, g, |pc, mc, vc, gc| match simd {
        // SAFETY: the caller passes a supported instruction set.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512 => unsafe { flat_kernel_avx512::<R, SCALED>(c, pc, mc, vc, gc) },
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => unsafe { flat_kernel_avx2::<R, SCALED>(c, pc, mc, vc, gc) },
        _ => flat_kernel::<R, SCALED>(c, pc, mc, vc, gc),
    });
}

/// Adam over one flat parameter vector with a single step count, as `torch.optim.Adam`
/// (single-tensor, non-capturable, no weight decay) over one tensor: the same kernel as
/// [`Adam`] in the order [`Form::ScaledMoment`]. The neural fields' optimiser (PyTorch defaults:
/// betas (0.9, 0.999), eps 1e-8).
#[derive(Clone, Debug, PartialEq)]
pub struct FlatAdam<R: Real> {
    pub cfg: AdamConfig,
    pub m: Vec<R>,
    pub v: Vec<R>,
    pub step: u64,
}

impl<R: Real> FlatAdam<R> {
    /// Zero moments for `n` parameters, PyTorch's defaults.
    pub fn new(n: usize) -> Self {
        FlatAdam {
            cfg: AdamConfig {
                beta1: 0.9,
                beta2: 0.999,
                eps: 1e-8,
            },
            m: vec![R::zero(); n],
            v: vec![R::zero(); n],
            step: 0,
        }
    }

    /// One step with learning rate `lr` on the widest supported instruction set (every path
    /// gives the same bits: each element does the same operations; parallel over fixed chunks,
    /// so the same bits for any thread count).
    pub fn update(&mut self, p: &mut [R], g: &[R], lr: f64) {
        assert!(
            g.len() == p.len() && self.m.len() == p.len() && self.v.len() == p.len(),
            "FlatAdam: parameter, gradient and moment lengths differ"
        );
        self.step += 1;
        let c = Consts::new(&self.cfg, self.step, lr, true);
        let simd = Simd::active().or_narrower();
        flat_step(simd, Form::ScaledMoment, &c, p, &mut self.m, &mut self.v, g);
    }
}

impl<R: Real> Adam<R> {
    /// Zero moments for `n` parameters.
    pub fn new(cfg: AdamConfig, n: usize) -> Self {
        Adam {
            cfg,
            m: Gaussians::zeros(n),
            v: Gaussians::zeros(n),
            steps: [0; N_GROUPS],
        }
    }

    fn consts(&self, g: usize, lr: f64, on: bool) -> Consts<R> {
        Consts::new(&self.cfg, self.steps[g] + 1, lr, on)
    }

    /// One Adam step of the groups with `active[g] == true`, learning rates `lr`.
    /// Parallel over fixed chunks of Gaussians; each element is independent, so the result is
    /// bit-identical for any thread count and on every SIMD path ([`Simd::active`]).
    pub fn step(
        &mut self,
        p: &mut Gaussians<R>,
        grad: &Gaussians<R>,
        lr: &GroupLr,
        active: &[bool; N_GROUPS],
    ) {
        self.step_with(Simd::active(), p, grad, lr, active)
    }

    /// [`Adam::step`] with the instruction set `simd` (or the widest supported narrower one).
    pub fn step_with(
        &mut self,
        simd: Simd,
        p: &mut Gaussians<R>,
        grad: &Gaussians<R>,
        lr: &GroupLr,
        active: &[bool; N_GROUPS],
    ) {
        let simd = simd.or_narrower();
        let n = p.len();
        assert!(
            grad.len() == n && self.m.len() == n && self.v.len() == n,
            "Adam: parameter, gradient and moment lengths differ"
        );
        let k: [Consts<R>; N_GROUPS] = std::array::from_fn(|g| self.consts(g, lr[g], active[g]));
        let (m, v) = (&mut self.m, &mut self.v);
        let kx = &k[Group::Xyz as usize];
        group_step(
            simd,
            kx,
            &mut p.means,
            &mut m.means,
            &mut v.means,
            &grad.means,
            0..3,
        );
        let ks = &k[Group::Scaling as usize];
        let (ps, ms, vs) = (&mut p.log_scales, &mut m.log_scales, &mut v.log_scales);
        group_step(simd, ks, ps, ms, vs, &grad.log_scales, 0..3);
        let kr = &k[Group::Rotation as usize];
        group_step(
            simd,
            kr,
            &mut p.quats,
            &mut m.quats,
            &mut v.quats,
            &grad.quats,
            0..4,
        );
        let ko = &k[Group::Opacity as usize];
        let (po, mo, vo) = (
            &mut p.opacity_logits,
            &mut m.opacity_logits,
            &mut v.opacity_logits,
        );
        flat_step(simd, Form::Addcdiv, ko, po, mo, vo, &grad.opacity_logits);
        let kd = &k[Group::FDc as usize];
        let (pf, mf, vf) = (&mut p.features, &mut m.features, &mut v.features);
        let kf = &k[Group::FRest as usize];
        if kd.on && kf.on {
            // One pass over the feature rows instead of one per group.
            split_step(simd, kd, kf, 1, pf, mf, vf, &grad.features);
        } else {
            group_step(simd, kd, pf, mf, vf, &grad.features, 0..1);
            group_step(simd, kf, pf, mf, vf, &grad.features, 1..N_FEATURES);
        }
        for (steps, &on) in self.steps.iter_mut().zip(active) {
            if on {
                *steps += 1;
            }
        }
    }

    /// Zero the opacity moments (3DGS `reset_opacity` -> `replace_tensor_to_optimizer`).
    pub fn zero_opacity_moments(&mut self) {
        self.m
            .opacity_logits
            .iter_mut()
            .for_each(|x| *x = R::zero());
        self.v
            .opacity_logits
            .iter_mut()
            .for_each(|x| *x = R::zero());
    }
}
