//! The neural-field baselines (`src/field/`): finite differences, encoders, the blocked matrix
//! products, golden files, ray sampling, and the field trainer's StepLR.

#[path = "../common/mod.rs"]
mod common;

mod dense_grid;
mod encoders;
mod gemm;
mod golden;
mod gradcheck;
mod init;
mod model_file;
mod sampling;
mod settings;
mod stages;
mod step_lr;

use unispine::field::encode::VmLines;
use unispine::field::{EncoderConfig, FieldConfig};

/// A small NAF field for the tests: 8 hidden units, 4 layers with a skip at 2, 6 samples a ray.
fn small_cfg(encoder: EncoderConfig) -> FieldConfig {
    let mut c = FieldConfig::preset("naf", 10).unwrap();
    c.encoder = encoder;
    c.hidden_dim = 8;
    c.num_layers = 4;
    c.skips = vec![2];
    c.n_samples = 6;
    c
}

/// A TensoRF VM encoder with the upstream line layout.
fn vm(resolution: usize, components: usize, out_dim: usize) -> EncoderConfig {
    EncoderConfig::TensorVm {
        resolution,
        components,
        out_dim,
        lines: VmLines::Upstream,
    }
}

/// A dense-grid encoder.
fn dense(resolution: usize, features: usize) -> EncoderConfig {
    EncoderConfig::DenseGrid {
        resolution,
        features,
    }
}
