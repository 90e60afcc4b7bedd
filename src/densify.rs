//! Adaptive density control: statistics, clone, split, prune and opacity reset, exactly as
//! 3DGS / X-Gaussian / UniSpine-GS `gaussian_model.py` (`densify_and_prune`) and `train.py`
//! call them, with the Adam moments kept aligned with every per-Gaussian array.
//!
//! [`TrainState`] owns the parameters, the Adam state and the densification statistics, and
//! changes them only through one index map ([`TrainState::remap`]), so no array can fall out of
//! step with another.
//!
//! Upstream behaviour reproduced (3DGS `graphdeco-inria/gaussian-splatting`
//! `scene/gaussian_model.py` `densify_and_prune`, `train.py`, as X-Gaussian and UniSpine-GS copy
//! them):
//! - statistics while `iteration < densify_until`: for Gaussians visible in the view (radius
//!   > 0), `grad_accum += |dL/dmean2d (NDC)|`, `denom += 1`, `max_radius = max(max_radius, r)`;
//! - at `iteration > densify_from` and `iteration % interval == 0`: grad = accum / denom (0 when
//!   never visible); **clone** (exact copy appended) when grad >= threshold and
//!   max(scale) <= percent_dense * extent; **split** when grad >= threshold and max(scale) >
//!   percent_dense * extent (clones have zero gradient and are never split): 2 samples
//!   mu + R(q) (s (.) z), z ~ N(0, I), appended as all first samples then all second samples
//!   (torch `repeat(2, 1)`), scale s / 1.6, other parameters copied, the original removed;
//!   **prune** opacity < 0.005, and, once `iteration > opacity_reset_interval`, max screen
//!   radius > 20 px or max(scale) > 0.1 extent;
//! - new Gaussians get zero Adam moments; survivors keep theirs; all statistics are zero after
//!   a densification (upstream `densification_postfix` re-creates them).
//! - Upstream's `densification_postfix` also zeroes `max_radii2D` *before* the prune, so its
//!   screen-size test never fires (a known 3DGS quirk). `DensifyConfig::upstream_radii_reset`
//!   (default true) reproduces this; set it false to prune with the radii seen since the last
//!   densification.
//! - Opacity reset: o <- min(o, 0.01) (in logit space) and the opacity moments zeroed.
//! - `max_gaussians` (off by default, not upstream): when clone + split would exceed it, only
//!   the candidates with the largest gradient (ties: lower index) are densified.
//!
//! Split sampling uses `ChaCha8Rng` seeded from (run seed, iteration) and Box-Muller normals,
//! drawn in the order of the appended Gaussians (sample, Gaussian, axis).
//!
//! [`TrainState`]: crate::densify::TrainState
//! [`TrainState::remap`]: crate::densify::TrainState::remap

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::gaussians::Gaussians;
use crate::math::activations::{logit, sigmoid};
use crate::math::quat::{normalize, rotmat_unit};
use crate::optim::{Adam, AdamConfig};
use crate::real::Real;

/// Densification settings (UniSpine-GS `config/example.yaml`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DensifyConfig {
    /// Densify when `iteration > from_iter` (500).
    pub from_iter: usize,
    /// Statistics and densification while `iteration < until_iter` (8000).
    pub until_iter: usize,
    /// Every `interval` iterations (200).
    pub interval: usize,
    /// Threshold on the mean NDC screen-space gradient norm (1.5e-4).
    pub grad_threshold: f64,
    /// Clone / split boundary as a fraction of the scene extent (0.01).
    pub percent_dense: f64,
    /// Prune below this opacity (0.005).
    pub min_opacity: f64,
    /// Prune above this max screen radius in pixels, after the first opacity reset (20).
    pub max_screen_px: f64,
    /// Prune above this world scale as a fraction of the extent, after the first reset (0.1).
    pub max_world_frac: f64,
    /// Opacity reset every this many iterations, while densifying (4000).
    pub opacity_reset_interval: usize,
    /// Opacities above this are set to it at a reset (0.01).
    pub reset_opacity_to: f64,
    /// Split scale divisor (0.8 * 2 = 1.6).
    pub split_scale_div: f64,
    /// Upper bound on the number of Gaussians (none upstream).
    pub max_gaussians: Option<usize>,
    /// Reproduce upstream's reset of the max screen radii before the prune (true).
    pub upstream_radii_reset: bool,
}

impl Default for DensifyConfig {
    fn default() -> Self {
        DensifyConfig {
            from_iter: 500,
            until_iter: 8000,
            interval: 200,
            grad_threshold: 1.5e-4,
            percent_dense: 0.01,
            min_opacity: 0.005,
            max_screen_px: 20.0,
            max_world_frac: 0.1,
            opacity_reset_interval: 4000,
            reset_opacity_to: 0.01,
            split_scale_div: 1.6,
            max_gaussians: None,
            upstream_radii_reset: true,
        }
    }
}

impl DensifyConfig {
    /// Accumulate statistics at this (1-based) iteration.
    pub fn collects(&self, it: usize) -> bool {
        it < self.until_iter
    }
    /// Densify at this iteration.
    pub fn densifies(&self, it: usize) -> bool {
        it < self.until_iter
            && it > self.from_iter
            && self.interval > 0
            && it.is_multiple_of(self.interval)
    }
    /// Reset opacities at this iteration.
    pub fn resets(&self, it: usize) -> bool {
        it < self.until_iter
            && self.opacity_reset_interval > 0
            && it.is_multiple_of(self.opacity_reset_interval)
    }
    /// Apply the screen- and world-size prune at this iteration.
    pub fn prunes_big(&self, it: usize) -> bool {
        it > self.opacity_reset_interval
    }
}

/// Densification statistics, one entry per Gaussian.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    pub grad_accum: Vec<f64>,
    pub denom: Vec<u32>,
    pub max_radius: Vec<u32>,
}

impl Stats {
    fn zeros(n: usize) -> Self {
        Stats {
            grad_accum: vec![0.0; n],
            denom: vec![0; n],
            max_radius: vec![0; n],
        }
    }
}

/// Where an entry of the new arrays comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// An existing Gaussian: parameters, moments and statistics carried over.
    Keep(usize),
    /// A new Gaussian whose parameters start as a copy of this one; zero moments, zero stats.
    New(usize),
}

/// Counts of one densification.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct DensifyReport {
    pub cloned: usize,
    pub split: usize,
    pub pruned: usize,
    pub before: usize,
    pub after: usize,
}

/// Parameters, Adam state and statistics of a run, kept aligned.
#[derive(Clone, Debug)]
pub struct TrainState<R: Real> {
    pub params: Gaussians<R>,
    pub adam: Adam<R>,
    pub stats: Stats,
}

fn gather<T: Copy>(v: &[T], src: &[Source], zero_new: Option<T>) -> Vec<T> {
    src.iter()
        .map(|s| match (*s, zero_new) {
            (Source::Keep(i), _) => v[i],
            (Source::New(_), Some(z)) => z,
            (Source::New(i), None) => v[i],
        })
        .collect()
}

fn gather_g<R: Real>(g: &Gaussians<R>, src: &[Source], zero_new: bool) -> Gaussians<R> {
    let z = R::zero();
    Gaussians {
        means: gather(&g.means, src, zero_new.then_some([z; 3])),
        log_scales: gather(&g.log_scales, src, zero_new.then_some([z; 3])),
        quats: gather(&g.quats, src, zero_new.then_some([z; 4])),
        opacity_logits: gather(&g.opacity_logits, src, zero_new.then_some(z)),
        features: gather(&g.features, src, zero_new.then_some([z; 16])),
    }
}

/// A standard normal from two uniforms (Box-Muller, cosine branch).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

impl<R: Real> TrainState<R> {
    /// A fresh state: zero moments and statistics.
    pub fn new(params: Gaussians<R>, adam: AdamConfig) -> Self {
        let n = params.len();
        TrainState {
            params,
            adam: Adam::new(adam, n),
            stats: Stats::zeros(n),
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.params.len()
    }

    /// True when there is no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// Rebuild every per-Gaussian array from `src` (the only way the set changes size).
    /// New entries copy their source's parameters and get zero moments and statistics.
    pub fn remap(&mut self, src: &[Source]) {
        self.params = gather_g(&self.params, src, false);
        self.adam.m = gather_g(&self.adam.m, src, true);
        self.adam.v = gather_g(&self.adam.v, src, true);
        self.stats = Stats {
            grad_accum: gather(&self.stats.grad_accum, src, Some(0.0)),
            denom: gather(&self.stats.denom, src, Some(0)),
            max_radius: gather(&self.stats.max_radius, src, Some(0)),
        };
    }

    /// Add one view's statistics (3DGS `add_densification_stats` and the `max_radii2D`
    /// update): only Gaussians drawn in the view (radius > 0) count.
    pub fn accumulate(&mut self, ndc_norm: &[R], radius: &[u32]) {
        let s = &mut self.stats;
        for i in 0..ndc_norm.len().min(s.denom.len()) {
            if radius[i] > 0 {
                s.grad_accum[i] += ndc_norm[i].f64();
                s.denom[i] += 1;
                s.max_radius[i] = s.max_radius[i].max(radius[i]);
            }
        }
    }

    fn max_scale(&self, i: usize) -> f64 {
        let l = self.params.log_scales[i];
        l[0].max(l[1]).max(l[2]).f64().exp()
    }

    /// Clone, split and prune (3DGS `densify_and_prune`). `prune_big` enables the screen- and
    /// world-size prune (upstream: after the first opacity-reset interval). `seed` seeds the
    /// split samples.
    pub fn densify_and_prune(
        &mut self,
        cfg: &DensifyConfig,
        extent: f64,
        prune_big: bool,
        seed: u64,
    ) -> DensifyReport {
        let n = self.len();
        let grads: Vec<f64> = (0..n)
            .map(|i| match self.stats.denom[i] {
                0 => 0.0,
                d => self.stats.grad_accum[i] / d as f64,
            })
            .collect();
        let dense = cfg.percent_dense * extent;
        let mut clone_sel: Vec<bool> = (0..n)
            .map(|i| grads[i] >= cfg.grad_threshold && self.max_scale(i) <= dense)
            .collect();
        let mut split_sel: Vec<bool> = (0..n)
            .map(|i| grads[i] >= cfg.grad_threshold && self.max_scale(i) > dense)
            .collect();
        if let Some(max) = cfg.max_gaussians {
            let allowed = max.saturating_sub(n);
            let mut cand: Vec<usize> = (0..n).filter(|&i| clone_sel[i] || split_sel[i]).collect();
            if cand.len() > allowed {
                cand.sort_by(|&a, &b| grads[b].total_cmp(&grads[a]).then(a.cmp(&b)));
                for &i in &cand[allowed..] {
                    clone_sel[i] = false;
                    split_sel[i] = false;
                }
            }
        }
        // Radii seen since the last densification, carried along for the non-upstream prune.
        let mut radii = self.stats.max_radius.clone();

        // Clone: append exact copies.
        let clones: Vec<usize> = (0..n).filter(|&i| clone_sel[i]).collect();
        let mut src: Vec<Source> = (0..n).map(Source::Keep).collect();
        src.extend(clones.iter().map(|&i| Source::New(i)));
        self.remap(&src);
        radii.extend(clones.iter().map(|_| 0));

        // Split: append 2 samples per selected Gaussian, then drop the originals.
        let n1 = self.len();
        let splits: Vec<usize> = (0..n).filter(|&i| split_sel[i]).collect();
        let mut src: Vec<Source> = (0..n1).map(Source::Keep).collect();
        for _ in 0..2 {
            src.extend(splits.iter().map(|&i| Source::New(i)));
        }
        self.remap(&src);
        radii.extend(std::iter::repeat_n(0, 2 * splits.len()));
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let div = cfg.split_scale_div.ln();
        for r in 0..2 {
            for (k, &i) in splits.iter().enumerate() {
                let j = n1 + r * splits.len() + k;
                let ls = self.params.log_scales[i].map(|x| x.f64());
                let q = self.params.quats[i].map(|x| x.f64());
                let rot = match normalize(q) {
                    Some((_, qn)) => rotmat_unit(qn),
                    None => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                };
                let z: [f64; 3] = std::array::from_fn(|a| ls[a].exp() * normal(&mut rng));
                let mu = self.params.means[i].map(|x| x.f64());
                self.params.means[j] = std::array::from_fn(|a| {
                    R::c(mu[a] + rot[a][0] * z[0] + rot[a][1] * z[1] + rot[a][2] * z[2])
                });
                self.params.log_scales[j] = ls.map(|x| R::c(x - div));
            }
        }
        if cfg.upstream_radii_reset {
            radii.iter_mut().for_each(|r| *r = 0);
        }

        // Prune: the split originals, low opacity, and (late) too big.
        let n2 = self.len();
        let min_logit = cfg.min_opacity;
        let big_world = cfg.max_world_frac * extent;
        let keep: Vec<Source> = (0..n2)
            .filter(|&i| {
                if i < n && split_sel[i] {
                    return false;
                }
                if sigmoid(self.params.opacity_logits[i].f64()) < min_logit {
                    return false;
                }
                if prune_big
                    && (radii[i] as f64 > cfg.max_screen_px || self.max_scale(i) > big_world)
                {
                    return false;
                }
                true
            })
            .map(Source::Keep)
            .collect();
        let after = keep.len();
        self.remap(&keep);
        self.stats = Stats::zeros(after);
        DensifyReport {
            cloned: clones.len(),
            split: splits.len(),
            pruned: n2 - after - splits.len(),
            before: n,
            after,
        }
    }

    /// Opacity reset (3DGS `reset_opacity`): o <- min(o, `to`), opacity moments zeroed.
    pub fn reset_opacity(&mut self, to: f64) {
        let cap = logit(to);
        for o in self.params.opacity_logits.iter_mut() {
            // min in opacity space = min in logit space (sigmoid is increasing); upstream goes
            // through sigmoid and back, which only differs by rounding.
            if o.f64() > cap {
                *o = R::c(cap);
            }
        }
        self.adam.zero_opacity_moments();
    }
}
