//! Neural attenuation fields: the NAF / IntraTomo / TensoRF / NeRF baselines of Table 1 as SAX-NeRF
//! (caiyuanhao1998/SAX-NeRF, `src/trainer.py`, `config/*/`) trains them: one trainer, and only
//! the encoder, the MLP and the sampling differ.
//!
//! Stages (one file each, forward and backward): [`encode`] (frequency, hash grid, TensoRF VM,
//! dense grid), [`mlp`] (its matrix products in [`gemm`]), [`render`] (rays, stratified
//! samples, line integral), [`train`] (the loop with [`crate::optim::FlatAdam`],
//! evaluation, model file); [`bench`] times them. Generic over [`Real`]: f32 to train, f64 for
//! the gradient checks.
//!
//! Presets ([`FieldConfig::preset`]); `*-full` follow the upstream configs, the others are
//! reduced to fit a 2-core CPU and are labelled `(reduced)` in `metrics.json`:
//!
//! | preset | encoder | MLP | rays x samples | epochs (x train views = iterations) | StepLR |
//! |---|---|---|---|---|---|
//! | `naf-full` | hash 16 levels, F 2, T 2^19, base 16 | 4 x 32, skip 2, sigmoid | 1024 x 192 | 1500 | 500 epochs, 0.1 |
//! | `naf` | hash 8 levels, T 2^17 | as full | 512 x 128 | 300 | 100 epochs, 0.1 |
//! | `intratomo-full` | frequency, 6 bands, metres | 8 x 32, skip 4, sigmoid | 1024 x 320 | 3000 | 1500 epochs, 0.1 |
//! | `intratomo` | as full | as full | 512 x 128 | 300 | 150 epochs, 0.1 |
//! | `nerf-full` | frequency, 6 bands | 8 x 256, skip 4, LeakyReLU | 1024 x 384 | 3000 | 1500 epochs, 0.1 |
//! | `nerf` | as full | as full | 256 x 128 | 100 | 50 epochs, 0.1 |
//! | `tensorf-full` | VM 3 x 8 x 256^2, upstream lines, basis 24 -> 32 | 4 x 64, skip 2, LeakyReLU | 1024 x 384 | 3000 | 1500 epochs, 0.1 |
//! | `tensorf` | as full | as full | 512 x 128 | 300 | 150 epochs, 0.1 |
//!
//! `--iters N` replaces the iteration count and scales the StepLR step in proportion.
//!
//! [`encode`]: crate::field::encode
//! [`mlp`]: crate::field::mlp
//! [`gemm`]: crate::field::gemm
//! [`render`]: crate::field::render
//! [`train`]: crate::field::train
//! [`bench`]: crate::bench::field
//! [`FieldConfig::preset`]: crate::field::FieldConfig::preset
//! [`Real`]: crate::real::Real

pub mod act;
pub mod checkpoint;
pub mod encode;
pub mod gemm;
pub mod mlp;
pub mod model;
pub mod render;
pub mod train;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::real::Real;
use crate::simd::Simd;
use encode::{DenseGrid, Encoder, Frequency, GridMap, HashGrid, TensorVm, VmLines};
use mlp::{Mlp, OutAct};

/// Most iterations of a field run (over 100 x the longest upstream schedule, `intratomo-full`
/// and `nerf-full`: 3000 epochs x 50 views).
pub const MAX_ITERATIONS: usize = 20_000_000;

/// Encoder settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum EncoderConfig {
    /// NeRF positional encoding of the raw coordinate in metres.
    Frequency { bands: usize },
    /// torch-ngp hash grid (per-level scale 2).
    HashGrid {
        levels: usize,
        features: usize,
        /// Entries per level (`T`), a power of two.
        table_size: usize,
        base_resolution: usize,
    },
    /// TensoRF vector-matrix decomposition (SAX-NeRF `tensorf_encoder.py`).
    TensorVm {
        /// Plane side and line length (`num_levels` upstream).
        resolution: usize,
        /// Components per plane (`density_n_comp`, the rank).
        components: usize,
        /// Output width of `basis_mat` (`app_dim`).
        out_dim: usize,
        /// `upstream` (the line factor reads the plane, as SAX-NeRF) or `corrected`.
        lines: VmLines,
    },
    /// Dense grid of `resolution^3` vertices (`grid_sample`'s align-corners mapping of
    /// `x / bound`); the test oracle of the grid encoders.
    DenseGrid { resolution: usize, features: usize },
}

crate::choice! {
/// Which pixels a training batch draws its rays from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum RayPixels {
    /// Pixels with projection > 0 (SAX-NeRF / naf_cbct `src/dataset/tigre.py`): space crossed
    /// only by background rays is never constrained.
    #[default]
    Positive = "positive",
    /// Every pixel of the view (not an upstream setting).
    All = "all",
}
}

impl RayPixels {
    /// The upstream default (not written to `config.json`, so configurations written before
    /// the setting existed read and hash the same).
    pub fn is_positive(&self) -> bool {
        *self == RayPixels::Positive
    }
}

/// Every setting of a field run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FieldConfig {
    /// Preset name (`naf`, `naf-full`, ...).
    pub preset: String,
    /// True for the presets reduced to fit a 2-core CPU.
    pub reduced: bool,
    pub encoder: EncoderConfig,
    pub hidden_dim: usize,
    pub num_layers: usize,
    pub skips: Vec<usize>,
    pub last_activation: OutAct,
    /// Rays per iteration (`n_rays`), sampled among the pixels of `ray_pixels`.
    pub n_rays: usize,
    /// The pixels rays are drawn from (upstream: projection > 0).
    #[serde(default, skip_serializing_if = "RayPixels::is_positive")]
    pub ray_pixels: RayPixels,
    /// Samples per ray (`n_samples`; NeRF's `n_samples + n_fine`, all stratified).
    pub n_samples: usize,
    /// Iterations (SAX-NeRF: epochs x training views).
    pub iterations: usize,
    /// Adam learning rate (1e-3).
    pub lr: f64,
    /// StepLR step in iterations (SAX-NeRF: `lrate_step` epochs x training views).
    pub lr_step: usize,
    /// StepLR factor (0.1).
    pub lr_gamma: f64,
    /// Half side of the network's cube, metres (0.3).
    pub bound: f64,
    pub seed: u64,
    /// Evaluate every `eval_stride`-th test view (1 = all).
    pub eval_stride: usize,
}

/// The preset names, in table order.
pub const PRESETS: [&str; 8] = [
    "naf",
    "intratomo",
    "tensorf",
    "nerf",
    "naf-full",
    "intratomo-full",
    "tensorf-full",
    "nerf-full",
];

impl FieldConfig {
    /// The preset `name` for a dataset with `train_views` training views.
    pub fn preset(name: &str, train_views: usize) -> Result<FieldConfig> {
        let hash = |levels, table_size| EncoderConfig::HashGrid {
            levels,
            features: 2,
            table_size,
            base_resolution: 16,
        };
        let freq = EncoderConfig::Frequency { bands: 6 };
        // SAX-NeRF `config/tensorf/*.yaml` (`num_levels: 256`) and `tensorf_encoder.py`
        // (`density_n_comp=8`, `app_dim=32`).
        let vm = EncoderConfig::TensorVm {
            resolution: 256,
            components: 8,
            out_dim: 32,
            lines: VmLines::Upstream,
        };
        let nv = train_views.max(1);
        // (encoder, hidden, layers, skip, act, rays, samples, epochs, step epochs, reduced)
        let (enc, hidden, layers, skip, act, rays, samples, epochs, step, reduced) = match name {
            "naf-full" => (
                hash(16, 1 << 19),
                32,
                4,
                2,
                OutAct::Sigmoid,
                1024,
                192,
                1500,
                500,
                false,
            ),
            "naf" => (
                hash(8, 1 << 17),
                32,
                4,
                2,
                OutAct::Sigmoid,
                512,
                128,
                300,
                100,
                true,
            ),
            "intratomo-full" => (
                freq,
                32,
                8,
                4,
                OutAct::Sigmoid,
                1024,
                320,
                3000,
                1500,
                false,
            ),
            "intratomo" => (freq, 32, 8, 4, OutAct::Sigmoid, 512, 128, 300, 150, true),
            "nerf-full" => (
                freq,
                256,
                8,
                4,
                OutAct::LeakyRelu,
                1024,
                384,
                3000,
                1500,
                false,
            ),
            "nerf" => (freq, 256, 8, 4, OutAct::LeakyRelu, 256, 128, 100, 50, true),
            // 192 coarse + 192 fine samples upstream: one MLP on 384 stratified samples.
            "tensorf-full" => (
                vm,
                64,
                4,
                2,
                OutAct::LeakyRelu,
                1024,
                384,
                3000,
                1500,
                false,
            ),
            "tensorf" => (vm, 64, 4, 2, OutAct::LeakyRelu, 512, 128, 300, 150, true),
            _ => {
                return Err(Error::invalid(
                    "method",
                    format!(
                        "unknown field preset `{name}` (one of: {})",
                        PRESETS.join(", ")
                    ),
                ))
            }
        };
        Ok(FieldConfig {
            preset: name.into(),
            reduced,
            encoder: enc,
            hidden_dim: hidden,
            num_layers: layers,
            skips: vec![skip],
            last_activation: act,
            n_rays: rays,
            ray_pixels: RayPixels::Positive,
            n_samples: samples,
            iterations: epochs * nv,
            lr: 1e-3,
            lr_step: step * nv,
            lr_gamma: 0.1,
            bound: 0.3,
            seed: 0,
            eval_stride: if name.starts_with("nerf") { 5 } else { 1 },
        })
    }

    /// Replace the iteration count, scaling the StepLR step in proportion.
    pub fn set_iterations(&mut self, iters: usize) {
        let f = iters as f64 / self.iterations.max(1) as f64;
        self.lr_step = ((self.lr_step as f64 * f).round() as usize).max(1);
        self.iterations = iters;
    }

    /// Whether `name` is a preset reduced to fit a 2-core CPU (false for unknown names).
    pub fn is_reduced(name: &str) -> bool {
        FieldConfig::preset(name, 1).is_ok_and(|c| c.reduced)
    }

    /// One line on what the preset trains: encoder, MLP, rays x samples, iterations per view.
    pub fn describe(&self) -> String {
        let enc = match &self.encoder {
            EncoderConfig::Frequency { bands } => format!("frequency encoding, {bands} bands"),
            EncoderConfig::HashGrid {
                levels,
                features,
                table_size,
                base_resolution,
            } => format!(
                "hash grid {levels} levels x {features} features, table 2^{}, base {base_resolution}",
                table_size.trailing_zeros()
            ),
            EncoderConfig::TensorVm {
                resolution,
                components,
                ..
            } => format!("TensoRF VM 3 x {components} x {resolution}^2"),
            EncoderConfig::DenseGrid {
                resolution,
                features,
            } => format!("dense grid {resolution}^3 x {features}"),
        };
        format!(
            "{}: {enc}; MLP {} x {}{}; {} rays x {} samples",
            self.label(),
            self.num_layers,
            self.hidden_dim,
            if self.skips.is_empty() {
                String::new()
            } else {
                format!(
                    " (skip {})",
                    self.skips
                        .iter()
                        .map(|k| k.to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            },
            self.n_rays,
            self.n_samples
        )
    }

    /// The name for tables: the preset, with ` (reduced)` for reduced presets and
    /// `all pixels` when rays are drawn from every pixel (not the upstream sampling).
    pub fn label(&self) -> String {
        match (self.reduced, self.ray_pixels) {
            (true, RayPixels::Positive) => format!("{} (reduced)", self.preset),
            (true, RayPixels::All) => format!("{} (reduced, all pixels)", self.preset),
            (false, RayPixels::Positive) => self.preset.clone(),
            (false, RayPixels::All) => format!("{} (all pixels)", self.preset),
        }
    }

    /// Check every setting; errors name it.
    pub fn validate(&self) -> Result<()> {
        let pos = |name: &str, v: usize| {
            if v == 0 {
                Err(Error::invalid(name, "must be > 0"))
            } else {
                Ok(())
            }
        };
        pos("n_rays", self.n_rays)?;
        pos("n_samples", self.n_samples)?;
        pos("iterations", self.iterations)?;
        if self.iterations > MAX_ITERATIONS {
            return Err(Error::invalid(
                "iterations",
                format!(
                    "{} is outside the allowed range [1, {MAX_ITERATIONS}]",
                    self.iterations
                ),
            ));
        }
        pos("lr_step", self.lr_step)?;
        pos("eval_stride", self.eval_stride)?;
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return Err(Error::invalid(
                "lr",
                format!("must be finite and > 0, got {}", self.lr),
            ));
        }
        if !(self.lr_gamma.is_finite() && self.lr_gamma > 0.0) {
            return Err(Error::invalid("lr_gamma", "must be finite and > 0"));
        }
        if !(self.bound.is_finite() && self.bound > 1e-5) {
            return Err(Error::invalid("bound", "must be finite and > 1e-5 m"));
        }
        match &self.encoder {
            EncoderConfig::Frequency { bands } => {
                if *bands > 30 {
                    return Err(Error::invalid("bands", "at most 30 frequency bands"));
                }
            }
            EncoderConfig::HashGrid {
                levels,
                features,
                table_size,
                base_resolution,
            } => {
                pos("levels", *levels)?;
                pos("features", *features)?;
                pos("base_resolution", *base_resolution)?;
                if !table_size.is_power_of_two() || *table_size < 2 || *table_size > 1 << 26 {
                    return Err(Error::invalid(
                        "table_size",
                        format!(
                            "the hash table size must be a power of two in 2..=2^26, got {table_size}"
                        ),
                    ));
                }
                if *levels > 24 || (*base_resolution as u128) << (*levels - 1) > 1 << 30 {
                    return Err(Error::invalid(
                        "levels",
                        format!(
                            "finest resolution base_resolution * 2^(levels-1) must be <= 2^30 \
                             (levels {levels}, base {base_resolution})"
                        ),
                    ));
                }
            }
            EncoderConfig::TensorVm {
                resolution,
                components,
                out_dim,
                ..
            } => {
                if *components == 0 {
                    return Err(Error::invalid(
                        "components",
                        "the TensoRF rank (components per plane) must be >= 1, got 0",
                    ));
                }
                pos("out_dim", *out_dim)?;
                grid_resolution(*resolution)?;
                let n = 3 * (*components as u128) * (*resolution as u128).pow(2);
                if n > MAX_GRID_PARAMS || *out_dim > 4096 {
                    return Err(Error::invalid(
                        "components",
                        format!(
                            "3 x components x resolution^2 = {n} plane values (at most \
                             {MAX_GRID_PARAMS}) and out_dim <= 4096 (got {out_dim})"
                        ),
                    ));
                }
            }
            EncoderConfig::DenseGrid {
                resolution,
                features,
            } => {
                pos("features", *features)?;
                grid_resolution(*resolution)?;
                let n = (*resolution as u128).pow(3) * *features as u128;
                if n > MAX_GRID_PARAMS {
                    return Err(Error::invalid(
                        "resolution",
                        format!("resolution^3 x features = {n} values, at most {MAX_GRID_PARAMS}"),
                    ));
                }
            }
        }
        Mlp::new(
            1,
            self.hidden_dim,
            self.num_layers,
            &self.skips,
            self.last_activation,
        )?;
        Ok(())
    }

    /// The encoder of these settings.
    pub fn build_encoder(&self) -> Encoder {
        match &self.encoder {
            EncoderConfig::Frequency { bands } => Encoder::Frequency(Frequency { bands: *bands }),
            EncoderConfig::HashGrid {
                levels,
                features,
                table_size,
                base_resolution,
            } => Encoder::HashGrid(HashGrid::new(
                *levels,
                *features,
                table_size.trailing_zeros(),
                *base_resolution,
                self.bound,
            )),
            EncoderConfig::TensorVm {
                resolution,
                components,
                out_dim,
                lines,
            } => Encoder::TensorVm(TensorVm {
                resolution: *resolution,
                components: *components,
                out_dim: *out_dim,
                bound: self.bound,
                lines: *lines,
            }),
            EncoderConfig::DenseGrid {
                resolution,
                features,
            } => Encoder::DenseGrid(DenseGrid {
                resolution: *resolution,
                features: *features,
                bound: self.bound,
                map: GridMap::AlignCorners,
            }),
        }
    }
}

/// Largest parameter count of a VM's planes or of a dense grid (1 GiB of f32).
pub const MAX_GRID_PARAMS: u128 = 1 << 28;

/// A grid resolution must be in 2..=65536 (a grid needs two vertices per axis).
fn grid_resolution(r: usize) -> Result<()> {
    if !(2..=65536).contains(&r) {
        return Err(Error::invalid(
            "resolution",
            format!("the grid resolution must be in 2..=65536, got {r}"),
        ));
    }
    Ok(())
}

/// A field: encoder, MLP and their parameters (encoder first, then the MLP's).
#[derive(Clone, Debug, PartialEq)]
pub struct Field<R: Real> {
    pub encoder: Encoder,
    pub mlp: Mlp,
    pub params: Vec<R>,
}

impl<R: Real> Field<R> {
    /// Validate `cfg` and initialise (hash and dense-grid features U(-1e-4, 1e-4), TensoRF as
    /// [`TensorVm::init`], PyTorch Linear init).
    pub fn new(cfg: &FieldConfig) -> Result<Field<R>> {
        cfg.validate()?;
        let encoder = cfg.build_encoder();
        let mlp = Mlp::new(
            encoder.out_dim(),
            cfg.hidden_dim,
            cfg.num_layers,
            &cfg.skips,
            cfg.last_activation,
        )?;
        let ne = encoder.n_params();
        let mut params = vec![R::zero(); ne + mlp.n_params];
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0xf1e1_d000_0000_0001);
        if let Encoder::TensorVm(vm) = &encoder {
            params[..ne].copy_from_slice(&vm.init::<R>(&mut || rng.random::<f64>()));
        } else {
            for v in &mut params[..ne] {
                *v = R::c(rng.random_range(-1e-4..1e-4));
            }
        }
        params[ne..].copy_from_slice(&mlp.init::<R>(cfg.seed ^ 0xf1e1_d000_0000_0002));
        Ok(Field {
            encoder,
            mlp,
            params,
        })
    }

    /// Split point of the parameter vector.
    pub fn n_encoder_params(&self) -> usize {
        self.encoder.n_params()
    }

    /// Encode a block of points (`n x out_dim`).
    pub fn encode(&self, pts: &[[R; 3]]) -> Vec<R> {
        let mut out = vec![R::zero(); pts.len() * self.encoder.out_dim()];
        self.encode_into(Simd::active(), pts, &mut out);
        out
    }

    /// [`Field::encode`] into `out` (`n x out_dim`).
    pub fn encode_into(&self, simd: Simd, pts: &[[R; 3]], out: &mut [R]) {
        let ep = &self.params[..self.n_encoder_params()];
        let e = self.encoder.out_dim();
        self.encoder
            .encode_block(simd, ep, pts, &mut out[..pts.len() * e]);
    }

    /// Attenuation at a block of points.
    pub fn density(&self, pts: &[[R; 3]]) -> Vec<R> {
        let enc = self.encode(pts);
        let mp = &self.params[self.n_encoder_params()..];
        self.mlp.forward(mp, &enc, pts.len(), false).0
    }
}
