//! The encoders' initial parameters against the distributions upstream draws them from, by
//! their moments and ranges: TensoRF's planes and lines `0.1 N(0, 1)` and its basis PyTorch's
//! Linear default `U(-1/sqrt(3C), 1/sqrt(3C))` (SAX-NeRF `src/encoder/tensorf_encoder.py`), the
//! hash and dense grids' features `U(-1e-4, 1e-4)` (torch-ngp `hashencoder/hashgrid.py`, the
//! hash grid NAF uses).

use rand::{RngExt, SeedableRng};
use unispine::field::encode::{Encoder, TensorVm, VmLines};
use unispine::field::{Field, FieldConfig};

use crate::{dense, small_cfg};

/// Mean and (population) standard deviation.
fn moments(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// The share of `v` farther than `k` standard deviations `sd` from 0.
fn beyond(v: &[f64], k: f64, sd: f64) -> f64 {
    v.iter().filter(|x| x.abs() > k * sd).count() as f64 / v.len() as f64
}

#[test]
fn tensor_vm_planes_and_lines_are_0_1_n01_and_its_basis_pytorch_s_linear_default() {
    for lines in [VmLines::Upstream, VmLines::Corrected] {
        let vm = TensorVm {
            resolution: 64,
            components: 4,
            out_dim: 16,
            bound: 0.3,
            lines,
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let p: Vec<f64> = vm.init(&mut || rng.random::<f64>());
        assert_eq!(p.len(), vm.n_params());
        let (loff, boff) = vm.offsets();
        assert_eq!(
            (loff, boff),
            (3 * 4 * 64 * 64, 3 * 4 * 64 * 64 + 3 * 4 * 64)
        );
        // 49,152 plane values: the mean within 7 standard errors (0.1 / sqrt(n) = 4.5e-4),
        // the deviation within 2 %, and a normal's tails (4.55 % beyond 2 sd, 0.27 % beyond 3).
        let planes = &p[..loff];
        let (m, sd) = moments(planes);
        assert!(
            m.abs() < 3e-3 && (sd - 0.1).abs() < 2e-3,
            "planes: {m} {sd}"
        );
        let (t2, t3) = (beyond(planes, 2.0, 0.1), beyond(planes, 3.0, 0.1));
        assert!(
            (t2 - 0.0455).abs() < 0.004 && (t3 - 0.0027).abs() < 0.001,
            "{t2} {t3}"
        );
        // 768 line values.
        let (m, sd) = moments(&p[loff..boff]);
        assert!(m.abs() < 0.02 && (sd - 0.1).abs() < 0.01, "lines: {m} {sd}");
        // 192 basis values in +-1/sqrt(12), reaching both ends, spread as a uniform's
        // (sd = bound / sqrt(3)).
        let bnd = 1.0 / 12f64.sqrt();
        let basis = &p[boff..];
        assert_eq!(basis.len(), 16 * 12);
        assert!(basis.iter().all(|v| v.abs() <= bnd), "basis beyond {bnd}");
        let (lo, hi) = basis
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        assert!(lo < -0.95 * bnd && hi > 0.95 * bnd, "{lo} {hi}");
        let (m, sd) = moments(basis);
        let want = bnd / 3f64.sqrt();
        assert!(
            m.abs() < 0.04 && (sd / want - 1.0).abs() < 0.1,
            "basis: {m} {sd}"
        );
    }
}

#[test]
fn hash_and_dense_grid_features_start_uniform_in_1e_4() {
    let hash = FieldConfig::preset("naf", 10).unwrap();
    for cfg in [hash, small_cfg(dense(16, 2))] {
        let f = Field::<f64>::new(&cfg).unwrap();
        assert!(!matches!(
            f.encoder,
            Encoder::TensorVm(_) | Encoder::Frequency(_)
        ));
        let ne = f.n_encoder_params();
        let feats = &f.params[..ne];
        assert!(ne >= 8192, "{ne}");
        assert!(feats.iter().all(|v| v.abs() < 1e-4));
        let (lo, hi) = feats
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        assert!(lo < -0.99e-4 && hi > 0.99e-4, "{lo} {hi}");
        let (m, sd) = moments(feats);
        let want = 1e-4 / 3f64.sqrt();
        assert!(
            m.abs() < 0.05 * want && (sd / want - 1.0).abs() < 0.03,
            "{m} {sd}"
        );
        // The MLP after the features keeps its own initialisation (not the features').
        assert!(f.params[ne..].iter().any(|v| v.abs() > 1e-3));
    }
}

/// TensoRF's initial parameters as a function of the uniform stream, for reproducibility: the
/// planes and lines take the stream two numbers at a time (Box-Muller: `r = sqrt(-2 ln(1 - u1))`,
/// `0.1 r cos(2 pi u2)` then `0.1 r sin(2 pi u2)`), the basis the numbers that follow, one each
/// (`(2 u - 1) / sqrt(3C)`). The planes and lines hold an even count, `3 C n (n + 1)`.
#[test]
fn tensor_vm_init_takes_box_muller_pairs_then_one_number_a_basis_value() {
    let vm = TensorVm {
        resolution: 5,
        components: 2,
        out_dim: 3,
        bound: 0.3,
        lines: VmLines::Upstream,
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let stream: Vec<f64> = (0..vm.n_params() + 8)
        .map(|_| rng.random::<f64>())
        .collect();
    let mut next = stream.iter().copied();
    let p: Vec<f64> = vm.init(&mut || next.next().unwrap());
    let (_, boff) = vm.offsets();
    assert_eq!(boff, 3 * 2 * 5 * 6);
    for (k, pair) in p[..boff].chunks(2).enumerate() {
        let (u1, u2) = (1.0 - stream[2 * k], stream[2 * k + 1]);
        let r = (-2.0 * u1.ln()).sqrt();
        let a = std::f64::consts::TAU * u2;
        assert_eq!(pair, [0.1 * r * a.cos(), 0.1 * r * a.sin()], "pair {k}");
    }
    let bnd = 1.0 / 6f64.sqrt();
    for (i, v) in p[boff..].iter().enumerate() {
        assert_eq!(*v, (2.0 * stream[boff + i] - 1.0) * bnd, "basis {i}");
    }
    assert_eq!(p.len(), vm.n_params());
}
